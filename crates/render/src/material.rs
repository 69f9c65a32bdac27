//! Materials: a BSDF whose parameters may come from procedural graphs, and the scene's graphs
//! (one per MaterialX document) that they read.
//!
//! A [`Material`] is a [`BsdfDesc`] plus, per graph it reads, a [`MaterialGraph`]: the plan that
//! evaluates the outputs it needs in one pass (shared upstream nodes once) and the slots their
//! values go to. [`crate::texture::Texture::GraphOutput`] reads those slots when the BSDF is
//! built at a hit.

use crate::bsdf::BsdfDesc;
use graph::{EvalOrder, EvalScratch, Filtered, Footprint, Graph, NoOverride};
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
    /// The order in which the outputs' nodes are evaluated.
    pub order: EvalOrder,
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
    /// Whether shading a hit reads its uv and their derivatives: graph outputs, a shading
    /// normal from a graph, or a BSDF texture that varies over the surface.
    #[inline]
    pub fn reads_uv(&self) -> bool {
        !self.graphs.is_empty() || self.normal_slot.is_some() || self.bsdf.reads_uv()
    }

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
            g.eval(&mg.order, &fp, &mut scratch, &NoOverride, &mut tmp);
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
