//! Unidirectional path tracing with next-event estimation and multiple importance sampling,
//! following the semantics of Mitsuba 3's `path` integrator (`max_depth`, `rr_depth`).
//!
//! The image is split into tiles rendered in parallel by rayon. Every camera sample draws from
//! its own random stream keyed by (seed, pixel, sample index), and every pixel is the plain mean
//! of its own samples, so the image is bit-identical whatever the number of threads.

use crate::camera::CameraRay;
use crate::film::Image;
use crate::geometry::{interaction, Ray, SurfaceInteraction};
use crate::math::{max_component, Frame, Spectrum};
use crate::material::Material;
use crate::pathfootprint::{shadow_scatter, FootprintMode, PathFootprint};
use crate::sampling::Rng;
use crate::scene::Scene;
use crate::shading::{Direct, GraphSource, NonFiniteSample, TextureEvaluator, NONFINITE_KEPT};
use crate::texture::ShadeContext;
use footprint::Vertex;
use glam::{DMat2, DVec2, Mat2, Vec2, Vec3};
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

/// Renders the buckets of a `w` × `h` image in parallel on the current rayon pool, `work`
/// making each bucket's result; the results come back in row-major bucket order, whatever the
/// thread count. Rendering and profiling both drive their buckets through this.
pub fn for_each_bucket<T: Send>(w: u32, h: u32, work: &(dyn Fn(Bucket) -> T + Sync)) -> Vec<(Bucket, T)> {
    let buckets: Vec<Bucket> = (0..h.div_ceil(BUCKET))
        .flat_map(|by| {
            (0..w.div_ceil(BUCKET)).map(move |bx| {
                let (x0, y0) = (bx * BUCKET, by * BUCKET);
                Bucket { x0, y0, x1: (x0 + BUCKET).min(w), y1: (y0 + BUCKET).min(h) }
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
}

impl RenderCounts {
    fn add(&mut self, o: &RenderCounts) {
        self.samples += o.samples;
        self.rays += o.rays;
        self.shadow_rays += o.shadow_rays;
        self.nonfinite_samples += o.nonfinite_samples;
    }
}

/// Bounces the footprint AOV reports (vertices x₁, x₂, x₃).
pub const AOV_BOUNCES: usize = 3;

/// Value of the footprint AOV where no sample reached that bounce.
pub const AOV_NO_VERTEX: f32 = footprint::LOD_MIN;

/// What a render produced.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// The image (linear RGB).
    pub image: Image,
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

impl std::str::FromStr for FilterScale {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(FilterScale::Auto);
        }
        match s.parse::<f32>() {
            Ok(v) if v.is_finite() && v >= 0.0 => Ok(FilterScale::Fixed(v)),
            _ => Err(format!("filter scale must be 'auto' or a non-negative number, got '{s}'")),
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
        }
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
    pixels: Vec<(Spectrum, Spectrum)>,
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
    let (w, h) = (scene.camera.width, scene.camera.height);
    let results = for_each_bucket(w, h, &|b| {
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
    let mut image = Image::new(w, h);
    let mut aov = settings.footprint_aov_density.map(|_| Image::new(w, h));
    let mut counts = RenderCounts::default();
    let mut graph_stats: Vec<graph::EvalStats> = Vec::new();
    let (mut nonfinite, mut graph_nonfinite) = (Vec::new(), Vec::new());
    for (b, r) in &results {
        counts.add(&r.counts);
        nonfinite.extend_from_slice(&r.nonfinite);
        graph_nonfinite.extend_from_slice(&r.graph_nonfinite);
        graph::EvalStats::merge_all(&mut graph_stats, &r.stats);
        for ((x, y), p) in b.pixels().zip(&r.pixels) {
            image.pixels[(y * w + x) as usize] = p.0;
            if let Some(a) = &mut aov {
                a.pixels[(y * w + x) as usize] = p.1;
            }
        }
    }
    for list in [&mut nonfinite, &mut graph_nonfinite] {
        list.sort_by_key(|n: &NonFiniteSample| (n.y, n.x, n.sample));
        list.truncate(NONFINITE_KEPT);
    }
    RenderOutput { image, footprint_aov: aov, counts, graph_stats, nonfinite, graph_nonfinite, time: start.elapsed() }
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

/// A pixel's radiance and, when asked for, its footprint AOV value.
fn render_pixel_aov<S: GraphSource>(
    scene: &Scene,
    settings: RenderSettings,
    x: u32,
    y: u32,
    counts: &mut RenderCounts,
    textures: &mut TextureEvaluator<S>,
) -> (Spectrum, Spectrum) {
    let spp = settings.spp;
    let Some(density) = settings.footprint_aov_density else {
        return (render_pixel_with(scene, settings, x, y, spp, counts, textures, &mut NoObserver), Spectrum::ZERO);
    };
    let mut obs = LodObserver { density, sum: [0.0; AOV_BOUNCES], count: [0; AOV_BOUNCES] };
    let l = render_pixel_with(scene, settings, x, y, spp, counts, textures, &mut obs);
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
    let pixel_index = u64::from(y) * u64::from(scene.camera.width) + u64::from(x);
    let offset = scene.rfilter.warp(crate::sampling::pixel_sample(seed, pixel_index, u64::from(s)));
    let film = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) + offset;
    let mut cam = scene.camera.generate_ray(film);
    cam.film_offset = offset;
    (cam, Rng::for_sample(seed, pixel_index, u64::from(s)))
}

/// Mean radiance of one pixel over its first `samples` samples (a render takes
/// `settings.spp`), reporting every path to `obs`; non-finite samples are left out of the mean
/// and recorded in `textures`.
#[allow(clippy::too_many_arguments)]
pub fn render_pixel_with<S: GraphSource, O: PathObserver>(
    scene: &Scene,
    settings: RenderSettings,
    x: u32,
    y: u32,
    samples: u32,
    counts: &mut RenderCounts,
    textures: &mut TextureEvaluator<S>,
    obs: &mut O,
) -> Spectrum {
    let mut sum = Spectrum::ZERO;
    for s in 0..samples {
        let (cam, mut rng) = camera_sample(scene, settings.seed, x, y, s);
        textures.begin_sample(s);
        let l = radiance(scene, settings, &cam, &mut rng, counts, textures, obs);
        counts.samples += 1;
        if l.is_finite() {
            sum += l;
        } else {
            counts.nonfinite_samples += 1;
            textures.record_nonfinite(x, y, s);
        }
        textures.end_sample(x, y, s);
    }
    sum / samples.max(1) as f32
}

/// Offsets a ray origin off the surface along the geometric normal, on the side of `d`.
#[inline]
pub fn spawn_ray(si: &SurfaceInteraction, d: Vec3) -> Ray {
    let eps = ray_epsilon(si.p);
    let side = if si.ng.dot(d) >= 0.0 { 1.0 } else { -1.0 };
    Ray { o: si.p + si.ng * (eps * side), d, tmin: 0.0, tmax: f32::INFINITY }
}

#[inline]
fn ray_epsilon(p: Vec3) -> f32 {
    2e-4 * (1.0 + p.abs().max_element())
}

/// Power heuristic with exponent 2.
#[inline]
fn mis(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a > 0.0 && (a2 + b2).is_finite() {
        a2 / (a2 + b2)
    } else if a > 0.0 {
        // Overflowing squares: fall back to the balance heuristic.
        a / (a + b)
    } else {
        0.0
    }
}

/// Most surfaces a ray passes straight through in a row (partial opacity). A camera or bounce
/// ray that would pass through more ends its path there, and a shadow ray crossing more is
/// taken as blocked: the only bias is on rays that cross more than this many partly
/// transparent layers between two scattering events, and it bounds the work should a ray ever
/// re-hit the surface it left.
pub const MAX_PASS_THROUGH: u32 = 128;

/// The distance along a ray past its hit at `t` (point `si`) from which a ray passing straight
/// through resumes. The ray keeps its origin and direction, so whatever lies behind is hit at
/// exactly the distance (and point) it would be without the surface; the step of one
/// [`ray_epsilon`] skips the surface itself, including a mesh's neighbouring triangles at a
/// shared edge.
#[inline]
fn past(si: &SurfaceInteraction, t: f32) -> f32 {
    t + ray_epsilon(si.p)
}

/// The material's graph outputs at hit `si`, filtered over the uv footprint that `var` (the
/// tangent-plane covariance at `vertex`) gives there, centred `shift` away from the hit; a point
/// without a vertex, the means with `--free-textures`, nothing for a material without graphs.
#[allow(clippy::too_many_arguments)]
fn material_outputs<'a, S: GraphSource>(
    scene: &'a Scene,
    settings: &RenderSettings,
    textures: &'a mut TextureEvaluator<S>,
    material: &'a Material,
    si: &SurfaceInteraction,
    vertex: Option<&Vertex>,
    var: DMat2,
    shift: CentreShift,
) -> &'a [graph::Filtered] {
    if material.graphs.is_empty() {
        &[]
    } else if settings.free_textures {
        &material.constant_outputs
    } else {
        let fp = match vertex {
            Some(v) => {
                let cov = footprint::uv_covariance(var, v).as_mat2() * settings.filter_scale_squared();
                let mut fp = si.graph_footprint(cov);
                fp.uv += shift.uv;
                fp.geom.p += shift.p;
                fp
            }
            None => si.graph_footprint(Mat2::ZERO),
        };
        textures.evaluate(&scene.graphs, material, &fp)
    }
}

/// How far toward the pixel centre a camera ray's first vertex moves its texture footprint, as a
/// fraction of the way.
///
/// A sample's film offset δ is drawn from the pixel filter (σ = ½ px), and the first vertex's
/// footprint is that same filter projected onto the surface (σ scaled by `k`, the texture
/// filter scale). Filtering around the sample's own hit blurs the texture twice: a render
/// converges to the texture blurred by σ√(1 + k²), not by the pixel filter. Centring the
/// footprint a fraction `c` of the way from the hit to where the pixel centre's ray meets the
/// hit's tangent plane leaves a spread of `(1 − c)σ` in the centres, so the expected texture is
/// blurred by `σ √((1 − c)² + k²)`: the pixel filter exactly (in the footprint's linear model)
/// when `c = 1 − √(1 − k²)`. For the whole footprint (`k` = 1) `c` = 1: every sample reads the
/// texture filtered over its pixel, which then adds no noise of its own.
pub fn recentre_fraction(filter_scale: f32) -> f64 {
    let k = filter_scale as f64;
    1.0 - (1.0 - k * k).max(0.0).sqrt()
}

/// Where a texture footprint is centred relative to its hit, in uv and in world space.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct CentreShift {
    uv: Vec2,
    p: Vec3,
}

/// The offset from a camera ray's first hit `v` to its texture footprint's centre
/// ([`recentre_fraction`] of the way to the pixel centre's ray's hit on the tangent plane); zero
/// for estimators other than the covariance tracker (the ray cone and pbrt-style differentials
/// keep their published centring), when the centre's ray does not meet the plane in front of
/// the camera, or for a non-finite result.
fn first_vertex_shift(settings: &RenderSettings, cam: &CameraRay, v: &Vertex) -> CentreShift {
    if settings.footprint != FootprintMode::Covariance || cam.film_offset == Vec2::ZERO {
        return CentreShift::default();
    }
    let c = recentre_fraction(settings.filter_scale.at(settings.spp));
    // The pixel centre's ray (directions are linear in film position) meets the hit's tangent
    // plane at `pc`; nothing to move toward when it leaves parallel to or away from the plane.
    let o = cam.ray.o.as_dvec3();
    let dc = (cam.d_unnormalised - cam.dd_dx * cam.film_offset.x - cam.dd_dy * cam.film_offset.y).as_dvec3();
    let local = v.local();
    let g = local.geometric_normal;
    let (num, den) = ((v.p - o).dot(g), dc.dot(g));
    if !(num * den > 0.0) {
        return CentreShift::default();
    }
    let d = o + dc * (num / den) - v.p;
    let shift = DVec2::new(d.dot(v.t), d.dot(v.b)) * c;
    if !(shift.is_finite() && shift.length_squared() <= footprint::MAX_VARIANCE) {
        return CentreShift::default();
    }
    CentreShift { uv: (local.uv_jacobian * shift).as_vec2(), p: (v.t * shift.x + v.b * shift.y).as_vec3() }
}

/// The material's BSDF at a hit and the shading frame it is evaluated in (bent by a
/// graph-driven normal).
fn shade_bsdf(material: &Material, si: &SurfaceInteraction, ctx: &ShadeContext) -> (crate::bsdf::Bsdf, Frame) {
    let bsdf = material.bsdf.at(ctx);
    let frame = match material.normal_slot {
        Some(slot) => {
            let f = &ctx.outputs[slot as usize];
            crate::shading::perturbed_frame(&si.sh, Vec3::new(f.ch[0].mean, f.ch[1].mean, f.ch[2].mean))
        }
        None => si.sh,
    };
    (bsdf, frame)
}

/// What a shadow ray lets through: 0 when an opaque surface blocks it, otherwise the product of
/// `1 − o` over the partly transparent surfaces it crosses (deterministically: no surface is
/// sampled as blocking, so next-event estimation stays unbiased). Each opacity is evaluated
/// filtered over the footprint the path would carry there, had its BSDF sampled the light's
/// direction (`from`: the path's footprint state at the shading point, its vertex and
/// [`shadow_scatter`]'s record; a point without it).
fn transmittance<S: GraphSource>(
    scene: &Scene,
    settings: &RenderSettings,
    textures: &mut TextureEvaluator<S>,
    mut shadow: Ray,
    from: Option<(&PathFootprint, &Vertex, &crate::bsdf::BsdfSample)>,
) -> Spectrum {
    if !scene.masked {
        return if scene.accel.occluded(&scene.shapes, &shadow) { Spectrum::ZERO } else { Spectrum::ONE };
    }
    let mut tr = Spectrum::ONE;
    for _ in 0..MAX_PASS_THROUGH {
        let Some(hit) = scene.accel.intersect(&scene.shapes, &shadow) else {
            return tr;
        };
        let material = &scene.materials[scene.shapes[hit.shape as usize].material as usize];
        if !material.bsdf.is_masked() {
            return Spectrum::ZERO;
        }
        let si = interaction(&scene.shapes, &shadow, &hit);
        let (vertex, var) = match from {
            Some((fp, cur, bs)) if !material.graphs.is_empty() => {
                let v = si.footprint_vertex();
                let mut state = *fp;
                let var = state.advance(cur, bs, shadow.d, &v);
                (Some(v), var)
            }
            _ => (None, DMat2::ZERO),
        };
        let outputs =
            material_outputs(scene, settings, textures, material, &si, vertex.as_ref(), var, CentreShift::default());
        tr *= Spectrum::ONE - material.bsdf.opacity(&ShadeContext { uv: si.uv, outputs });
        if max_component(tr) <= 0.0 {
            return Spectrum::ZERO;
        }
        shadow.tmin = past(&si, hit.t);
        if !(shadow.tmin < shadow.tmax) {
            return tr;
        }
    }
    // As many surfaces crossed as a path may pass through: anything more blocks.
    if scene.accel.occluded(&scene.shapes, &shadow) {
        Spectrum::ZERO
    } else {
        tr
    }
}

/// Incident radiance along a camera ray (Mitsuba's `path` integrator), with the path's
/// footprints tracked by `settings.footprint` and reported to `obs`.
///
/// Partly transparent surfaces ([`crate::bsdf::BsdfDesc::Mask`], opacity `o` per channel) are
/// the BSDF with weight `o` plus a straight pass-through with weight `1 − o`. A camera or
/// bounce ray picks one at random, the BSDF with probability `p` = the mean of `o`, and weighs
/// the path by `o/p` or `(1 − o)/(1 − p)` per channel (no random number is drawn when `p` is 0
/// or 1). Passing through continues the same ray past the hit: it is not a bounce (depth,
/// Russian roulette and the MIS state of the last scattering vertex are untouched) and it
/// leaves the path's footprint as if the surface were absent; the opacity itself is filtered
/// over the current ray's footprint projected onto the surface. At most [`MAX_PASS_THROUGH`]
/// pass-throughs in a row. Shadow rays are attenuated by `1 − o` of every such surface they
/// cross ([`transmittance`]). For MIS, the BSDF strategy's density at a partly transparent
/// vertex is `p` times the BSDF's (what the mixture samples), both at emitter hits and in
/// next-event estimation. Emission of a partly transparent emitter is not masked (Mitsuba's
/// emitters are separate from their shape's BSDF).
pub fn radiance<S: GraphSource, O: PathObserver>(
    scene: &Scene,
    settings_r: RenderSettings,
    cam: &CameraRay,
    rng: &mut Rng,
    counts: &mut RenderCounts,
    textures: &mut TextureEvaluator<S>,
    obs: &mut O,
) -> Spectrum {
    let settings = scene.integrator;
    let n_emitters = scene.emitters.len();
    let select_pdf = if n_emitters > 0 { 1.0 / n_emitters as f32 } else { 0.0 };
    let mut ray = cam.ray;
    let mut throughput = Spectrum::ONE;
    let mut result = Spectrum::ZERO;
    let mut eta = 1.0f32;
    let mut depth = 0u32;
    // Where the previous BSDF sample came from, for MIS on emitters hit by chance.
    let mut prev_p = ray.o;
    let mut prev_pdf = 0.0f32;
    let mut prev_delta = true;
    // Footprint state: the estimator, the previous vertex and what was sampled there.
    // Footprints cost a few hundred nanoseconds per bounce: track them only when a material's
    // textures or the observer will read them.
    let track = settings_r.footprint != FootprintMode::None
        && ((scene.footprints_needed && !settings_r.free_textures) || O::WANTS_FOOTPRINTS);
    let mut fp = PathFootprint::None;
    let mut prev_vertex: Option<Vertex> = None;
    let mut prev_bs: Option<crate::bsdf::BsdfSample> = None;
    // Surfaces passed straight through since the last scattering vertex.
    let mut passes = 0u32;
    loop {
        textures.depth = depth;
        counts.rays += 1;
        let hit = scene.accel.intersect(&scene.shapes, &ray);
        let Some(hit) = hit else {
            for &ei in &scene.infinite {
                let e = &scene.emitters[ei as usize];
                let le = e.eval_escape(ray.d);
                let w = if prev_delta {
                    1.0
                } else {
                    mis(prev_pdf, select_pdf * e.pdf(&scene.shapes, prev_p, Vec3::ZERO, Vec3::ZERO, ray.d))
                };
                result += throughput * le * w;
            }
            obs.escape(depth, ray.d);
            break;
        };
        let si = interaction(&scene.shapes, &ray, &hit);
        let shape = &scene.shapes[si.shape as usize];
        let material = &scene.materials[shape.material as usize];
        let vertex = if track { Some(si.footprint_vertex()) } else { None };
        // The footprint here, carried from the last scattering vertex (or the camera) along this
        // ray; the path keeps it only if it scatters here.
        let (fp_here, var) = match (&vertex, &prev_vertex, &prev_bs) {
            (Some(v), None, _) => PathFootprint::start(settings_r.footprint, &scene.camera, cam, v, settings_r.spp),
            (Some(v), Some(pv), Some(bs)) => {
                let mut state = fp;
                let var = state.advance(pv, bs, ray.d, v);
                (state, var)
            }
            _ => (fp, DMat2::ZERO),
        };
        // On the camera ray, textures are filtered around the pixel centre's hit.
        let shift = match (&vertex, &prev_vertex) {
            (Some(v), None) => first_vertex_shift(&settings_r, cam, v),
            _ => CentreShift::default(),
        };
        if let Some(ei) = shape.emitter {
            let e = &scene.emitters[ei as usize];
            if let crate::emitter::Emitter::Area { radiance, .. } = e {
                if si.sh.n.dot(-ray.d) > 0.0 {
                    let w = if prev_delta {
                        1.0
                    } else {
                        mis(prev_pdf, select_pdf * e.pdf(&scene.shapes, prev_p, si.p, si.sh.n, ray.d))
                    };
                    result += throughput * *radiance * w;
                }
            }
        }
        // Partial opacity: scatter here (probability `p`) or pass straight through.
        let mut scatter_pdf = 1.0f32;
        let mut shaded = None;
        if material.bsdf.is_masked() {
            let outputs = material_outputs(scene, &settings_r, textures, material, &si, vertex.as_ref(), var, shift);
            let ctx = ShadeContext { uv: si.uv, outputs };
            let o = material.bsdf.opacity(&ctx);
            let p = (o.x + o.y + o.z) / 3.0;
            let scatter = p >= 1.0 || (p > 0.0 && rng.next_f32() < p);
            if !scatter {
                throughput *= (Spectrum::ONE - o) / (1.0 - p);
                passes += 1;
                if passes > MAX_PASS_THROUGH || max_component(throughput) <= 0.0 {
                    break;
                }
                ray.tmin = past(&si, hit.t);
                continue;
            }
            if p < 1.0 {
                throughput *= o / p;
                scatter_pdf = p;
            }
            shaded = Some(shade_bsdf(material, &si, &ctx));
        }
        passes = 0;
        fp = fp_here;
        obs.hit(depth, &si, vertex.as_ref(), var);
        if depth + 1 >= settings.max_depth {
            obs.event(depth, if shape.emitter.is_some() { Event::Emit } else { Event::Absorb }, 0.0, 1.0);
            break;
        }
        let (bsdf, frame) = match shaded {
            Some(s) => s,
            None => {
                // Procedural textures are filtered to the vertex's uv footprint (a point without one).
                let outputs = material_outputs(scene, &settings_r, textures, material, &si, vertex.as_ref(), var, shift);
                shade_bsdf(material, &si, &ShadeContext { uv: si.uv, outputs })
            }
        };
        // A graph-driven shading normal bends the frame the BSDF is evaluated in.
        let mut si = si;
        si.sh = frame;
        let wi = si.sh.to_local(-ray.d);

        // Next-event estimation.
        if n_emitters > 0 && bsdf.has_smooth() {
            let pick = ((rng.next_f32() * n_emitters as f32) as usize).min(n_emitters - 1);
            let u = rng.next_2d();
            let e = &scene.emitters[pick];
            if let Some(es) = e.sample(&scene.shapes, si.p, u) {
                let wo = si.sh.to_local(es.wi);
                let f = bsdf.eval(wi, wo);
                if es.pdf > 0.0 && max_component(f) > 0.0 && max_component(es.value) > 0.0 {
                    let mut shadow = spawn_ray(&si, es.wi);
                    if es.dist.is_finite() {
                        shadow.tmax = es.dist - ray_epsilon(si.p + es.wi * es.dist) - (shadow.o - si.p).length();
                    }
                    counts.shadow_rays += 1;
                    if shadow.tmax > 0.0 {
                        let toward = match (&vertex, scene.masked) {
                            (Some(v), true) => Some((v, shadow_scatter(&bsdf, wi, wo))),
                            _ => None,
                        };
                        let from = toward.as_ref().map(|(v, bs)| (&fp, *v, bs));
                        let tr = transmittance(scene, &settings_r, textures, shadow, from);
                        if max_component(tr) > 0.0 {
                            let light_pdf = select_pdf * es.pdf;
                            let w = if es.delta { 1.0 } else { mis(light_pdf, scatter_pdf * bsdf.pdf(wi, wo)) };
                            result += throughput * f * es.value * tr * (w / light_pdf);
                        }
                    }
                }
            }
        }

        // Continue the path by sampling the BSDF.
        let u_lobe = rng.next_f32();
        let u = rng.next_2d();
        let ended = if shape.emitter.is_some() { Event::Emit } else { Event::Absorb };
        let Some(bs) = bsdf.sample(wi, u_lobe, u) else {
            obs.event(depth, ended, 0.0, 1.0);
            break;
        };
        if !(bs.pdf > 0.0) || !bs.weight.is_finite() || max_component(bs.weight) <= 0.0 {
            obs.event(depth, ended, 0.0, 1.0);
            break;
        }
        let event = match (bs.kind, bs.transmitted) {
            (_, true) => Event::Refract,
            (crate::bsdf::LobeKind::Diffuse, false) => Event::Diffuse,
            _ => Event::Reflect,
        };
        obs.event(depth, event, bs.alpha, bs.eta);
        throughput *= bs.weight;
        eta *= bs.eta;
        prev_p = si.p;
        prev_pdf = bs.pdf * scatter_pdf;
        prev_delta = matches!(bs.kind, crate::bsdf::LobeKind::Specular);
        ray = spawn_ray(&si, si.sh.to_world(bs.wo));
        depth += 1;
        if track {
            prev_vertex = vertex;
            prev_bs = Some(bs);
        }

        if depth >= settings.rr_depth {
            let q = (max_component(throughput) * eta * eta).min(0.95);
            if !(rng.next_f32() < q) {
                break;
            }
            throughput /= q;
        }
    }
    result
}
