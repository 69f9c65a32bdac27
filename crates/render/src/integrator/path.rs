//! One camera ray's radiance: the loop over its path's vertices, and the pieces each vertex
//! calls — emission met by chance, the pass-through of partly transparent surfaces, next-event
//! estimation with its shadow rays' transmittance, and the footprint the path carries.
//!
//! The loop follows Mitsuba 3's `path` integrator (`max_depth`, `rr_depth`, MIS by the power
//! heuristic); it reads like pbrt's `PathIntegrator::Li`, with [`FootprintCarrier`] owning the
//! footprint state that pbrt keeps in its ray differentials.

use super::{Event, PathObserver, RenderCounts, RenderSettings};
use crate::bsdf::{Bsdf, BsdfSample, LobeKind};
use crate::camera::{Camera, CameraRay};
use crate::emitter::Emitter;
use crate::geometry::{interaction, interaction_with, Intersector, Ray, SurfaceInteraction};
use crate::material::Material;
use crate::math::{max_component, Frame, Spectrum};
use crate::pathfootprint::{shadow_scatter, FootprintMode, PathFootprint};
use crate::sampling::Rng;
use crate::scene::Scene;
use crate::shading::{GraphSource, PixelKey, TextureEvaluator};
use crate::texture::ShadeContext;
use footprint::{LocalGeometry, Vertex};
use glam::{DMat2, DVec2, DVec3, Mat2, Vec2, Vec3};

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
fn first_vertex_shift(
    settings: &RenderSettings,
    cam: &CameraRay,
    v: &Vertex,
    (local, g): (&LocalGeometry, DVec3),
) -> CentreShift {
    if settings.footprint != FootprintMode::Covariance || cam.film_offset == Vec2::ZERO {
        return CentreShift::default();
    }
    let c = recentre_fraction(settings.filter_scale.at(settings.spp));
    // The pixel centre's ray (directions are linear in film position) meets the hit's tangent
    // plane at `pc`; nothing to move toward when it leaves parallel to or away from the plane.
    let o = cam.ray.o.as_dvec3();
    let dc = (cam.d_unnormalised - cam.dd_dx * cam.film_offset.x - cam.dd_dy * cam.film_offset.y).as_dvec3();
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

/// Whether camera rays' first hits, and the hits they reach through perfect mirrors and smooth
/// dielectrics, read their pixel's shared textures: with covariance
/// footprints centred all the way on the pixel centre (the whole footprint as the filter,
/// [`recentre_fraction`] 1), unless [`RenderSettings::per_sample_textures`] asks otherwise.
pub fn shares_pixel_textures(settings: &RenderSettings) -> bool {
    !settings.per_sample_textures
        && settings.footprint == FootprintMode::Covariance
        && recentre_fraction(settings.filter_scale.at(settings.spp)) >= 1.0
}

/// What a material's textures are filtered over at a hit: the hit as a footprint vertex (none
/// when footprints are not tracked: textures are then read at a point, the default), the
/// path's tangent-plane covariance there, and where the filter is centred relative to the hit.
/// `pixel`: the hit's key among the pixel's shared textures ([`TextureEvaluator::begin_pixel`]),
/// where it has one: the camera ray's hit, or a hit the path reached from there through perfect
/// mirrors and smooth dielectrics without textures (whether or not the hit reads the entry;
/// `shared` is the entry it reads).
#[derive(Clone, Copy, Debug, Default)]
struct TextureFootprint {
    vertex: Option<Vertex>,
    var: DMat2,
    /// The vertex's uv Jacobian ([`LocalGeometry::uv_jacobian`]; zero without a vertex).
    uv_jacobian: DMat2,
    shift: CentreShift,
    pixel: Option<PixelKey>,
    /// The pixel's entry whose textures this hit reads (decided before its footprint, which it
    /// then does not need: see [`Tracer::shared_entry`]).
    shared: Option<usize>,
}

/// Film offsets (pixels) from a pixel's centre, nearest first, whose camera rays stand in for
/// the centre's where it does not reach the surface a pixel's shared textures are for
/// ([`Tracer::pixel_centre_footprint`]): along the axes and the diagonals, a quarter, half,
/// one and one and a half pixels out per axis, within the reach of the widest pixel filter's
/// samples (a Gaussian's, to two pixels).
const SILHOUETTE_OFFSETS: [(f32, f32); 32] = {
    let mut out = [(0.0, 0.0); 32];
    let radii = [0.25f32, 0.5, 1.0, 1.5];
    let dirs =
        [(1.0f32, 0.0f32), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0), (1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)];
    let mut i = 0;
    while i < 32 {
        let (r, (dx, dy)) = (radii[i / 8], dirs[i % 8]);
        out[i] = (r * dx, r * dy);
        i += 1;
    }
    out
};

/// A vertex the path scattered at whose footprint nothing read: the estimator advances through
/// it only when a later vertex's footprint is read ([`FootprintCarrier`]).
#[derive(Clone, Copy, Debug)]
struct Deferred {
    vertex: Vertex,
    /// The direction the path arrived along.
    d: Vec3,
    /// The BSDF sample the path left by.
    bs: BsdfSample,
}

/// How many deferred vertices a path holds before advancing through the oldest.
const DEFERRED: usize = 4;

/// The footprint a camera path carries from vertex to vertex (pbrt carries its ray
/// differentials the same way).
///
/// Footprints are computed only where read. A hit whose material has no textures, or whose
/// textures come from its pixel's shared evaluation (decided from its texture coordinates
/// alone), and whose footprint neither the observer nor a shadow ray's crossings read, is
/// deferred: the estimator advances through it, with the same arithmetic in the same order,
/// when a later hit's textures need their footprint, and never if none does. Most camera
/// paths' footprints were computed for nothing: a first hit that reads its pixel's textures,
/// then a plain wall and the sky.
///
/// `TRACK`: whether footprints are tracked at all (they cost a few hundred nanoseconds per
/// bounce, so only when a material's textures or the observer will read them; see
/// [`footprints_tracked`]). A constant, so that a render without textures compiles its path
/// loop without any of this.
struct FootprintCarrier<'c, const TRACK: bool> {
    /// Whether hits whose footprint nothing reads there (no textures, or the pixel's shared
    /// ones) may be deferred: not when the observer reads every
    /// footprint, nor where shadow rays cross partly transparent surfaces (their footprints
    /// start from the shading vertex's state), nor when the settings ask for every footprint
    /// ([`RenderSettings::eager_footprints`]).
    defer: bool,
    /// Footprints computed so far (starts and advances).
    computed: u32,
    /// The estimator's state after the last scattering vertex advanced through (or at the
    /// camera), `states[cur]`, and at a partly transparent hit the path reached last,
    /// `states[1 − cur]` (written by [`Self::arrive`]): scattering there flips `cur` (at an
    /// opaque hit the state advances in place). A state is most of a kilobyte; copied
    /// out of the carrier at every hit and back at every scattering vertex, it was 8 % of an
    /// untextured render.
    states: [PathFootprint; 2],
    cur: usize,
    /// Whether [`Self::arrive`] advanced into `states[1 − cur]` (at a partly transparent
    /// surface, which the path may pass through keeping `states[cur]`), for [`Self::scatter_at`]
    /// to flip to. At an opaque one the path scatters or ends, and the state advances in place:
    /// no copy of it to keep.
    advanced_aside: bool,
    /// The BSDF sample taken at the last scattering vertex advanced through; `None` before the
    /// first.
    last: Option<BsdfSample>,
    /// That vertex, kept where the estimator reads it (ray cones and differentials; the
    /// covariance tracker keeps its own): a quarter of a kilobyte copied at every bounce.
    last_vertex: Vertex,
    /// The direction the last hit was reached along, when its footprint was deferred.
    arrived: Option<Vec3>,
    /// Scattering vertices after `last`, oldest first, not yet advanced through.
    deferred: [Option<Deferred>; DEFERRED],
    n_deferred: usize,
    /// What starting the estimator at a deferred first hit reads.
    camera: &'c Camera,
    cam: &'c CameraRay,
    mode: FootprintMode,
    spp: u32,
}

/// The estimator started at a camera ray's first hit `v` (the camera `cam` of `camera`): its
/// state, `var(Δx₁)`, and `v`'s local geometry with its geometric normal (which the recentring
/// reads too). The one start of an eager first hit, a deferred one and a pixel centre's ray.
fn start_at(
    mode: FootprintMode,
    camera: &Camera,
    cam: &CameraRay,
    v: &Vertex,
    spp: u32,
) -> (PathFootprint, DMat2, LocalGeometry, DVec3) {
    let local = v.local();
    let g = local.geometric_normal(v.n);
    let (state, var) = PathFootprint::start(mode, camera, cam, v, (&local, g), spp);
    (state, var, local, g)
}

/// Whether camera paths carry footprints: an estimator is chosen, and a material's textures (not
/// replaced by their means) or the observer read them.
fn footprints_tracked(scene: &Scene, settings: &RenderSettings, observer_wants_footprints: bool) -> bool {
    settings.footprint != FootprintMode::None
        && ((scene.footprints_needed && !settings.free_textures) || observer_wants_footprints)
}

impl<'c, const TRACK: bool> FootprintCarrier<'c, TRACK> {
    fn new(scene: &'c Scene, settings: &RenderSettings, cam: &'c CameraRay, observer_wants_footprints: bool) -> Self {
        FootprintCarrier {
            defer: !observer_wants_footprints && !scene.masked && !settings.eager_footprints,
            computed: 0,
            states: [PathFootprint::None; 2],
            cur: 0,
            advanced_aside: false,
            last: None,
            last_vertex: Vertex::point(glam::DVec3::ZERO),
            arrived: None,
            deferred: [None; DEFERRED],
            n_deferred: 0,
            camera: &scene.camera,
            cam,
            mode: settings.footprint,
            spp: settings.spp,
        }
    }

    /// Whether the estimator reads the last scattering vertex (`last_vertex`): every one but the
    /// covariance tracker, which keeps its own.
    #[inline]
    fn keeps_vertex(&self) -> bool {
        self.mode != FootprintMode::Covariance
    }

    /// The estimator's state at the last scattering vertex (advanced through every deferred
    /// one only where shadow rays read it: see `defer`).
    fn state(&self) -> &PathFootprint {
        &self.states[self.cur]
    }

    /// Advances the estimator through the deferred vertices, oldest first, exactly as
    /// [`Self::arrive`] would have on reaching each.
    #[inline(never)]
    fn catch_up(&mut self) {
        let n = self.n_deferred;
        // Read in place: a deferred vertex is a quarter of a kilobyte, and moving each out of
        // the queue before advancing through it doubled the copies.
        let keeps_vertex = self.keeps_vertex();
        let FootprintCarrier { deferred, states, cur, last, last_vertex, camera, cam, mode, spp, .. } = self;
        let state = &mut states[*cur];
        for e in deferred[..n].iter().flatten() {
            match last {
                None => *state = start_at(*mode, camera, cam, &e.vertex, *spp).0,
                Some(bs) => {
                    state.advance(last_vertex, bs, e.d, &e.vertex);
                }
            }
            *last = Some(e.bs);
            if keeps_vertex {
                *last_vertex = e.vertex;
            }
        }
        self.computed += n as u32;
        self.n_deferred = 0;
    }

    /// Adds the path's footprints, computed and skipped, to `counts` (when it ends).
    fn count_into(&self, counts: &mut RenderCounts) {
        if !TRACK {
            return;
        }
        counts.footprints += u64::from(self.computed);
        counts.footprints_skipped += (self.n_deferred + usize::from(self.arrived.is_some())) as u64;
    }

    /// The footprint at hit `si`, carried along direction `d` from the last scattering vertex
    /// (or the camera); on the camera ray, textures are filtered around the pixel centre's hit.
    /// At an `opaque` hit, where the path scatters or ends, the estimator's state advances in
    /// place; at a partly transparent one it is kept aside until the path scatters at `si`. Where
    /// `read` is false (the hit's material has no textures, or reads its pixel's) the footprint
    /// may be deferred: the answer then has the vertex alone.
    fn arrive(
        &mut self,
        settings: &RenderSettings,
        si: &SurfaceInteraction,
        d: Vec3,
        read: bool,
        opaque: bool,
    ) -> TextureFootprint {
        if !TRACK {
            return TextureFootprint::default();
        }
        let v = si.footprint_vertex();
        if self.defer && !read {
            self.arrived = Some(d);
            return TextureFootprint { vertex: Some(v), ..TextureFootprint::default() };
        }
        self.arrived = None;
        if self.n_deferred > 0 {
            self.catch_up();
        }
        self.computed += 1;
        let next = if opaque { self.cur } else { 1 - self.cur };
        self.advanced_aside = !opaque;
        let (var, uv_jacobian, shift) = match &self.last {
            None => {
                // The first hit's local geometry serves the tracker's start, the recentring and
                // the texture footprint: computed once (it was four times).
                let (state, var, local, g) = start_at(self.mode, self.camera, self.cam, &v, self.spp);
                self.states[next] = state;
                let shift = first_vertex_shift(settings, self.cam, &v, (&local, g));
                (var, local.uv_jacobian, shift)
            }
            Some(bs) => {
                if next != self.cur {
                    self.states[next] = self.states[self.cur];
                }
                let var = self.states[next].advance(&self.last_vertex, bs, d, &v);
                (var, self.states[next].uv_jacobian(&v), CentreShift::default())
            }
        };
        TextureFootprint { vertex: Some(v), var, uv_jacobian, shift, pixel: None, shared: None }
    }

    /// The path scatters at the hit it arrived at last: it keeps the footprint there (a
    /// deferred hit joins the deferred vertices when its BSDF sample is known).
    fn scatter_at(&mut self) {
        if TRACK && self.arrived.is_none() && self.advanced_aside {
            self.cur = 1 - self.cur;
        }
    }

    /// The path left the hit with footprint `here` by BSDF sample `bs`.
    fn sampled(&mut self, here: &TextureFootprint, bs: BsdfSample) {
        if !TRACK {
            return;
        }
        let Some(v) = here.vertex else { return };
        match self.arrived.take() {
            None => {
                self.last = Some(bs);
                if self.keeps_vertex() {
                    self.last_vertex = v;
                }
            }
            Some(d) => {
                if self.n_deferred == DEFERRED {
                    self.catch_up();
                }
                self.deferred[self.n_deferred] = Some(Deferred { vertex: v, d, bs });
                self.n_deferred += 1;
            }
        }
    }
}

/// Where the last BSDF sample came from, for MIS on emitters the path then meets by chance.
#[derive(Clone, Copy, Debug)]
struct LastScatter {
    p: Vec3,
    /// The density the path's strategy sampled its direction with.
    pdf: f32,
    /// A specular (or camera) sample: emitters met are counted whole.
    delta: bool,
}

/// What every vertex of one camera path reads and writes besides the path's own state: the
/// scene, the render settings, the thread's texture evaluator and counters.
struct Tracer<'a, 't, S> {
    scene: &'a Scene,
    settings: RenderSettings,
    textures: &'t mut TextureEvaluator<S>,
    counts: &'t mut RenderCounts,
    /// Probability of picking each emitter for next-event estimation.
    select_pdf: f32,
}

impl<'a, S: GraphSource> Tracer<'a, '_, S> {
    /// The material's graph outputs at hit `si`, filtered over the uv footprint that `tf` gives
    /// there; a point without a vertex, the means with `--free-textures`, nothing for a material
    /// without graphs.
    fn material_outputs<'s>(
        &'s mut self,
        material: &'a Material,
        si: &SurfaceInteraction,
        tf: &TextureFootprint,
    ) -> &'s [graph::Filtered] {
        if material.graphs.is_empty() {
            &[]
        } else if self.settings.free_textures {
            &material.constant_outputs
        } else if let Some(k) = tf.shared {
            self.textures.first_hit_outputs(k, material)
        } else {
            let fp = match &tf.vertex {
                Some(_) => {
                    let mut fp = self.graph_footprint(si, tf.uv_jacobian, tf.var);
                    fp.uv += tf.shift.uv;
                    fp.geom.p += tf.shift.p;
                    fp
                }
                None => si.graph_footprint(Mat2::ZERO),
            };
            self.textures.evaluate(&self.scene.graphs, material, &fp)
        }
    }

    /// The entry of the pixel's shared textures for `key` (made on the pixel's first sample to
    /// reach it) that a sample whose hit on the key's last surface is `si` reads, if it may read
    /// one (`TextureEvaluator::first_hit_accepts`: near the entry's centre in texture
    /// coordinates and in space). Decided before the sample's own footprint there, which a
    /// sample that reads the entry then does not need (it is computed only if a later hit reads
    /// textures).
    fn shared_entry(&mut self, material: &'a Material, key: &PixelKey, si: &SurfaceInteraction) -> Option<usize> {
        let k = match self.textures.first_hit(key) {
            Some(k) => k,
            None => {
                let centre = self.pixel_centre_footprint(key);
                let (k, evaluated) = self.textures.keep_first_hit(&self.scene.graphs, material, *key, centre);
                self.counts.pixel_texture_evaluations += u64::from(evaluated);
                k
            }
        };
        let read = self.textures.first_hit_accepts(k, si.uv, si.p);
        if read {
            self.counts.pixel_texture_reads += 1;
        } else {
            self.counts.pixel_texture_misses += 1;
        }
        read.then_some(k)
    }

    /// The footprint textures are filtered over where the current pixel's centre ray (the
    /// camera ray with no film offset) meets the key's last surface, having met the others
    /// before it and scattered at each the key's way (reflected or refracted; their materials
    /// have no textures and perfectly specular BSDFs, so the way is the whole choice). Each
    /// surface is met wherever the ray meets it, in front of the others or not, as a first hit's
    /// is.
    ///
    /// Where the centre's ray misses a surface (the pixel straddles a silhouette) or cannot
    /// scatter the key's way, the first of [`SILHOUETTE_OFFSETS`] whose ray reaches the key's
    /// last surface takes its place: the samples that reach it there then share one evaluation
    /// instead of each making its own, which cost a silhouette pixel one evaluation per sample
    /// (the misses grew with the sample count: at 64 spp a third as many as the pixels' own
    /// evaluations on tiles_planks). The points are fixed, so what a sample reads still depends
    /// on its pixel and key alone. `None` when no ray of them reaches it.
    #[inline(never)]
    fn pixel_centre_footprint(&self, key: &PixelKey) -> Option<(graph::Footprint, f64)> {
        let (x, y) = self.textures.pixel()?;
        let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
        std::iter::once(Vec2::ZERO)
            .chain(SILHOUETTE_OFFSETS.iter().map(|&(dx, dy)| Vec2::new(dx, dy)))
            .find_map(|offset| self.pixel_footprint_at(key, centre + offset))
    }

    /// [`Self::pixel_centre_footprint`] for the camera ray through film point `film`.
    fn pixel_footprint_at(&self, key: &PixelKey, film: Vec2) -> Option<(graph::Footprint, f64)> {
        let scene = self.scene;
        let cam = scene.camera.generate_ray(film);
        let shapes = key.shapes();
        let mut ray = cam.ray;
        let hit = scene.accel.intersect_shape(&scene.shapes, &ray, shapes[0])?;
        let mut si = interaction(&scene.shapes, &ray, &hit);
        let mut v = si.footprint_vertex();
        let (mut state, mut var, local, _) =
            start_at(self.settings.footprint, &scene.camera, &cam, &v, self.settings.spp);
        let mut uv_jacobian = local.uv_jacobian;
        for (k, &shape) in shapes.iter().enumerate().skip(1) {
            let material = &scene.materials[scene.shapes[shapes[k - 1] as usize].material as usize];
            let bsdf = material.bsdf.at(&ShadeContext { uv: si.uv, outputs: &[] });
            let refracted = key.refracted_at(k - 1);
            // A smooth dielectric reflects when `u_lobe` is below the Fresnel reflectance.
            let u_lobe = if refracted { 1.0 - f32::EPSILON / 2.0 } else { 0.0 };
            let bs = bsdf.sample(si.sh.to_local(-ray.d), u_lobe, Vec2::splat(0.5))?;
            if bs.kind != LobeKind::Specular || bs.transmitted != refracted {
                return None;
            }
            let d = si.sh.to_world(bs.wo);
            ray = spawn_ray(&si, d);
            let hit = scene.accel.intersect_shape(&scene.shapes, &ray, shape)?;
            let next = interaction(&scene.shapes, &ray, &hit);
            let nv = next.footprint_vertex();
            var = state.advance(&v, &bs, d, &nv);
            uv_jacobian = state.uv_jacobian(&nv);
            (si, v) = (next, nv);
        }
        let fp = self.graph_footprint(&si, uv_jacobian, var);
        // The tangent-plane covariance's larger eigenvalue: the footprint's spread in space.
        let spread = footprint::mat::sym_eigen(var).0;
        (fp.uv.is_finite() && fp.cov.is_finite() && spread.is_finite()).then_some((fp, spread))
    }

    /// The footprint graphs are evaluated over at hit `si` (whose vertex has uv Jacobian
    /// `uv_jacobian`) whose tangent-plane covariance is `var`, scaled by the texture filter,
    /// centred on the hit.
    fn graph_footprint(&self, si: &SurfaceInteraction, uv_jacobian: DMat2, var: DMat2) -> graph::Footprint {
        si.graph_footprint(
            footprint::uv_covariance_with(var, uv_jacobian).as_mat2() * self.settings.filter_scale_squared(),
        )
    }

    /// What a shadow ray lets through: 0 when an opaque surface blocks it, otherwise the
    /// product of `1 − o` over the partly transparent surfaces it crosses (deterministically: no
    /// surface is sampled as blocking, so next-event estimation stays unbiased). Each opacity is
    /// evaluated filtered over the footprint the path would carry there, had its BSDF sampled
    /// the light's direction (`from`: the path's footprint state at the shading point, its
    /// vertex and [`shadow_scatter`]'s record; a point without it).
    fn transmittance(&mut self, mut shadow: Ray, from: Option<(&PathFootprint, &Vertex, &BsdfSample)>) -> Spectrum {
        let scene = self.scene;
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
            let tf = match from {
                Some((fp, cur, bs)) if !material.graphs.is_empty() => {
                    let v = si.footprint_vertex();
                    let mut state = *fp;
                    let var = state.advance(cur, bs, shadow.d, &v);
                    let uv_jacobian = state.uv_jacobian(&v);
                    TextureFootprint {
                        vertex: Some(v),
                        var,
                        uv_jacobian,
                        shift: CentreShift::default(),
                        pixel: None,
                        shared: None,
                    }
                }
                _ => TextureFootprint::default(),
            };
            let outputs = self.material_outputs(material, &si, &tf);
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

    /// Next-event estimation at `si` for a path of weight `throughput`: one emitter picked at
    /// random and sampled, its light weighed by MIS against the BSDF strategy (which samples
    /// with `scatter_pdf` times the BSDF's density) and attenuated by the shadow ray's
    /// transmittance. `here` is the path's footprint at `si`, whose vertex (when tracked) the
    /// shadow ray's footprint starts from.
    #[allow(clippy::too_many_arguments)]
    fn direct_lighting(
        &mut self,
        rng: &mut Rng,
        si: &SurfaceInteraction,
        bsdf: &Bsdf,
        wi: Vec3,
        throughput: Spectrum,
        scatter_pdf: f32,
        here: (&PathFootprint, Option<&Vertex>),
    ) -> Option<Spectrum> {
        let scene = self.scene;
        let n_emitters = scene.emitters.len();
        let pick = ((rng.next_f32() * n_emitters as f32) as usize).min(n_emitters - 1);
        let u = rng.next_2d();
        let e = &scene.emitters[pick];
        let es = e.sample(&scene.shapes, si.p, u)?;
        let wo = si.sh.to_local(es.wi);
        let f = bsdf.eval(wi, wo);
        if !(es.pdf > 0.0 && max_component(f) > 0.0 && max_component(es.value) > 0.0) {
            return None;
        }
        let mut shadow = spawn_ray(si, es.wi);
        if es.dist.is_finite() {
            shadow.tmax = es.dist - ray_epsilon(si.p + es.wi * es.dist) - (shadow.o - si.p).length();
        }
        self.counts.shadow_rays += 1;
        if !(shadow.tmax > 0.0) {
            return None;
        }
        let toward = match (here.1, scene.masked) {
            (Some(v), true) => Some((v, shadow_scatter(bsdf, wi, wo))),
            _ => None,
        };
        let from = toward.as_ref().map(|(v, bs)| (here.0, *v, bs));
        let tr = self.transmittance(shadow, from);
        if !(max_component(tr) > 0.0) {
            return None;
        }
        let light_pdf = self.select_pdf * es.pdf;
        let w = if es.delta { 1.0 } else { mis(light_pdf, scatter_pdf * bsdf.pdf(wi, wo)) };
        Some(throughput * f * es.value * tr * (w / light_pdf))
    }

    /// How a path crosses hit `si` of `material` (a path of weight `throughput`, updated): a
    /// partly transparent surface is scattered at with probability `p` = the mean opacity `o`
    /// (weight `o/p`) or passed through (weight `(1 − o)/(1 − p)`), drawing a random number only
    /// when `p` is strictly between 0 and 1; an opaque one is scattered at. When the opacity was
    /// evaluated, the BSDF built from the same texture values comes with the answer.
    fn cross(
        &mut self,
        material: &'a Material,
        si: &SurfaceInteraction,
        tf: &TextureFootprint,
        rng: &mut Rng,
        throughput: &mut Spectrum,
    ) -> Crossing {
        if !material.bsdf.is_masked() {
            return Crossing::Scatter { pdf: 1.0, shaded: None };
        }
        let outputs = self.material_outputs(material, si, tf);
        let ctx = ShadeContext { uv: si.uv, outputs };
        let o = material.bsdf.opacity(&ctx);
        let p = (o.x + o.y + o.z) / 3.0;
        let scatter = p >= 1.0 || (p > 0.0 && rng.next_f32() < p);
        if !scatter {
            *throughput *= (Spectrum::ONE - o) / (1.0 - p);
            return Crossing::PassThrough;
        }
        let mut pdf = 1.0;
        if p < 1.0 {
            *throughput *= o / p;
            pdf = p;
        }
        Crossing::Scatter { pdf, shaded: Some((material.bsdf.at(&ctx), shading_frame(material, si, &ctx))) }
    }

    /// The light of `emitter` (the hit shape's, if it has one) met by chance at `si` along `d`,
    /// times the path's `throughput` and the MIS weight against next-event estimation; area
    /// lights emit on the side their normal faces.
    fn emitted(
        &self,
        emitter: Option<u32>,
        si: &SurfaceInteraction,
        d: Vec3,
        last: &LastScatter,
        throughput: Spectrum,
    ) -> Option<Spectrum> {
        let e = &self.scene.emitters[emitter? as usize];
        let Emitter::Area { radiance, .. } = e else { return None };
        if !(si.sh.n.dot(-d) > 0.0) {
            return None;
        }
        let w = self.met_weight(last, || e.pdf(&self.scene.shapes, last.p, si.p, si.sh.n, d));
        Some(throughput * *radiance * w)
    }

    /// The MIS weight of emitter `e`'s light met by chance along a ray from `last`, whose
    /// density for that direction `e` gives as `emitter_pdf` per chosen emitter.
    #[inline]
    fn met_weight(&self, last: &LastScatter, emitter_pdf: impl FnOnce() -> f32) -> f32 {
        if last.delta {
            1.0
        } else {
            mis(last.pdf, self.select_pdf * emitter_pdf())
        }
    }
}

/// How a path crosses a surface ([`Tracer::cross`]).
enum Crossing {
    /// It scatters here; the BSDF strategy's density is `pdf` times the BSDF's, and `shaded` is
    /// the BSDF and frame already built when the opacity needed the textures.
    Scatter { pdf: f32, shaded: Option<(Bsdf, Frame)> },
    /// It continues past the surface.
    PassThrough,
}

/// What the path did at a vertex whose BSDF sampled `bs`.
fn event_of(bs: &BsdfSample) -> Event {
    match (bs.kind, bs.transmitted) {
        (_, true) => Event::Refract,
        (LobeKind::Diffuse, false) => Event::Diffuse,
        _ => Event::Reflect,
    }
}

/// The shading frame a material's BSDF is evaluated in at a hit: the surface's, bent by a
/// graph-driven normal.
#[inline]
fn shading_frame(material: &Material, si: &SurfaceInteraction, ctx: &ShadeContext) -> Frame {
    match material.normal_slot {
        Some(slot) => {
            let f = &ctx.outputs[slot as usize];
            crate::shading::perturbed_frame(&si.sh, Vec3::new(f.ch[0].mean, f.ch[1].mean, f.ch[2].mean))
        }
        None => si.sh,
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
/// cross, deterministically. For MIS, the BSDF strategy's density at a partly transparent
/// vertex is `p` times the BSDF's (what the mixture samples), both at emitter hits and in
/// next-event estimation. Emission of a partly transparent emitter is not masked (Mitsuba's
/// emitters are separate from their shape's BSDF).
pub fn radiance<S: GraphSource, O: PathObserver>(
    scene: &Scene,
    settings: RenderSettings,
    cam: &CameraRay,
    rng: &mut Rng,
    counts: &mut RenderCounts,
    textures: &mut TextureEvaluator<S>,
    obs: &mut O,
) -> Spectrum {
    if footprints_tracked(scene, &settings, O::WANTS_FOOTPRINTS) {
        radiance_with::<S, O, true>(scene, settings, cam, rng, counts, textures, obs)
    } else {
        radiance_with::<S, O, false>(scene, settings, cam, rng, counts, textures, obs)
    }
}

/// [`radiance`] with footprints tracked (`TRACK`) or not.
fn radiance_with<S: GraphSource, O: PathObserver, const TRACK: bool>(
    scene: &Scene,
    settings: RenderSettings,
    cam: &CameraRay,
    rng: &mut Rng,
    counts: &mut RenderCounts,
    textures: &mut TextureEvaluator<S>,
    obs: &mut O,
) -> Spectrum {
    let path = scene.integrator;
    let n_emitters = scene.emitters.len();
    let select_pdf = if n_emitters > 0 { 1.0 / n_emitters as f32 } else { 0.0 };
    let mut tracer = Tracer { scene, settings, textures, counts, select_pdf };
    let mut ray = cam.ray;
    let mut throughput = Spectrum::ONE;
    let mut result = Spectrum::ZERO;
    let mut eta = 1.0f32;
    let mut depth = 0u32;
    let mut last = LastScatter { p: ray.o, pdf: 0.0, delta: true };
    let mut footprints = FootprintCarrier::<TRACK>::new(scene, &settings, cam, O::WANTS_FOOTPRINTS);
    // Surfaces passed straight through since the last scattering vertex.
    let mut passes = 0u32;
    // While every surface the path scattered at so far was a perfect mirror or smooth
    // dielectric without textures (and pixels share textures): the key of those surfaces and
    // whether the path refracted at the last. The next textured hit reads the pixel's textures
    // for that key.
    let shares = TRACK && shares_pixel_textures(&settings);
    let mut specular: Option<(PixelKey, bool)> = None;
    loop {
        tracer.textures.depth = depth;
        tracer.counts.rays += 1;
        let Some(hit) = scene.accel.intersect(&scene.shapes, &ray) else {
            for &ei in &scene.infinite {
                let e = &scene.emitters[ei as usize];
                let le = e.eval_escape(ray.d);
                let w = tracer.met_weight(&last, || e.pdf(&scene.shapes, last.p, Vec3::ZERO, Vec3::ZERO, ray.d));
                result += throughput * le * w;
            }
            obs.escape(depth, ray.d);
            break;
        };
        let shape = &scene.shapes[hit.shape as usize];
        let material = &scene.materials[shape.material as usize];
        // The surface's parametrisation only where a texture, a footprint or the observer reads it.
        let full = TRACK || O::WANTS_FOOTPRINTS || material.reads_uv();
        let si = interaction_with(&scene.shapes, &ray, &hit, full);
        // The pixel's shared textures this hit reads, if any: decided before its footprint, which
        // it then needs only if a later hit reads textures.
        let key = if depth == 0 {
            shares.then(|| PixelKey::first(hit.shape))
        } else {
            specular.and_then(|(key, refracted)| key.then(refracted, hit.shape))
        };
        // Textures are read here for the opacity, or for the BSDF unless the path ends here.
        let reads_textures = !material.graphs.is_empty()
            && !settings.free_textures
            && (material.bsdf.is_masked() || depth + 1 < path.max_depth);
        let shared = match &key {
            Some(key) if reads_textures => tracer.shared_entry(material, key, &si),
            _ => None,
        };
        // The footprint here; the path keeps it only if it scatters here.
        let mut here =
            footprints.arrive(&settings, &si, ray.d, reads_textures && shared.is_none(), !material.bsdf.is_masked());
        (here.pixel, here.shared) = (key, shared);
        if let Some(l) = tracer.emitted(shape.emitter, &si, ray.d, &last, throughput) {
            result += l;
        }
        // Partial opacity: scatter here (probability `p`) or pass straight through.
        let (scatter_pdf, shaded) = match tracer.cross(material, &si, &here, rng, &mut throughput) {
            Crossing::Scatter { pdf, shaded } => (pdf, shaded),
            Crossing::PassThrough => {
                passes += 1;
                if passes > MAX_PASS_THROUGH || max_component(throughput) <= 0.0 {
                    break;
                }
                ray.tmin = past(&si, hit.t);
                continue;
            }
        };
        passes = 0;
        footprints.scatter_at();
        let vertex = here.vertex.as_ref();
        obs.hit(depth, &si, vertex, here.var);
        let ended = if shape.emitter.is_some() { Event::Emit } else { Event::Absorb };
        if depth + 1 >= path.max_depth {
            obs.event(depth, ended, 0.0, 1.0);
            break;
        }
        // The BSDF is read where it was built, not moved into one place from either branch:
        // the move's wide loads stalled on the fresh narrow stores that built it (store
        // forwarding, 1.4 % of a Cornell box).
        let built;
        let bent;
        let (bsdf, frame) = match &shaded {
            Some((b, f)) => (b, f),
            None => {
                // Procedural textures are filtered to the vertex's uv footprint (a point without one).
                let outputs = tracer.material_outputs(material, &si, &here);
                let ctx = ShadeContext { uv: si.uv, outputs };
                built = material.bsdf.at(&ctx);
                // A graph-driven shading normal bends the frame the BSDF is evaluated in.
                let frame = match material.normal_slot {
                    Some(_) => {
                        bent = shading_frame(material, &si, &ctx);
                        &bent
                    }
                    None => &si.sh,
                };
                (&built, frame)
            }
        };
        // `wi` from the frame where it lies: read from a fresh copy, the frame's loads straddled
        // the copy's 16-byte stores and stalled (store forwarding; 1.5 % of a Cornell box), as
        // they did when read back from `si` right after being stored there.
        let (wi, frame) = (frame.to_local(-ray.d), *frame);
        let mut si = si;
        si.sh = frame;

        if n_emitters > 0 && bsdf.has_smooth() {
            let at = (footprints.state(), vertex);
            if let Some(l) = tracer.direct_lighting(rng, &si, bsdf, wi, throughput, scatter_pdf, at) {
                result += l;
            }
        }

        // Continue the path by sampling the BSDF.
        let u_lobe = rng.next_f32();
        let u = rng.next_2d();
        let Some(bs) = bsdf.sample(wi, u_lobe, u) else {
            obs.event(depth, ended, 0.0, 1.0);
            break;
        };
        if !(bs.pdf > 0.0) || !bs.weight.is_finite() || max_component(bs.weight) <= 0.0 {
            obs.event(depth, ended, 0.0, 1.0);
            break;
        }
        obs.event(depth, event_of(&bs), bs.alpha, bs.eta);
        throughput *= bs.weight;
        eta *= bs.eta;
        last = LastScatter { p: si.p, pdf: bs.pdf * scatter_pdf, delta: matches!(bs.kind, LobeKind::Specular) };
        ray = spawn_ray(&si, si.sh.to_world(bs.wo));
        depth += 1;
        specular = match here.pixel {
            // A hit has a key only where pixels share textures.
            Some(key) if bs.kind == LobeKind::Specular && material.graphs.is_empty() && !bsdf.has_smooth() => {
                Some((key, bs.transmitted))
            }
            _ => None,
        };
        footprints.sampled(&here, bs);

        if depth >= path.rr_depth {
            let q = (max_component(throughput) * eta * eta).min(0.95);
            if !(rng.next_f32() < q) {
                break;
            }
            throughput /= q;
        }
    }
    footprints.count_into(tracer.counts);
    result
}
