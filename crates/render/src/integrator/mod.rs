//! Unidirectional path tracing with next-event estimation and multiple importance sampling,
//! following the semantics of Mitsuba 3's `path` integrator (`max_depth`, `rr_depth`).
//!
//! The image is split into buckets rendered in parallel by rayon ([`for_each_bucket`]). Every
//! camera sample draws from its own random stream keyed by (seed, pixel, sample index), and
//! every pixel is the plain mean of its own samples, summed exactly ([`PixelSum`]), so the image
//! is bit-identical whatever the number of threads, and a render split into sample passes or
//! image windows ([`RenderSettings::sample_range`], [`RenderSettings::window`]) merges into the
//! very same image (`crate::pass`). One camera ray's path is traced by [`radiance`] (module
//! `path`).

mod path;

pub use path::{radiance, recentre_fraction, shares_pixel_textures, spawn_ray, MAX_PASS_THROUGH};

use crate::camera::CameraRay;
use crate::film::{Image, PixelSum};
use crate::geometry::SurfaceInteraction;
use crate::math::Spectrum;
use crate::pathfootprint::FootprintMode;
use crate::sampling::{PixelSequence, Rng};
use crate::scene::Scene;
use crate::shading::{Direct, GraphSource, NonFiniteSample, TextureEvaluator, NONFINITE_KEPT};
use footprint::Vertex;
use glam::{DMat2, Vec2, Vec3};
use rayon::prelude::*;
use std::time::{Duration, Instant};

/// Side of the square image buckets handed to threads.
pub const BUCKET: u32 = 16;

/// A rectangle of the image rendered by one thread: pixels `x0..x1` × `y0..y1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Bucket {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// One past the last column.
    pub x1: u32,
    /// One past the last row.
    pub y1: u32,
}

impl Bucket {
    /// The whole of a `width` × `height` image.
    pub fn full(width: u32, height: u32) -> Bucket {
        Bucket { x0: 0, y0: 0, x1: width, y1: height }
    }

    /// Width in pixels.
    pub fn width(self) -> u32 {
        self.x1 - self.x0
    }

    /// Height in pixels.
    pub fn height(self) -> u32 {
        self.y1 - self.y0
    }

    /// The bucket's pixels, row by row.
    pub fn pixels(self) -> impl Iterator<Item = (u32, u32)> {
        (self.y0..self.y1).flat_map(move |y| (self.x0..self.x1).map(move |x| (x, y)))
    }

    /// Number of pixels.
    pub fn len(self) -> usize {
        ((self.x1 - self.x0) * (self.y1 - self.y0)) as usize
    }

    /// Whether the bucket has no pixels.
    pub fn is_empty(self) -> bool {
        self.len() == 0
    }
}

/// Renders the buckets of an image window in parallel on the current rayon pool, `work`
/// making each bucket's result; the results come back in row-major bucket order, whatever the
/// thread count. Rendering and profiling both drive their buckets through this.
pub fn for_each_bucket<T: Send>(window: Bucket, work: &(dyn Fn(Bucket) -> T + Sync)) -> Vec<(Bucket, T)> {
    let buckets: Vec<Bucket> = (0..window.height().div_ceil(BUCKET))
        .flat_map(|by| {
            (0..window.width().div_ceil(BUCKET)).map(move |bx| {
                let (x0, y0) = (window.x0 + bx * BUCKET, window.y0 + by * BUCKET);
                Bucket { x0, y0, x1: (x0 + BUCKET).min(window.x1), y1: (y0 + BUCKET).min(window.y1) }
            })
        })
        .collect();
    buckets.par_iter().map(|&b| (b, work(b))).collect()
}

/// Counts gathered while rendering.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderCounts {
    /// Camera samples taken.
    pub samples: u64,
    /// Rays traced for closest hits (camera and bounce rays).
    pub rays: u64,
    /// Shadow rays traced for next-event estimation.
    pub shadow_rays: u64,
    /// Samples whose radiance was NaN or infinite and were discarded.
    pub nonfinite_samples: u64,
    /// Samples with a channel beyond [`crate::film::SAMPLE_LIMIT`], clamped to it.
    pub clamped_samples: u64,
    /// Texture evaluations at a pixel centre's footprint, one per pixel and key: the surface,
    /// and the way through perfect mirrors and smooth glass to it (more where a pixel meets more
    /// keys than it keeps at once; see `TextureEvaluator::begin_pixel` in `crate::shading`).
    pub pixel_texture_evaluations: u64,
    /// Hits that read their pixel's shared textures.
    pub pixel_texture_reads: u64,
    /// Hits that could have shared their pixel's textures but evaluated their own (a
    /// silhouette, a seam, the pixel centre's ray not taking the sample's way through mirrors
    /// and glass, or a value that was not finite at the pixel centre).
    pub pixel_texture_misses: u64,
    /// Path vertices whose footprint the estimator computed.
    pub footprints: u64,
    /// Hits whose footprint nothing read, there (no textures, textures from the pixel's shared
    /// evaluation, or the path's last hit) or at a later hit of the path, so never computed (see
    /// `FootprintCarrier` in `crate::integrator::path`).
    pub footprints_skipped: u64,
}

impl RenderCounts {
    fn add(&mut self, o: &RenderCounts) {
        self.samples += o.samples;
        self.rays += o.rays;
        self.shadow_rays += o.shadow_rays;
        self.nonfinite_samples += o.nonfinite_samples;
        self.clamped_samples += o.clamped_samples;
        self.pixel_texture_evaluations += o.pixel_texture_evaluations;
        self.pixel_texture_reads += o.pixel_texture_reads;
        self.footprints += o.footprints;
        self.footprints_skipped += o.footprints_skipped;
        self.pixel_texture_misses += o.pixel_texture_misses;
    }
}

/// Bounces the footprint AOV reports (vertices x₁, x₂, x₃).
pub const AOV_BOUNCES: usize = 3;

/// Value of the footprint AOV where no sample reached that bounce.
pub const AOV_NO_VERTEX: f32 = footprint::LOD_MIN;

/// What a render produced.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// The image (linear RGB) of the rendered window: the whole image unless
    /// [`RenderSettings::window`] names a part.
    pub image: Image,
    /// The window of the full image that `image` (and `sums`, `footprint_aov`) covers.
    pub window: Bucket,
    /// The sample indices every pixel took.
    pub samples: std::ops::Range<u32>,
    /// Each pixel's exact sum of its samples, row by row over the window, when
    /// [`RenderSettings::keep_sums`] asked for it (what a pass file stores).
    pub sums: Option<Vec<PixelSum>>,
    /// Footprint AOV when asked for: channel k is the mean LOD (log2 of the footprint's
    /// standard deviation along its major axis, in texels of the requested density) at bounce
    /// k + 1, over the samples that reached it; [`AOV_NO_VERTEX`] where none did.
    pub footprint_aov: Option<Image>,
    /// Counters.
    pub counts: RenderCounts,
    /// Per scene graph: node evaluations and work counters.
    pub graph_stats: Vec<graph::EvalStats>,
    /// The first samples whose radiance was not finite (at most [`NONFINITE_KEPT`], ordered by
    /// pixel row, column and sample), with where each came from.
    pub nonfinite: Vec<NonFiniteSample>,
    /// The first samples on whose path a procedural texture value went non-finite (whether or
    /// not their radiance did), in the same order, with where.
    pub graph_nonfinite: Vec<NonFiniteSample>,
    /// Wall-clock time of the rendering phase.
    pub time: Duration,
}

/// Rendering parameters that the command line may override.
#[derive(Clone, Copy, Debug)]
pub struct RenderSettings {
    /// Samples per pixel.
    pub spp: u32,
    /// Seed of all random streams.
    pub seed: u64,
    /// Footprint estimator carried by camera paths.
    pub footprint: FootprintMode,
    /// When set, also produce the footprint AOV with this many texels per uv unit.
    pub footprint_aov_density: Option<f64>,
    /// Replace every graph output by its mean over the texture: the free-texture lower bound
    /// on render time.
    pub free_textures: bool,
    /// Scale of the texture filter relative to the footprint (see [`FilterScale`]).
    pub filter_scale: FilterScale,
    /// The sample indices each pixel takes, `(start, end)`: a sample pass of a render of `spp`
    /// samples per pixel. `None` takes all, `0..spp`.
    pub sample_range: Option<(u32, u32)>,
    /// The part of the image rendered; `None` renders all of it.
    pub window: Option<Bucket>,
    /// Keep each pixel's exact sum in [`RenderOutput::sums`].
    pub keep_sums: bool,
    /// Evaluate every camera sample's first-hit textures at its own footprint. By default the
    /// samples of a pixel that meet the same surface share one evaluation at the pixel
    /// centre's footprint there, when the footprint is centred on the pixel centre anyway (the
    /// default filter scale; see `TextureEvaluator::begin_pixel` in `crate::shading`).
    pub per_sample_textures: bool,
    /// Compute the footprint of every hit as the path reaches it. By default a hit whose
    /// footprint nothing reads there (no textures, or textures read from the pixel's shared
    /// evaluation) is computed only once a later hit's textures read their footprint (never,
    /// if none does); the images are the same either way.
    pub eager_footprints: bool,
}

/// How wide textures are filtered relative to the path footprint.
///
/// The default, `Fixed(1)`, filters each sample over the whole footprint (σ = ½ px at the first
/// hit, the paper's pixel filter): the strongest anti-aliasing at few samples, and the footprints
/// the tile cache and the selective-caching planner are built around. At the first hit the
/// footprint is centred where the pixel centre's ray meets the surface ([`recentre_fraction`]),
/// so every sample reads the texture filtered by the pixel filter once: textures add no noise
/// there, and the render converges to the point-sampled image as far as the graph's filtered
/// approximations allow. `Auto` narrows the texture filter as samples accumulate, as pbrt-v4
/// does with its ray differentials (`max(1/8, 1/√spp)`, centred part of the way so that the
/// total blur is still the pixel filter): it relies less on the filtered approximations (the
/// footprint is finer), at the price of texture noise and finer footprints: more noise octaves
/// evaluated, and finer (more, costlier) cache tiles. Footprints themselves (path statistics,
/// AOVs, `tessera footprint`) are never scaled or moved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FilterScale {
    /// A fixed scale of the footprint's standard deviation (1 = the paper's footprint).
    Fixed(f32),
    /// `max(1/8, 1/√spp)`.
    Auto,
}

impl FilterScale {
    /// The scale of the footprint's standard deviation for a render of `spp` samples per pixel.
    pub fn at(self, spp: u32) -> f32 {
        match self {
            FilterScale::Fixed(s) => s,
            FilterScale::Auto => (1.0 / (spp.max(1) as f32).sqrt()).max(0.125),
        }
    }
}

/// The widest fixed texture filter, in footprints: a hundred times the pixel filter blurs any
/// texture to its mean already, and far wider ones only overflow the footprint arithmetic.
pub const MAX_FILTER_SCALE: f32 = 100.0;

impl std::str::FromStr for FilterScale {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(FilterScale::Auto);
        }
        match s.parse::<f32>() {
            Ok(v) if (0.0..=MAX_FILTER_SCALE).contains(&v) => Ok(FilterScale::Fixed(v)),
            _ => Err(format!(
                "filter scale must be 'auto' or a number from 0 to {MAX_FILTER_SCALE}, got '{}'",
                crate::xml::excerpt(s)
            )),
        }
    }
}

impl RenderSettings {
    /// The factor applied to uv covariances before textures are filtered.
    #[inline]
    pub fn filter_scale_squared(&self) -> f32 {
        let s = self.filter_scale.at(self.spp);
        s * s
    }
}

impl RenderSettings {
    /// `spp` samples with `seed`, the default (covariance) footprints and the default texture
    /// filter (the whole footprint, [`FilterScale::Fixed`]`(1)`).
    pub fn new(spp: u32, seed: u64) -> Self {
        RenderSettings {
            spp,
            seed,
            footprint: FootprintMode::default(),
            footprint_aov_density: None,
            free_textures: false,
            filter_scale: FilterScale::Fixed(1.0),
            sample_range: None,
            window: None,
            keep_sums: false,
            per_sample_textures: false,
            eager_footprints: false,
        }
    }

    /// The sample indices each pixel takes.
    pub fn samples(&self) -> std::ops::Range<u32> {
        let (a, b) = self.sample_range.unwrap_or((0, self.spp));
        a..b
    }
}

/// What happened at a path vertex.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    /// Glossy or specular reflection.
    Reflect,
    /// Transmission through an interface.
    Refract,
    /// A diffuse bounce.
    Diffuse,
    /// The path ended on an emitter.
    Emit,
    /// The path ended here without scattering (depth limit, roulette, black or back-facing BSDF).
    Absorb,
    /// The ray left the scene.
    Escape,
}

impl Event {
    /// Lower-case name used in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Event::Reflect => "reflect",
            Event::Refract => "refract",
            Event::Diffuse => "diffuse",
            Event::Emit => "emit",
            Event::Absorb => "absorb",
            Event::Escape => "escape",
        }
    }
}

/// Receives what happens along a camera path; the render loop uses [`NoObserver`], which
/// compiles to nothing.
pub trait PathObserver {
    /// Whether this observer needs footprints even when no material asks for them.
    const WANTS_FOOTPRINTS: bool = false;
    /// A surface hit at `depth` (0 = first hit) with its tangent-plane footprint covariance.
    fn hit(&mut self, _depth: u32, _si: &SurfaceInteraction, _vertex: Option<&Vertex>, _var: DMat2) {}
    /// What the path did at `depth`: the sampled event with the lobe's roughness and IOR ratio.
    fn event(&mut self, _depth: u32, _event: Event, _alpha: f32, _eta: f32) {}
    /// The ray left the scene after `depth` hits, along `dir`.
    fn escape(&mut self, _depth: u32, _dir: Vec3) {}
}

/// An observer that records nothing.
pub struct NoObserver;
impl PathObserver for NoObserver {}

/// A bucket's pixels (radiance, footprint AOV), counters, graph statistics and non-finite
/// samples.
struct BucketResult {
    pixels: Vec<(PixelSum, Spectrum)>,
    counts: RenderCounts,
    stats: Vec<graph::EvalStats>,
    nonfinite: Vec<NonFiniteSample>,
    graph_nonfinite: Vec<NonFiniteSample>,
}

/// Renders `scene` with every graph node evaluated on every request; `progress` is called with
/// the number of pixels each image bucket finished.
pub fn render(scene: &Scene, settings: RenderSettings, progress: &(dyn Fn(u64) + Sync)) -> RenderOutput {
    render_with(scene, settings, &|| Direct, progress)
}

/// Renders `scene` with graph requests served by the sources `source` makes (one per image
/// bucket): [`Direct`], or a cache's (`crate::caching::render_cached`).
pub fn render_with<S: GraphSource>(
    scene: &Scene,
    settings: RenderSettings,
    source: &(dyn Fn() -> S + Sync),
    progress: &(dyn Fn(u64) + Sync),
) -> RenderOutput {
    let start = Instant::now();
    let window = settings.window.unwrap_or(Bucket::full(scene.camera.width, scene.camera.height));
    let samples = settings.samples();
    let results = for_each_bucket(window, &|b| {
        let mut counts = RenderCounts::default();
        let mut textures = TextureEvaluator::new(&scene.graphs, &scene.materials, source());
        let mut pixels = Vec::with_capacity(b.len());
        for (x, y) in b.pixels() {
            pixels.push(render_pixel_aov(scene, settings, x, y, &mut counts, &mut textures));
        }
        progress(pixels.len() as u64);
        let mut stats = Vec::new();
        textures.merge_stats_into(&mut stats);
        BucketResult {
            pixels,
            counts,
            stats,
            nonfinite: std::mem::take(&mut textures.nonfinite),
            graph_nonfinite: std::mem::take(&mut textures.graph_nonfinite),
        }
    });
    let (w, h) = (window.width(), window.height());
    let mut image = Image::new(w, h);
    let mut aov = settings.footprint_aov_density.map(|_| Image::new(w, h));
    let mut sums = settings.keep_sums.then(|| vec![PixelSum::default(); image.pixels.len()]);
    let n = samples.len() as u32;
    let mut counts = RenderCounts::default();
    let mut graph_stats: Vec<graph::EvalStats> = Vec::new();
    let (mut nonfinite, mut graph_nonfinite) = (Vec::new(), Vec::new());
    for (b, r) in &results {
        counts.add(&r.counts);
        nonfinite.extend_from_slice(&r.nonfinite);
        graph_nonfinite.extend_from_slice(&r.graph_nonfinite);
        graph::EvalStats::merge_all(&mut graph_stats, &r.stats);
        for ((x, y), p) in b.pixels().zip(&r.pixels) {
            let i = ((y - window.y0) * w + (x - window.x0)) as usize;
            image.pixels[i] = p.0.mean(n);
            if let Some(a) = &mut aov {
                a.pixels[i] = p.1;
            }
            if let Some(s) = &mut sums {
                s[i] = p.0;
            }
        }
    }
    for list in [&mut nonfinite, &mut graph_nonfinite] {
        list.sort_by_key(|n: &NonFiniteSample| (n.y, n.x, n.sample));
        list.truncate(NONFINITE_KEPT);
    }
    RenderOutput {
        image,
        window,
        samples,
        sums,
        footprint_aov: aov,
        counts,
        graph_stats,
        nonfinite,
        graph_nonfinite,
        time: start.elapsed(),
    }
}

/// Accumulates per-bounce LODs for the footprint AOV.
struct LodObserver {
    density: f64,
    sum: [f64; AOV_BOUNCES],
    count: [u32; AOV_BOUNCES],
}

impl PathObserver for LodObserver {
    const WANTS_FOOTPRINTS: bool = true;
    fn hit(&mut self, depth: u32, _si: &SurfaceInteraction, vertex: Option<&Vertex>, var: DMat2) {
        if let (Some(v), true) = (vertex, (depth as usize) < AOV_BOUNCES) {
            let lod = footprint::lod(footprint::uv_covariance(var, v), self.density);
            self.sum[depth as usize] += lod as f64;
            self.count[depth as usize] += 1;
        }
    }
}

/// A pixel's sum of radiance samples and, when asked for, its footprint AOV value.
fn render_pixel_aov<S: GraphSource>(
    scene: &Scene,
    settings: RenderSettings,
    x: u32,
    y: u32,
    counts: &mut RenderCounts,
    textures: &mut TextureEvaluator<S>,
) -> (PixelSum, Spectrum) {
    let samples = settings.samples();
    let Some(density) = settings.footprint_aov_density else {
        return (render_pixel_with(scene, settings, x, y, samples, counts, textures, &mut NoObserver), Spectrum::ZERO);
    };
    let mut obs = LodObserver { density, sum: [0.0; AOV_BOUNCES], count: [0; AOV_BOUNCES] };
    let l = render_pixel_with(scene, settings, x, y, samples, counts, textures, &mut obs);
    let lods: [f32; AOV_BOUNCES] =
        std::array::from_fn(
            |k| if obs.count[k] > 0 { (obs.sum[k] / obs.count[k] as f64) as f32 } else { AOV_NO_VERTEX },
        );
    (l, Spectrum::from_array(lods))
}

/// Camera sample `s` of pixel (`x`, `y`) in a render seeded by `seed`: its ray, through the film
/// point the pixel filter warps [`crate::sampling::pixel_sample`] to (so a pixel's samples
/// cover its filter evenly), and the random stream its path draws from. Every renderer entry
/// point (render, profiling, `tessera footprint`) takes its samples from here, so they agree.
pub fn camera_sample(scene: &Scene, seed: u64, x: u32, y: u32, s: u32) -> (CameraRay, Rng) {
    camera_sample_in(scene, &PixelSequence::new(seed, pixel_index(scene, x, y)), seed, x, y, s)
}

/// The index of pixel `(x, y)` that seeds its streams.
fn pixel_index(scene: &Scene, x: u32, y: u32) -> u64 {
    u64::from(y) * u64::from(scene.camera.width) + u64::from(x)
}

/// [`camera_sample`] with the pixel's sample sequence already set up (once per pixel).
fn camera_sample_in(scene: &Scene, seq: &PixelSequence, seed: u64, x: u32, y: u32, s: u32) -> (CameraRay, Rng) {
    let pixel_index = pixel_index(scene, x, y);
    let offset = scene.rfilter.warp(seq.at(u64::from(s)));
    let film = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) + offset;
    let mut cam = scene.camera.generate_ray(film);
    cam.film_offset = offset;
    (cam, Rng::for_sample(seed, pixel_index, u64::from(s)))
}

/// The exact sum of one pixel's radiance over the samples with indices `samples` (a render
/// takes [`RenderSettings::samples`]), reporting every path to `obs`; non-finite samples are
/// left out of the sum (their pixel's mean still divides by every sample taken) and recorded in
/// `textures`.
#[allow(clippy::too_many_arguments)]
pub fn render_pixel_with<S: GraphSource, O: PathObserver>(
    scene: &Scene,
    settings: RenderSettings,
    x: u32,
    y: u32,
    samples: std::ops::Range<u32>,
    counts: &mut RenderCounts,
    textures: &mut TextureEvaluator<S>,
    obs: &mut O,
) -> PixelSum {
    let mut sum = PixelSum::default();
    textures.begin_pixel(x, y);
    let seq = PixelSequence::new(settings.seed, pixel_index(scene, x, y));
    for s in samples {
        let (cam, mut rng) = camera_sample_in(scene, &seq, settings.seed, x, y, s);
        textures.begin_sample(s);
        let l = radiance(scene, settings, &cam, &mut rng, counts, textures, obs);
        counts.samples += 1;
        if l.is_finite() {
            counts.clamped_samples += u64::from(sum.add(l));
        } else {
            counts.nonfinite_samples += 1;
            textures.record_nonfinite(x, y, s);
        }
        textures.end_sample(x, y, s);
    }
    sum
}
