//! tessera's renderer: scene loading (a Mitsuba 3 XML subset), geometry and BVH, BSDFs,
//! emitters, materials with procedural textures, the path-tracing integrator and the film.
//!
//! A [`scene::Scene`] comes from [`loader::load_file`] (Mitsuba 3 XML, read by [`xml`]); it holds
//! [`geometry::Shape`]s indexed by a BVH ([`geometry::Accel`]), [`material::Material`]s (a
//! [`bsdf::BsdfDesc`] whose textures may read outputs of the scene's [`material::SceneGraph`]s),
//! [`emitter::Emitter`]s and a [`camera::Camera`]. [`integrator::render`] turns it into a
//! [`film::Image`], bucket by bucket ([`integrator::for_each_bucket`]).
//!
//! **The seam.** A shading point asks its thread's [`shading::TextureEvaluator`] for a material's
//! graph outputs at its footprint; the evaluator hands the request to a
//! [`shading::GraphSource`]: [`shading::Direct`] evaluation, the tile cache's
//! ([`caching::CacheAccess`], rendered by [`caching::render_cached`]) or the profiler's
//! ([`profiling::Profiler`], which wraps the direct one). The integrator is generic over the
//! source and imports neither the cache nor the profiler; they import it. No two modules import
//! each other, directly or around a circle (a test reads the imports from the source).

#![deny(missing_docs)]
// `!(x > 0.0)` is how this crate says "not positive, or NaN": the negation is the point.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod accel;
pub mod bsdf;
pub mod caching;
pub mod camera;
pub mod embree;
pub mod emitter;
pub mod error;
pub mod exhaustive;
pub mod film;
pub mod geometry;
pub mod integrator;
pub mod loader;
pub mod material;
pub mod math;
pub mod mesh;
pub mod output;
pub mod pass;
pub mod pathfootprint;
pub mod profiling;
pub mod sampling;
pub mod scene;
pub mod shading;
pub mod stats;
pub mod texture;
pub mod xml;

#[cfg(test)]
mod module_graph;
