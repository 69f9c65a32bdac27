//! Path footprints for texture filtering, after the supplemental of "Selective Caching in
//! Procedural Texture Graphs for Path Tracing" (Schüßler et al., EGSR 2025).
//!
//! The *footprint* of a path at vertex `x_i` is the distribution of `x_i`'s position over all
//! nearby paths sampled the same way (adjoint analog sampling): a screen offset from the pixel
//! filter and a half-vector offset from each vertex's roughness. To first order, vertex offsets
//! `Δx` and half-vector offsets `Δh` are related by the block-tridiagonal constraint derivative
//! matrix (eq. 2), and the footprint is a Gaussian with a 2×2 covariance in each vertex's
//! tangent plane. This crate is pure maths on glam types; it knows nothing of scenes.
//!
//! How the pieces fit, in the order a renderer calls them for one camera path:
//!
//! 1. Describe each hit as a [`Vertex`]: position, shading frame `(t, b, n)`, `dp/du`, `dp/dv`,
//!    `dn/du`, `dn/dv`, uv. [`Vertex::local`] derives the surface's first-order shape there
//!    ([`LocalGeometry`]: tangent map, shape operator `W`, uv Jacobian).
//! 2. At the first hit, [`first_vertex_variance`] projects the ½-pixel pixel filter onto the
//!    tangent plane with ray differentials (Igehy's transfer): `var(Δx₁) = J (¼ I) Jᵀ`.
//! 3. A [`FootprintTracker`] runs Algorithm 1 with O(1) state. Per bounce,
//!    [`FootprintTracker::advance`] takes the next vertex, the event at the current one
//!    ([`Scatter`]: reflection, or refraction with relative IOR) and `var(Δh)` from
//!    [`half_vector_variance`] (`(α/√2)² I` for Beckmann-equivalent roughness `α`, see
//!    [`ggx_to_beckmann_alpha`]); it forms the half-vector constraint derivatives
//!    `A_i, B_i, C_i` ([`constraint_derivatives`], [`ConstraintDerivatives`]) and returns
//!    `var(Δx_{i+1})`. [`FootprintTracker::step`] is the same update from given matrices.
//! 4. At the boundary, [`VertexFootprint::new`] gives the world-space covariance `T Σ Tᵀ`
//!    ([`world_covariance`]) and the uv covariance `J_uv Σ J_uvᵀ` ([`uv_covariance`]);
//!    [`lod`] maps a uv covariance to a continuous mip level.
//!
//! ```
//! use footprint::*;
//! use glam::{DVec2, DVec3};
//!
//! // Pinhole camera at the origin; one pixel turns the (unit) ray direction by 1 mrad.
//! let camera = DVec3::ZERO;
//! let dir = DVec3::new(0.0, 0.6, -0.8);
//! let (ddx, ddy) = (DVec3::X * 1e-3, DVec3::new(0.0, 0.8, 0.6) * 1e-3);
//! // First hit: a floor at z = -4 (flat: dp/du = t, dp/dv = b, no curvature).
//! let x1 = Vertex::on_plane(dir * 5.0, DVec3::Z);
//! let mut tracker = FootprintTracker::start_path(camera, &x1, first_vertex_variance(camera, dir, ddx, ddy, &x1));
//! // The BSDF at x1 sampled a GGX lobe with α = 0.2; the reflected ray hit a wall at x2.
//! let x2 = Vertex { uv: DVec2::new(0.3, 0.7), ..Vertex::on_plane(DVec3::new(0.0, 6.0, -2.0), -DVec3::Y) };
//! let alpha = ggx_to_beckmann_alpha(0.2) as f64;
//! let var_x2 = tracker.advance(&x2, Scatter::Reflection, half_vector_variance(alpha));
//! let fp = VertexFootprint::new(var_x2, &x2);
//! let level = fp.lod(1024.0); // texels per uv unit at level 0
//! assert!(fp.world_major_sigma() > 0.0 && level.is_finite());
//! ```
//!
//! For comparison, [`RayCone`] (ray cones) and [`PbrtDifferentials`] (pbrt-v4's ray
//! differentials with its camera approximation after rough bounces) offer the same per-bounce
//! shape and also return tangent-plane covariances.
//!
//! Conventions: footprints inside are 2×2 covariances of offsets along `(t, b)`; all derivative
//! maths is in `f64`. Every clamp is a named constant below; no function returns NaN or
//! infinity for finite inputs, and non-finite inputs lead to the largest footprint.

#![deny(missing_docs)]
// `!(x > 0.0)` is how this crate says "not positive, or NaN": the negation is the point.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod camera;
mod constraint;
mod estimators;
pub mod mat;
mod texture;
mod tracker;
mod vertex;

pub use camera::{
    first_vertex_jacobian, first_vertex_jacobian_with, first_vertex_variance, first_vertex_variance_with, PixelRay,
    PIXEL_SIGMA,
};
pub use constraint::{
    constraint_derivatives, constraint_derivatives_with, effective_eta, ggx_to_beckmann_alpha, half_vector_slope,
    half_vector_variance, half_vector_variance_aniso, ConstraintDerivatives, GGX_TO_BECKMANN,
};
pub use estimators::{pixel_spread_angle, PbrtDifferentials, RayCone};
pub use texture::{
    lod, tangent_covariance, uv_covariance, uv_covariance_with, world_covariance, VertexFootprint, LOD_MAX, LOD_MIN,
};
pub use tracker::FootprintTracker;
pub use vertex::{orthonormal_basis, LocalGeometry, Scatter, Vertex};

/// Largest variance (world units², or uv units² for texture space) along any axis of any
/// footprint: a standard deviation of 10⁸. Larger values are clamped; non-finite ones become it.
pub const MAX_VARIANCE: f64 = 1e16;

/// Smallest `|cos|` used wherever a direction meets a plane: ray-differential transfer at
/// grazing incidence (first vertex, pbrt-style estimator, ray-cone projection) and the half
/// vector's `h·n` relative to `|h|` (slopes are at most 10⁴). Grazing beyond ≈ 89.994° is
/// treated as that angle.
pub const MIN_COSINE: f64 = 1e-4;

/// Floor on `|h·n|` when the half vector itself (nearly) vanishes, e.g. a reflection whose
/// outgoing direction is opposite to the incoming one.
pub const MIN_HALF_VECTOR_NORM: f64 = 1e-12;

/// Smallest distance between consecutive vertices used in the derivatives (world units).
pub const MIN_DISTANCE: f64 = 1e-12;

/// Smallest `|eta − 1|` for refraction (see [`effective_eta`]).
pub const MIN_ETA_OFFSET: f64 = 1e-4;

/// `C_i⁻¹` in Algorithm 1 raises `C_i`'s singular values to at least this fraction of the
/// largest: a next vertex seen at grazing angles (or a nearly degenerate half-vector map)
/// elongates the footprint by at most 10⁴.
pub const C_CONDITION_LIMIT: f64 = 1e-4;

/// Absolute floor on `C_i`'s singular values (units 1/length): a next vertex at distance beyond
/// ~10¹² no longer grows the footprint (which is clamped at [`MAX_VARIANCE`] anyway).
pub const MIN_C_SINGULAR_VALUE: f64 = 1e-12;

/// Relative singular-value threshold of the uv parameterisation (see [`Vertex::local`]).
pub const UV_CONDITION_LIMIT: f64 = 1e-6;

/// Largest roughness accepted by [`half_vector_variance`] and [`ggx_to_beckmann_alpha`].
pub const MAX_ALPHA: f64 = 1e3;
