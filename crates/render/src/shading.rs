//! Materials whose parameters come from procedural graphs, and the per-thread memory that
//! evaluates those graphs at each shading point.
//!
//! A [`Material`] is a [`BsdfDesc`] plus the graph outputs its textures read. Before the BSDF is
//! built at a hit, [`ShadeScratch::evaluate`] evaluates every output the material needs, filtered
//! to the hit's uv footprint, in one pass per graph (shared upstream nodes are evaluated once);
//! [`crate::texture::Texture::GraphOutput`] then reads them by slot.

use crate::bsdf::BsdfDesc;
use graph::{EvalPlan, EvalScratch, EvalStats, Filtered, Footprint, Graph, NoOverride};
use std::sync::Arc;

/// A procedural graph used by the scene (one per MaterialX document).
#[derive(Debug)]
pub struct SceneGraph {
    /// The document it came from (for reports).
    pub name: String,
    /// The loaded document; its graph holds every nodegraph of the file.
    pub document: Arc<graph::Document>,
}

impl SceneGraph {
    /// The document's file name (without folders): how profiles and plans name the graph.
    pub fn file_name(&self) -> &str {
        self.name.rsplit(['/', '\\']).next().unwrap_or(&self.name)
    }

    /// The graph.
    pub fn graph(&self) -> &Graph {
        self.document.graph()
    }
}

/// The outputs of one graph that a material reads.
#[derive(Clone, Debug)]
pub struct MaterialGraph {
    /// Index into the scene's graphs.
    pub graph: u32,
    /// Evaluation plan over the outputs.
    pub plan: EvalPlan,
    /// For each output of `plan`, the slot its value goes to.
    pub slots: Vec<u32>,
    /// Index of this (material, graph) pair among all the scene's: the request stream a
    /// profile records it as.
    pub stream: u32,
}

/// A BSDF and the graph outputs its textures read.
#[derive(Clone, Debug)]
pub struct Material {
    /// The name reports give it: the BSDF's `id`, or its plugin and place in the scene file.
    pub name: String,
    /// The BSDF with its (possibly graph-valued) textures.
    pub bsdf: BsdfDesc,
    /// Graph outputs to evaluate before building the BSDF; empty for plain Mitsuba materials.
    pub graphs: Vec<MaterialGraph>,
    /// Number of slots the outputs fill.
    pub slot_count: u32,
    /// Each slot's value averaged over the whole texture (the graph evaluated with a huge
    /// footprint): what the free-texture lower bound renders with.
    pub constant_outputs: Vec<Filtered>,
    /// The slot holding a shading normal (MaterialX `normal` input, e.g. from `normalmap`),
    /// read in the shading frame: (x, y, z) = tangent, bitangent and normal components.
    pub normal_slot: Option<u32>,
}

impl Material {
    /// Fills [`Material::constant_outputs`]: every output evaluated with a footprint far larger
    /// than any feature (σ = 100 uv units), i.e. its mean over the plane.
    pub fn compute_constant_outputs(&mut self, graphs: &[SceneGraph]) {
        let zero = Filtered::constant(graph::Value::float(0.0));
        self.constant_outputs = vec![zero; self.slot_count as usize];
        let fp = Footprint::isotropic(glam::Vec2::splat(0.5), 100.0);
        for mg in &self.graphs {
            let g = graphs[mg.graph as usize].graph();
            let mut scratch = EvalScratch::new(g);
            let mut tmp = vec![zero; mg.slots.len()];
            g.eval(&mg.plan, &fp, &mut scratch, &NoOverride, &mut tmp);
            for (k, &slot) in mg.slots.iter().enumerate() {
                let mut c = tmp[k];
                for m in c.ch.iter_mut() {
                    *m = graph::Moments::constant(m.mean);
                }
                self.constant_outputs[slot as usize] = c;
            }
        }
    }

    /// A material without procedural textures.
    pub fn plain(bsdf: BsdfDesc) -> Self {
        Material {
            name: "default".into(),
            bsdf,
            graphs: Vec::new(),
            slot_count: 0,
            constant_outputs: Vec::new(),
            normal_slot: None,
        }
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

/// Per-thread graph evaluation memory and statistics (allocated once per thread or tile), and
/// the thread's access to the node cache when one is used.
pub struct ShadeScratch<'a> {
    /// The bounce (0 = first hit) of the vertex being shaded, set by the integrator: reports of
    /// non-finite values name it.
    pub(crate) depth: u32,
    /// Where the current camera sample's graph evaluations first went non-finite.
    sample_origin: Option<GraphNonFinite>,
    /// The first non-finite samples of this scratch's pixels (at most [`NONFINITE_KEPT`]).
    pub(crate) nonfinite: Vec<NonFiniteSample>,
    /// The first samples on whose path a graph value went non-finite, whether or not the
    /// sample's radiance did (texture reads map NaN to 0); at most [`NONFINITE_KEPT`].
    pub(crate) graph_nonfinite: Vec<NonFiniteSample>,
    scratches: Vec<EvalScratch>,
    outputs: Vec<Filtered>,
    tmp: Vec<Filtered>,
    cache: Option<crate::caching::CacheAccess<'a>>,
    /// The profiler's per-thread recorder, when profiling.
    pub(crate) tap: Option<Box<crate::profiling::Tap>>,
}

impl<'a> ShadeScratch<'a> {
    /// Scratch for every graph of a scene and the largest material, reading cached nodes from
    /// `cache` when given.
    pub fn with_cache(
        graphs: &'a [SceneGraph],
        materials: &[Material],
        cache: Option<&'a crate::caching::NodeCache>,
    ) -> Self {
        let mut s = Self::new(graphs, materials);
        s.cache = cache.map(|c| crate::caching::CacheAccess::new(c, graphs));
        s
    }

    /// Scratch for every graph of a scene and the largest material.
    pub fn new(graphs: &[SceneGraph], materials: &[Material]) -> Self {
        let slots = materials.iter().map(|m| m.slot_count as usize).max().unwrap_or(0);
        let per_graph = materials.iter().flat_map(|m| m.graphs.iter().map(|g| g.slots.len())).max().unwrap_or(0);
        let zero = Filtered::constant(graph::Value::float(0.0));
        ShadeScratch {
            depth: 0,
            sample_origin: None,
            nonfinite: Vec::new(),
            graph_nonfinite: Vec::new(),
            scratches: graphs.iter().map(|g| EvalScratch::new(g.graph())).collect(),
            outputs: vec![zero; slots],
            tmp: vec![zero; per_graph],
            cache: None,
            tap: None,
        }
    }

    /// Evaluates `material`'s graph outputs at footprint `fp`; returns them by slot.
    #[inline]
    pub fn evaluate(&mut self, graphs: &[SceneGraph], material: &Material, fp: &Footprint) -> &[Filtered] {
        for mg in &material.graphs {
            let g = graphs[mg.graph as usize].graph();
            let n = mg.slots.len();
            let scratch = &mut self.scratches[mg.graph as usize];
            if let Some(tap) = &mut self.tap {
                tap.evaluate(mg.stream, g, &mg.plan, fp, scratch, &mut self.tmp[..n]);
            } else {
                match &self.cache {
                    Some(access) => g.eval(&mg.plan, fp, scratch, &access.for_graph(mg.graph), &mut self.tmp[..n]),
                    None => g.eval(&mg.plan, fp, scratch, &NoOverride, &mut self.tmp[..n]),
                }
            }
            if let Some(at) = scratch.take_nonfinite() {
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
        &self.outputs[..material.slot_count as usize]
    }

    /// Starts a camera sample: forgets the previous sample's non-finite origin.
    #[inline]
    pub(crate) fn begin_sample(&mut self) {
        self.sample_origin = None;
    }

    /// Records that sample `sample` of pixel (`x`, `y`) had a non-finite radiance (kept if it is
    /// among this scratch's first [`NONFINITE_KEPT`]).
    pub(crate) fn record_nonfinite(&mut self, x: u32, y: u32, sample: u32) {
        if self.nonfinite.len() < NONFINITE_KEPT {
            self.nonfinite.push(NonFiniteSample { x, y, sample, origin: self.sample_origin.clone() });
        }
    }

    /// Ends sample `sample` of pixel (`x`, `y`): if a graph value went non-finite on its path,
    /// keeps where (among this scratch's first [`NONFINITE_KEPT`]).
    #[inline]
    pub(crate) fn end_sample(&mut self, x: u32, y: u32, sample: u32) {
        if self.sample_origin.is_some() && self.graph_nonfinite.len() < NONFINITE_KEPT {
            self.graph_nonfinite.push(NonFiniteSample { x, y, sample, origin: self.sample_origin.clone() });
        }
    }

    /// The per-graph evaluation scratches (the profiler turns on their binned timings).
    pub(crate) fn eval_scratches_mut(&mut self) -> &mut [EvalScratch] {
        &mut self.scratches
    }

    /// Adds this scratch's per-node statistics to `stats` (one entry per scene graph).
    pub fn merge_stats_into(&self, stats: &mut Vec<EvalStats>) {
        stats.resize(self.scratches.len(), EvalStats::default());
        for (s, out) in self.scratches.iter().zip(stats.iter_mut()) {
            s.merge_stats_into(out);
        }
        if let Some(access) = &self.cache {
            access.merge_fill_stats_into(stats);
        }
    }
}

/// The footprint a material's graphs are evaluated over at surface hit `si`: its uv centre and
/// uv covariance `cov`, and the hit's geometry for nodes that read more than uv (`position`,
/// `normal`, `tangent`, `bitangent`, 3D noises): world position, shading normal, the shading
/// frame's tangent (∂p/∂u made orthogonal to the normal) and bitangent, ∂p/∂u, ∂p/∂v (so the
/// position's footprint is `J Σ Jᵀ`) and ∂n/∂u, ∂n/∂v. World space is also MaterialX's object
/// space here: shapes are transformed to world space at load.
pub fn footprint_at(si: &crate::geometry::SurfaceInteraction, cov: glam::Mat2) -> Footprint {
    let geom = graph::Geometry {
        p: si.p,
        n: si.sh.n,
        t: si.sh.s,
        b: si.sh.t,
        dpdu: si.dpdu,
        dpdv: si.dpdv,
        dndu: si.dndu,
        dndv: si.dndv,
    };
    Footprint::with_geometry(si.uv, cov, geom)
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
