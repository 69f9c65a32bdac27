//! tessera's renderer: scene loading (a Mitsuba 3 XML subset), geometry and BVH, BSDFs,
//! emitters, the path-tracing integrator and the film.

pub mod bsdf;
pub mod error;
pub mod math;
pub mod sampling;
pub mod texture;
