//! The first vertex: the pixel filter projected onto the first hit by ray differentials.

use glam::{DMat2, DVec2, DVec3};

use crate::mat::clamp_covariance;
use crate::vertex::Vertex;
use crate::{MAX_VARIANCE, MIN_COSINE};

/// Standard deviation of the pixel filter, in pixels.
pub const PIXEL_SIGMA: f64 = 0.5;

/// Igehy's transfer of a ray differential onto a plane: a ray `o + s·dir` reaches `p` on the
/// plane with normal `g`; the offset ray `(o + d_o) + s'(dir + d_dir)` reaches `p + dp` with
/// `dp = (d_o + s d_dir) − dir ((d_o + s d_dir)·g) / (dir·g)`.
/// `|dir·g|` is kept at least [`MIN_COSINE`]`·|dir|`.
pub(crate) fn transfer(d_origin: DVec3, dir: DVec3, d_dir: DVec3, s: f64, g: DVec3) -> DVec3 {
    let v = d_origin + d_dir * s;
    let dn = dir.dot(g);
    let floor = MIN_COSINE * dir.length();
    let dn = if dn.abs() >= floor { dn } else { floor.copysign(dn) };
    v - dir * (v.dot(g) / dn)
}

/// `J = ∂Δx₁/∂(pixel x, pixel y)`: how the first hit moves in its tangent plane per pixel of
/// screen offset, for a pinhole camera at `camera_origin`.
///
/// `dir` is the camera ray's direction and `d_dir_dpx`, `d_dir_dpy` its derivatives per pixel.
/// Both conventions work as long as they match: the unnormalised direction with its
/// derivatives, or the normalised direction with the derivatives *of the normalised direction*
/// (only the components perpendicular to `dir`, relative to `|dir|`, matter, since the offset
/// rays are intersected with the tangent plane). tessera's camera passes the normalised ones.
///
/// The offset rays are intersected with the true tangent plane of `hit` (normal
/// [`crate::LocalGeometry::geometric_normal`]) and the displacement is expressed in `hit`'s
/// shading frame `(t, b)` (Igehy 1999, transfer). Grazing incidence is clamped at
/// `|cos| ≥ MIN_COSINE`. A non-finite result (degenerate `dir`) yields `√MAX_VARIANCE · I`.
pub fn first_vertex_jacobian(
    camera_origin: DVec3,
    dir: DVec3,
    d_dir_dpx: DVec3,
    d_dir_dpy: DVec3,
    hit: &Vertex,
) -> DMat2 {
    let g = hit.local().geometric_normal(hit.n);
    first_vertex_jacobian_with(&PixelRay { origin: camera_origin, dir, d_dir_dpx, d_dir_dpy }, hit, g)
}

/// A camera ray and its direction's derivatives per pixel, as [`first_vertex_jacobian`] reads
/// them (same conventions).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelRay {
    /// The camera's position.
    pub origin: DVec3,
    /// The ray's direction.
    pub dir: DVec3,
    /// `∂dir/∂(pixel x)`.
    pub d_dir_dpx: DVec3,
    /// `∂dir/∂(pixel y)`.
    pub d_dir_dpy: DVec3,
}

/// [`first_vertex_jacobian`] with `hit`'s geometric normal already computed
/// ([`crate::LocalGeometry::geometric_normal`]; a path computes it once at its first vertex,
/// where the recentring reads it too).
pub fn first_vertex_jacobian_with(ray: &PixelRay, hit: &Vertex, geometric_normal: DVec3) -> DMat2 {
    let (dir, g) = (ray.dir, geometric_normal);
    let s = (hit.p - ray.origin).dot(dir) / dir.length_squared();
    let dpx = transfer(DVec3::ZERO, dir, ray.d_dir_dpx, s, g);
    let dpy = transfer(DVec3::ZERO, dir, ray.d_dir_dpy, s, g);
    let j = DMat2::from_cols(DVec2::new(hit.t.dot(dpx), hit.b.dot(dpx)), DVec2::new(hit.t.dot(dpy), hit.b.dot(dpy)));
    if j.is_finite() {
        j
    } else {
        DMat2::from_diagonal(DVec2::splat(MAX_VARIANCE.sqrt()))
    }
}

/// `var(Δx₁) = J (σ² I) Jᵀ` with `σ = ½` pixel ([`PIXEL_SIGMA`]) and `J` from
/// [`first_vertex_jacobian`] (same arguments and conventions). Clamped to `MAX_VARIANCE`.
pub fn first_vertex_variance(
    camera_origin: DVec3,
    dir: DVec3,
    d_dir_dpx: DVec3,
    d_dir_dpy: DVec3,
    hit: &Vertex,
) -> DMat2 {
    let g = hit.local().geometric_normal(hit.n);
    first_vertex_variance_with(&PixelRay { origin: camera_origin, dir, d_dir_dpx, d_dir_dpy }, hit, g)
}

/// [`first_vertex_variance`] with `hit`'s geometric normal already computed.
pub fn first_vertex_variance_with(ray: &PixelRay, hit: &Vertex, geometric_normal: DVec3) -> DMat2 {
    let j = first_vertex_jacobian_with(ray, hit, geometric_normal);
    let v = j * j.transpose() * (PIXEL_SIGMA * PIXEL_SIGMA);
    clamp_covariance(v, MAX_VARIANCE).cov
}
