//! Graph outputs at shading points: the one seam through which the renderer asks for
//! procedural texture values.
//!
//! A shading point asks its thread's [`TextureEvaluator`] for a material's graph outputs at the
//! hit's footprint ([`TextureEvaluator::evaluate`]). The evaluator owns what every strategy
//! shares (the per-graph evaluation scratches, the output slots, the record of where values went
//! non-finite) and hands each (material, graph) request to its [`GraphSource`], which decides
//! how it is served: [`Direct`] evaluates every node, the tile cache's source
//! ([`crate::caching::CacheAccess`]) answers cached nodes from mip-mapped tiles, and the
//! profiler's ([`crate::profiling::Profiler`]) records the request's footprint and times a
//! direct evaluation. The integrator is generic over the source, so the choice costs nothing per
//! request and neither the integrator nor this module knows the cache or the profiler.

use crate::material::{Material, MaterialGraph, SceneGraph};
use glam::{DMat2, DVec2};
use graph::{EvalScratch, EvalStats, Filtered, Footprint, Graph, NoOverride};

/// How a thread's graph requests are served (see the [module docs](self)).
pub trait GraphSource {
    /// Evaluates the outputs of `request` (a material's outputs of graph `g`) at footprint `fp`
    /// into `out`, one value per output of its plan, using `scratch` (`g`'s evaluation memory).
    fn evaluate(
        &mut self,
        g: &Graph,
        request: &MaterialGraph,
        fp: &Footprint,
        scratch: &mut EvalScratch,
        out: &mut [Filtered],
    );

    /// Adds the statistics of evaluations made outside the evaluator's scratches (a cache's
    /// tile fills) to `stats`, one entry per scene graph.
    fn merge_stats_into(&self, _stats: &mut [EvalStats]) {}

    /// Camera sample `index` of a pixel starts (its path's requests follow).
    #[inline]
    fn begin_sample(&mut self, _index: u32) {}

    /// The camera sample begun last has ended.
    #[inline]
    fn end_sample(&mut self) {}

    /// The requests that follow (until called again with `false`) are ones a pixel's camera
    /// samples share ([`TextureEvaluator::begin_pixel`]).
    #[inline]
    fn shared(&mut self, _on: bool) {}
}

/// Every node evaluated on every request (shade on hit).
#[derive(Clone, Copy, Debug, Default)]
pub struct Direct;

impl GraphSource for Direct {
    #[inline]
    fn evaluate(
        &mut self,
        g: &Graph,
        request: &MaterialGraph,
        fp: &Footprint,
        scratch: &mut EvalScratch,
        out: &mut [Filtered],
    ) {
        g.eval(&request.order, fp, scratch, &NoOverride, out);
    }
}

/// How many non-finite samples a render describes (the first ones, by pixel row, column and
/// sample index, whatever the thread count).
pub const NONFINITE_KEPT: usize = 8;

/// A graph evaluation that went non-finite at a shading point.
#[derive(Clone, Debug, PartialEq)]
pub struct GraphNonFinite {
    /// The material being shaded.
    pub material: String,
    /// Index of the scene graph.
    pub graph: u32,
    /// The node that first gave a non-finite value, and the footprint.
    pub at: graph::NonFinite,
    /// The path vertex (0 = first hit).
    pub bounce: u32,
}

/// A camera sample whose radiance was not finite (and was left out of its pixel).
#[derive(Clone, Debug, PartialEq)]
pub struct NonFiniteSample {
    /// Pixel column.
    pub x: u32,
    /// Pixel row (0 = top).
    pub y: u32,
    /// Sample index within the pixel.
    pub sample: u32,
    /// The graph evaluation that went non-finite first on this sample's path, if one did (if
    /// none did, the value came from a BSDF, an emitter or the integrator).
    pub origin: Option<GraphNonFinite>,
}

impl NonFiniteSample {
    /// One line for messages: the pixel, and the material, graph node, uv, footprint and bounce
    /// where a graph value first went non-finite.
    pub fn describe(&self, graphs: &[SceneGraph]) -> String {
        let px = format!("pixel ({}, {}) sample {}", self.x, self.y, self.sample);
        match &self.origin {
            Some(o) => {
                let g = &graphs[o.graph as usize];
                format!(
                    "{px}: material '{}', graph {}: {}, bounce {}",
                    o.material,
                    g.file_name(),
                    o.at.describe(g.graph()),
                    o.bounce
                )
            }
            None => format!("{px}: no graph value was non-finite (from a BSDF, an emitter or the integrator)"),
        }
    }
}

/// A thread's evaluation of materials' graph outputs at shading points, served by its source
/// `S`: the per-graph evaluation scratches and output slots (allocated once per thread or image
/// bucket), and where values went non-finite.
pub struct TextureEvaluator<S> {
    /// The bounce (0 = first hit) of the vertex being shaded, set by the integrator: reports of
    /// non-finite values name it.
    pub(crate) depth: u32,
    /// Where the current camera sample's graph evaluations first went non-finite.
    sample_origin: Option<GraphNonFinite>,
    /// The first non-finite samples of this evaluator's pixels (at most [`NONFINITE_KEPT`]).
    pub(crate) nonfinite: Vec<NonFiniteSample>,
    /// The first samples on whose path a graph value went non-finite, whether or not the
    /// sample's radiance did (texture reads map NaN to 0); at most [`NONFINITE_KEPT`].
    pub(crate) graph_nonfinite: Vec<NonFiniteSample>,
    scratches: Vec<EvalScratch>,
    outputs: Vec<Filtered>,
    tmp: Vec<Filtered>,
    /// The current pixel's first-hit textures, shared by its samples.
    first_hits: FirstHits,
    /// How requests are served.
    pub source: S,
}

/// Most surfaces whose shared textures one pixel keeps at once. A pixel whose samples meet
/// more replaces its oldest entry: an entry is a function of the pixel and its key alone, so what
/// a sample reads does not depend on which entries earlier samples left.
const FIRST_HITS_KEPT: usize = 8;

/// Most surfaces on a [`PixelKey`]: the textured hit and the perfectly specular ones before it.
const PIXEL_CHAIN: usize = 4;

/// Which of a pixel's shared texture entries a camera sample reads: the surfaces its path met
/// from the camera on, every one but the last a perfect mirror or smooth dielectric without
/// textures, and whether the path reflected or refracted at each. A first hit is a key of one
/// surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct PixelKey {
    shapes: [u32; PIXEL_CHAIN],
    len: u8,
    /// Bit `k`: the path refracted at surface `k`.
    refracted: u8,
}

impl PixelKey {
    /// A camera ray's first hit, on `shape`.
    pub(crate) fn first(shape: u32) -> PixelKey {
        let mut shapes = [u32::MAX; PIXEL_CHAIN];
        shapes[0] = shape;
        PixelKey { shapes, len: 1, refracted: 0 }
    }

    /// The key of the hit on `shape` that a path with this key reaches after scattering
    /// specularly at its last surface (`refracted` or reflected); `None` past [`PIXEL_CHAIN`].
    pub(crate) fn then(&self, refracted: bool, shape: u32) -> Option<PixelKey> {
        let n = usize::from(self.len);
        if n >= PIXEL_CHAIN {
            return None;
        }
        let mut k = *self;
        k.shapes[n] = shape;
        k.len += 1;
        k.refracted |= u8::from(refracted) << (n - 1);
        Some(k)
    }

    /// The surfaces, from the camera on.
    pub(crate) fn shapes(&self) -> &[u32] {
        &self.shapes[..usize::from(self.len)]
    }

    /// Whether the path refracted (rather than reflected) at surface `k` of [`Self::shapes`].
    pub(crate) fn refracted_at(&self, k: usize) -> bool {
        self.refracted >> k & 1 == 1
    }
}

/// How far (in standard deviations of the pixel centre's footprint there) a sample's hit may
/// lie from the pixel centre's, in texture coordinates, for the sample to read the pixel's
/// textures. A sample's hit is its film offset (drawn from the pixel filter) carried onto the
/// surface, through any perfect mirrors and smooth dielectrics on the way: a draw from the
/// footprint itself, to first order. 4σ takes 99.97 % of them and still tells a uv seam (a whole
/// period away), a silhouette or a different part of the surface from the pixel's own; a sample
/// beyond evaluates its own. The test reads the hit's texture coordinates alone, so a sample
/// that reads the pixel's textures needs no footprint of its own there.
pub(crate) const SHARE_DISTANCE: f64 = 4.0;

/// One pixel's shared textures, by [`PixelKey`] (see [`TextureEvaluator::begin_pixel`]).
struct FirstHits {
    /// The pixel, once [`TextureEvaluator::begin_pixel`] named it; without one nothing is shared.
    pixel: Option<(u32, u32)>,
    /// How many of `entries` belong to the pixel.
    len: usize,
    /// The entry replaced next once all are taken.
    next: usize,
    /// [`FIRST_HITS_KEPT`] entries, allocated once.
    entries: Vec<FirstHit>,
}

/// One key's textures at the pixel centre's footprint there.
struct FirstHit {
    key: PixelKey,
    /// Where the pixel centre's ray reaches the key's last surface, or `None` when it misses it
    /// (or cannot take the key's way) or the textures went non-finite there: then every sample
    /// evaluates its own.
    centre: Option<Centre>,
    outputs: Vec<Filtered>,
}

/// The pixel centre's hit of a [`FirstHit`], as [`TextureEvaluator::first_hit_accepts`] reads it.
#[derive(Clone, Copy, Debug)]
struct Centre {
    /// Texture coordinates and the inverse of the footprint's uv covariance.
    uv: DVec2,
    inv: DMat2,
    /// Position, and the squared distance from it within which a sample's hit may lie
    /// ([`SHARE_DISTANCE`] times the footprint's larger standard deviation, squared).
    p: glam::Vec3,
    reach2: f32,
}

impl<S: GraphSource> TextureEvaluator<S> {
    /// An evaluator for every graph of a scene and its largest material, served by `source`.
    pub fn new(graphs: &[SceneGraph], materials: &[Material], source: S) -> Self {
        let slots = materials.iter().map(|m| m.slot_count as usize).max().unwrap_or(0);
        let per_graph = materials.iter().flat_map(|m| m.graphs.iter().map(|g| g.slots.len())).max().unwrap_or(0);
        let zero = Filtered::constant(graph::Value::float(0.0));
        TextureEvaluator {
            depth: 0,
            sample_origin: None,
            nonfinite: Vec::new(),
            graph_nonfinite: Vec::new(),
            scratches: graphs.iter().map(|g| EvalScratch::new(g.graph())).collect(),
            outputs: vec![zero; slots],
            tmp: vec![zero; per_graph],
            first_hits: FirstHits {
                pixel: None,
                len: 0,
                next: 0,
                entries: (0..FIRST_HITS_KEPT)
                    .map(|_| FirstHit { key: PixelKey::first(u32::MAX), centre: None, outputs: vec![zero; slots] })
                    .collect(),
            },
            source,
        }
    }

    /// Starts pixel (`x`, `y`): forgets the previous pixel's first-hit textures.
    ///
    /// At the first hit of a camera path the footprint is the pixel filter projected onto the
    /// surface and, with the whole footprint as the texture filter, centred where the pixel
    /// centre's ray meets it ([`crate::integrator::recentre_fraction`]): every sample of the
    /// pixel that meets the same surface asks for the same filtered textures. They are
    /// evaluated once, at the footprint the pixel centre's own ray has there (a function of the
    /// pixel and the surface alone, so the image does not depend on which samples a render or a
    /// sample pass takes, or in what order), and each sample whose hit lies near the pixel
    /// centre's ([`SHARE_DISTANCE`]) reads them.
    ///
    /// A hit the path reached through perfect mirrors and smooth dielectrics without textures
    /// is shared the same way, keyed by the surfaces met and whether the path reflected or
    /// refracted at each ([`PixelKey`]): the pixel centre's ray takes the same way to the same
    /// surface and carries its footprint there.
    #[inline]
    pub(crate) fn begin_pixel(&mut self, x: u32, y: u32) {
        self.first_hits.pixel = Some((x, y));
        self.first_hits.len = 0;
        self.first_hits.next = 0;
    }

    /// The pixel begun last, if one was.
    #[inline]
    pub(crate) fn pixel(&self) -> Option<(u32, u32)> {
        self.first_hits.pixel
    }

    /// The current pixel's entry for `key`, if one is kept.
    #[inline]
    pub(crate) fn first_hit(&self, key: &PixelKey) -> Option<usize> {
        self.first_hits.entries[..self.first_hits.len].iter().position(|e| e.key == *key)
    }

    /// Keeps `material`'s textures at the pixel centre's footprint `centre` (`None`: the
    /// centre's path does not reach the key's last surface the key's way) as the pixel's entry
    /// for `key`, in a free entry or in place of the oldest; says whether it evaluated them.
    pub(crate) fn keep_first_hit(
        &mut self,
        graphs: &[SceneGraph],
        material: &Material,
        key: PixelKey,
        centre: Option<(Footprint, f64)>,
    ) -> (usize, bool) {
        let hits = &mut self.first_hits;
        let k = if hits.len < FIRST_HITS_KEPT {
            hits.len += 1;
            hits.len - 1
        } else {
            let oldest = hits.next;
            hits.next = (oldest + 1) % FIRST_HITS_KEPT;
            oldest
        };
        let n = material.slot_count as usize;
        let mut evaluated = false;
        let kept = centre.and_then(|(fp, spread)| {
            let cov = fp.cov.as_dmat2();
            let det = cov.determinant();
            if !(det > 0.0 && det.is_finite()) {
                return None;
            }
            self.source.shared(true);
            let finite = self.evaluate_outputs(graphs, material, &fp);
            evaluated = true;
            self.source.shared(false);
            let reach2 = (SHARE_DISTANCE * SHARE_DISTANCE * spread) as f32;
            finite.then(|| Centre { uv: fp.uv.as_dvec2(), inv: cov.inverse(), p: fp.geom.p, reach2 })
        });
        let e = &mut self.first_hits.entries[k];
        e.key = key;
        e.centre = kept;
        if kept.is_some() {
            e.outputs[..n].copy_from_slice(&self.outputs[..n]);
        }
        (k, evaluated)
    }

    /// Whether a sample whose hit has texture coordinates `uv` and position `p` reads entry
    /// `k`'s textures: `uv` within [`SHARE_DISTANCE`] of the entry's centre, in the standard
    /// deviations of the entry's footprint, and `p` as near the centre's hit in space (measured
    /// along the footprint's wider axis: a guard where texture coordinates repeat over the
    /// surface, as on overlapping or mirrored uv islands or a mesh without uv).
    #[inline]
    pub(crate) fn first_hit_accepts(&self, k: usize, uv: glam::Vec2, p: glam::Vec3) -> bool {
        let Some(c) = &self.first_hits.entries[k].centre else { return false };
        let d = uv.as_dvec2() - c.uv;
        d.dot(c.inv * d) <= SHARE_DISTANCE * SHARE_DISTANCE && p.distance_squared(c.p) <= c.reach2
    }

    /// Entry `k`'s textures, by slot.
    #[inline]
    pub(crate) fn first_hit_outputs(&self, k: usize, material: &Material) -> &[Filtered] {
        &self.first_hits.entries[k].outputs[..material.slot_count as usize]
    }

    /// Evaluates `material`'s graph outputs at footprint `fp`; returns them by slot.
    #[inline]
    pub fn evaluate(&mut self, graphs: &[SceneGraph], material: &Material, fp: &Footprint) -> &[Filtered] {
        self.evaluate_outputs(graphs, material, fp);
        &self.outputs[..material.slot_count as usize]
    }

    /// [`Self::evaluate`] into the output slots; false if a graph value went non-finite.
    #[inline]
    fn evaluate_outputs(&mut self, graphs: &[SceneGraph], material: &Material, fp: &Footprint) -> bool {
        let mut finite = true;
        for mg in &material.graphs {
            let g = graphs[mg.graph as usize].graph();
            let n = mg.slots.len();
            let scratch = &mut self.scratches[mg.graph as usize];
            self.source.evaluate(g, mg, fp, scratch, &mut self.tmp[..n]);
            if let Some(at) = scratch.take_nonfinite() {
                finite = false;
                if self.sample_origin.is_none() {
                    self.sample_origin = Some(GraphNonFinite {
                        material: material.name.clone(),
                        graph: mg.graph,
                        at,
                        bounce: self.depth,
                    });
                }
            }
            for (k, &slot) in mg.slots.iter().enumerate() {
                self.outputs[slot as usize] = self.tmp[k];
            }
        }
        finite
    }

    /// Starts camera sample `index`: forgets the previous sample's non-finite origin.
    #[inline]
    pub(crate) fn begin_sample(&mut self, index: u32) {
        self.sample_origin = None;
        self.source.begin_sample(index);
    }

    /// Records that sample `sample` of pixel (`x`, `y`) had a non-finite radiance (kept if it is
    /// among this evaluator's first [`NONFINITE_KEPT`]).
    pub(crate) fn record_nonfinite(&mut self, x: u32, y: u32, sample: u32) {
        if self.nonfinite.len() < NONFINITE_KEPT {
            self.nonfinite.push(NonFiniteSample { x, y, sample, origin: self.sample_origin.clone() });
        }
    }

    /// Ends sample `sample` of pixel (`x`, `y`): if a graph value went non-finite on its path,
    /// keeps where (among this evaluator's first [`NONFINITE_KEPT`]).
    #[inline]
    pub(crate) fn end_sample(&mut self, x: u32, y: u32, sample: u32) {
        self.source.end_sample();
        if self.sample_origin.is_some() && self.graph_nonfinite.len() < NONFINITE_KEPT {
            self.graph_nonfinite.push(NonFiniteSample { x, y, sample, origin: self.sample_origin.clone() });
        }
    }

    /// The per-graph evaluation scratches (the profiler turns on their binned timings).
    pub(crate) fn eval_scratches_mut(&mut self) -> &mut [EvalScratch] {
        &mut self.scratches
    }

    /// Adds this evaluator's per-node statistics to `stats` (one entry per scene graph).
    pub fn merge_stats_into(&self, stats: &mut Vec<EvalStats>) {
        stats.resize(self.scratches.len(), EvalStats::default());
        for (s, out) in self.scratches.iter().zip(stats.iter_mut()) {
            s.merge_stats_into(out);
        }
        self.source.merge_stats_into(stats);
    }
}

/// The shading frame bent to the normal `n_ts` given in the frame's own coordinates (a graph's
/// `normal` output, as `normalmap` produces with its default flat frame). Normals that are not
/// finite or lie (nearly) below the surface leave the frame as it is.
pub fn perturbed_frame(frame: &crate::math::Frame, n_ts: glam::Vec3) -> crate::math::Frame {
    let n = frame.to_world(n_ts);
    let len = n.length();
    if !(len.is_finite() && len > 1e-6) || n.dot(frame.n) < 0.05 * len {
        return *frame;
    }
    crate::math::Frame::from_normal_tangent(n / len, frame.s)
}
