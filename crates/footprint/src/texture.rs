//! Footprints at the boundaries: world-space and texture-space covariances, and the mip level.

use glam::{DMat2, DMat3, DVec3};

use crate::mat::{clamp_covariance, sym_eigen};
use crate::vertex::Vertex;
use crate::MAX_VARIANCE;

/// Lowest level [`lod`] returns (a footprint 2⁻³² texels wide, or zero).
pub const LOD_MIN: f32 = -32.0;
/// Highest level [`lod`] returns (a footprint 2³² texels wide, infinite, or undefined).
pub const LOD_MAX: f32 = 32.0;

/// The world-space covariance `T Σ Tᵀ` (3×3, `T = [t b]`) of a tangent-plane footprint `cov`
/// at `v`. It does not depend on the choice of `(t, b)` within the tangent plane.
pub fn world_covariance(cov: DMat2, v: &Vertex) -> DMat3 {
    let (t, b) = (v.t, v.b);
    let u0 = t * cov.x_axis.x + b * cov.x_axis.y; // T Σ e₀
    let u1 = t * cov.y_axis.x + b * cov.y_axis.y; // T Σ e₁
    DMat3::from_cols(u0 * t.x + u1 * b.x, u0 * t.y + u1 * b.y, u0 * t.z + u1 * b.z)
}

/// The texture-space covariance `Σ_uv = J_uv Σ J_uvᵀ` with `J_uv = ∂(u, v)/∂Δx` from
/// [`crate::LocalGeometry::uv_jacobian`] (a clamped inverse of `[t b]ᵀ [dpdu dpdv]`, see
/// [`Vertex::local`]). Symmetric, positive semi-definite, eigenvalues at most `MAX_VARIANCE`.
pub fn uv_covariance(cov: DMat2, v: &Vertex) -> DMat2 {
    uv_covariance_with(cov, v.uv_jacobian())
}

/// [`uv_covariance`] with the vertex's uv Jacobian `j` already computed
/// ([`crate::LocalGeometry::uv_jacobian`], which a tracker keeps for its current vertex).
pub fn uv_covariance_with(cov: DMat2, j: DMat2) -> DMat2 {
    clamp_covariance(j * cov * j.transpose(), MAX_VARIANCE).cov
}

/// The continuous mip level of a texture-space footprint:
/// `lod = log2(σ_major · texels_per_uv_unit) = ½ log2(λ_max(Σ_uv)) + log2(texels_per_uv_unit)`,
/// where `σ_major` is the footprint's standard deviation along its major axis. At level `lod`
/// (which has `2^−lod` of level 0's texels per uv unit) one texel spans one standard deviation.
///
/// Using the major axis never under-filters; anisotropic footprints are blurred along their
/// minor axis. The result is clamped to `[LOD_MIN, LOD_MAX]`: a zero footprint (or a
/// non-positive density) gives `LOD_MIN`; an infinite or NaN input gives `LOD_MAX`. Callers clamp
/// further to the levels a texture has.
pub fn lod(cov_uv: DMat2, texels_per_uv_unit: f64) -> f32 {
    if !cov_uv.is_finite() || texels_per_uv_unit.is_nan() {
        return LOD_MAX;
    }
    let (l1, _, _) = sym_eigen(cov_uv);
    let l = 0.5 * l1.max(0.0).log2() + texels_per_uv_unit.max(0.0).log2();
    if l.is_nan() {
        // 0 · ∞ style conflicts (zero footprint, infinite density): treat as undefined.
        return LOD_MAX;
    }
    (l as f32).clamp(LOD_MIN, LOD_MAX)
}

/// A footprint at one vertex as the boundary sees it: tangent-plane, world and uv covariances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VertexFootprint {
    /// 2×2 covariance of `Δx` in the vertex's shading tangent frame `(t, b)`.
    pub tangent: DMat2,
    /// 3×3 world-space covariance `T Σ Tᵀ`.
    pub world: DMat3,
    /// 2×2 covariance in uv space.
    pub uv: DMat2,
}

impl VertexFootprint {
    /// Gathers the boundary forms of the tangent-plane footprint `cov` at `v`.
    pub fn new(cov: DMat2, v: &Vertex) -> Self {
        VertexFootprint { tangent: cov, world: world_covariance(cov, v), uv: uv_covariance(cov, v) }
    }

    /// [`lod`] of the uv covariance.
    pub fn lod(&self, texels_per_uv_unit: f64) -> f32 {
        lod(self.uv, texels_per_uv_unit)
    }

    /// Standard deviation along the major axis in world units.
    pub fn world_major_sigma(&self) -> f64 {
        sym_eigen(self.tangent).0.max(0.0).sqrt()
    }
}

/// Projects a world-space covariance back to `v`'s tangent frame (`Tᵀ Σ T`); the inverse of
/// [`world_covariance`] for covariances lying in the tangent plane.
pub fn tangent_covariance(world: DMat3, v: &Vertex) -> DMat2 {
    let f = |a: DVec3, b: DVec3| a.dot(world * b);
    let xy = f(v.t, v.b);
    DMat2::from_cols(glam::DVec2::new(f(v.t, v.t), xy), glam::DVec2::new(xy, f(v.b, v.b)))
}
