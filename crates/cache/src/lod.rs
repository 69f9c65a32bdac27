//! The level of detail of a uv footprint: the one function that maps a uv covariance to a level.
//!
//! This is the definition of `footprint::lod` (crates/footprint/src/texture.rs) re-implemented
//! for `f32` inputs, because this crate depends on nothing of ours. It computes in `f64` exactly
//! as that function does, so for the same covariance (converted to `f64`) both return the same
//! `f32`. Lookups, profiling and the planner's model must all use it.

use glam::Mat2;

/// Lowest level [`level_for`] returns (a footprint 2⁻³² texels wide, or zero).
pub const LOD_MIN: f32 = -32.0;
/// Highest level [`level_for`] returns (a footprint 2³² texels wide, infinite, or undefined).
pub const LOD_MAX: f32 = 32.0;

/// The continuous mip level of a texture-space footprint:
/// `lod = log2(σ_major · texels_per_uv) = ½ log2(λ_max(Σ_uv)) + log2(texels_per_uv)`,
/// where `σ_major` is the footprint's standard deviation along its major axis and
/// `texels_per_uv` is level 0's texel density. At level `lod` (which has `2^−lod` of level 0's
/// texels per uv unit) one texel spans one standard deviation.
///
/// Using the major axis never under-filters; anisotropic footprints are blurred along their
/// minor axis (see [`crate::FilterKind::Anisotropic`] for the lookup that is not). The result is
/// clamped to `[LOD_MIN, LOD_MAX]`: a zero footprint (or a non-positive density) gives
/// `LOD_MIN`; an infinite or NaN input gives `LOD_MAX`. Callers clamp further to the levels a
/// texture has.
pub fn level_for(cov_uv: Mat2, texels_per_uv: f32) -> f32 {
    if !cov_uv.is_finite() || texels_per_uv.is_nan() {
        return LOD_MAX;
    }
    // One logarithm: ½ log₂(λ₁ d²) = ½ log₂ λ₁ + log₂ d (every render lookup computes it; the
    // two logarithms were 1.5 % of a cached render).
    let d = f64::from(texels_per_uv).max(0.0);
    let l = 0.5 * (major_eigenvalue(cov_uv).max(0.0) * (d * d)).log2();
    if l.is_nan() {
        // 0 · ∞ style conflicts (zero footprint, infinite density): treat as undefined.
        return LOD_MAX;
    }
    (l as f32).clamp(LOD_MIN, LOD_MAX)
}

/// `(a, b, c)`: the symmetric part `[[a, b], [b, c]]` of `m` in `f64`.
#[inline]
fn sym_parts(m: Mat2) -> (f64, f64, f64) {
    let b = 0.5 * (f64::from(m.x_axis.y) + f64::from(m.y_axis.x));
    (f64::from(m.x_axis.x), b, f64::from(m.y_axis.y))
}

/// The larger eigenvalue of the symmetric part of `m` (the closed form of `footprint`'s
/// `sym_eigen`, without the angle).
#[inline]
fn major_eigenvalue(m: Mat2) -> f64 {
    let (a, b, c) = sym_parts(m);
    0.5 * (a + c) + hypot(0.5 * (a - c), b)
}

/// Eigen-decomposition of the symmetric part of `m` in `f64`: `(λ₁, λ₂, e₁)` with `λ₁ ≥ λ₂` (as
/// in [`level_for`]) and `e₁` a unit eigenvector of `λ₁` (`x` axis for a multiple of `I`).
#[inline]
pub(crate) fn sym_eigen(m: Mat2) -> (f64, f64, [f64; 2]) {
    let (a, b, c) = sym_parts(m);
    let mean = 0.5 * (a + c);
    let d = hypot(0.5 * (a - c), b);
    let (l1, l2) = (mean + d, mean - d);
    // (A − λ₂I) maps onto the λ₁ eigenspace; take its larger column.
    let (u, v) = ([a - l2, b], [b, c - l2]);
    let e = if u[0] * u[0] + u[1] * u[1] >= v[0] * v[0] + v[1] * v[1] { u } else { v };
    let n = hypot(e[0], e[1]);
    let e = if n > 0.0 && n.is_finite() { [e[0] / n, e[1] / n] } else { [1.0, 0.0] };
    (l1, l2, e)
}

/// `√(a² + b²)`, falling back to the overflow-safe `hypot` only when needed.
fn hypot(a: f64, b: f64) -> f64 {
    let s = a * a + b * b;
    if s.is_finite() {
        s.sqrt()
    } else {
        a.hypot(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    #[test]
    fn one_texel_sigma_is_level_zero() {
        // σ = 1/64 uv at 64 texels per uv: one texel, level 0; 4 texels: level 2.
        let s = 1.0 / 64.0;
        assert_eq!(level_for(Mat2::from_diagonal(Vec2::splat(s * s)), 64.0), 0.0);
        let s = 4.0 / 64.0;
        assert_eq!(level_for(Mat2::from_diagonal(Vec2::splat(s * s)), 64.0), 2.0);
    }

    #[test]
    fn major_axis_decides_whatever_the_orientation() {
        let (l1, l2) = (0.01f32, 0.0001f32);
        let expect = 0.5 * (l1 as f64).log2() + 5.0;
        for i in 0..16 {
            let psi = i as f32 * 0.4;
            let r = Mat2::from_angle(psi);
            let cov = r * Mat2::from_diagonal(Vec2::new(l1, l2)) * r.transpose();
            assert!((level_for(cov, 32.0) as f64 - expect).abs() < 1e-4, "psi {psi}");
        }
    }

    #[test]
    fn eigenvectors_are_eigenvectors() {
        for (l1, l2, psi) in [(3.0f32, 1.0f32, 0.3f32), (2.0, 2.0, 1.0), (5.0, 0.0, -2.0), (1e-6, 1e-9, 2.5)] {
            let r = Mat2::from_angle(psi);
            let m = r * Mat2::from_diagonal(Vec2::new(l1, l2)) * r.transpose();
            let (a, b, e) = sym_eigen(m);
            assert!((a - l1 as f64).abs() <= 1e-6 * l1 as f64 && (b - l2 as f64).abs() <= 1e-6 * l1 as f64);
            let e = Vec2::new(e[0] as f32, e[1] as f32);
            assert!((m * e - e * l1).length() <= 1e-5 * l1, "{l1} {l2} {psi}: {e}");
            assert!((e.length() - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn degenerate_inputs_clamp() {
        assert_eq!(level_for(Mat2::ZERO, 64.0), LOD_MIN);
        assert_eq!(level_for(Mat2::IDENTITY, 0.0), LOD_MIN);
        assert_eq!(level_for(Mat2::from_diagonal(Vec2::splat(f32::NAN)), 64.0), LOD_MAX);
        assert_eq!(level_for(Mat2::from_diagonal(Vec2::splat(f32::INFINITY)), 64.0), LOD_MAX);
        assert_eq!(level_for(Mat2::ZERO, f32::INFINITY), LOD_MAX);
        assert_eq!(level_for(Mat2::IDENTITY * 1e30, 1e30), LOD_MAX);
    }
}
