//! A loaded scene: shapes and their BVH, materials, emitters, camera, film and integrator
//! settings.

use crate::camera::{Camera, Rfilter};
use crate::emitter::Emitter;
use crate::geometry::Shape;
use crate::material::{Material, SceneGraph};
use std::path::PathBuf;

/// Settings of Mitsuba's `path` integrator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PathSettings {
    /// Longest path in segments (`u32::MAX` for Mitsuba's −1); 1 shows only emitters.
    pub max_depth: u32,
    /// Depth from which Russian roulette starts.
    pub rr_depth: u32,
}

/// Everything needed to render.
pub struct Scene {
    /// Shapes (world space).
    pub shapes: Vec<Shape>,
    /// BVH over the shapes.
    pub accel: crate::accel::SceneAccel,
    /// Materials; shapes refer to them by index.
    pub materials: Vec<Material>,
    /// Procedural graphs the materials read (one per MaterialX document).
    pub graphs: Vec<SceneGraph>,
    /// Emitters; area emitters refer to their shape.
    pub emitters: Vec<Emitter>,
    /// Indices of emitters at infinity (constant, envmap).
    pub infinite: Vec<u32>,
    /// The sensor.
    pub camera: Camera,
    /// Pixel reconstruction filter.
    pub rfilter: Rfilter,
    /// Integrator settings.
    pub integrator: PathSettings,
    /// Sample count the scene asks for.
    pub spp: u32,
    /// Seed the scene's sampler asks for.
    pub seed: u64,
    /// Whether any material filters its textures by the path footprint (then every camera path
    /// tracks footprints; otherwise only when an AOV or `tessera footprint` asks).
    pub footprints_needed: bool,
    /// Whether any material is partly transparent ([`crate::bsdf::BsdfDesc::Mask`]): then
    /// shadow rays gather the transmittance of the surfaces they cross instead of stopping at
    /// the first.
    pub masked: bool,
    /// Every file the scene was built from, each once, the scene file first: its includes,
    /// meshes, images, MaterialX documents (with their includes) and the images they name. What
    /// a render elsewhere needs copied (files supplied in memory are not listed).
    pub files: Vec<PathBuf>,
}
