//! tessera's renderer: scene loading (a Mitsuba 3 XML subset), geometry and BVH, BSDFs,
//! emitters, the path-tracing integrator and the film.
//!
//! A [`scene::Scene`] comes from [`loader::load_file`] (Mitsuba 3 XML, read by [`xml`]); it holds
//! [`geometry::Shape`]s indexed by a BVH ([`geometry::Accel`]), [`bsdf::BsdfDesc`] materials,
//! [`emitter::Emitter`]s and a [`camera::Camera`]. [`integrator::render`] turns it into a
//! [`film::Image`].

// `!(x > 0.0)` is how this crate says "not positive, or NaN": the negation is the point.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bsdf;
pub mod caching;
pub mod camera;
pub mod emitter;
pub mod error;
pub mod film;
pub mod geometry;
pub mod integrator;
pub mod loader;
pub mod math;
pub mod mesh;
pub mod pathfootprint;
pub mod profiling;
pub mod sampling;
pub mod scene;
pub mod shading;
pub mod texture;
pub mod xml;
