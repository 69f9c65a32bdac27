//! Filtered lookups over a pyramid of bilinear taps: trilinear and anisotropic (probes along the
//! major axis). Pure arithmetic over a `bilinear(level, uv)` callback; knows nothing of tiles.

use glam::{Mat2, Vec2};

use crate::lod::{level_for, sym_eigen};
use crate::tile::{lerp3, Texel};
use crate::MAX_ANISOTROPY;

/// Probes per unit of `σ_residual / σ_probe` on each side of the centre; spacing the probes at
/// most `≈ 1.8 σ_probe` apart keeps the probe comb's first alias below 0.3 % (`exp(−2π²σ²/h²)`).
pub(crate) const PROBE_DENSITY: f64 = 1.25;

/// Most probes on each side of the centre.
const MAX_SIDE: usize = (PROBE_DENSITY * MAX_ANISOTROPY as f64) as usize + 1;

/// A residual variance below this fraction of the probe variance is ignored (one probe).
const MIN_RESIDUAL: f64 = 0.01;

/// Trilinear interpolation at continuous level `lod` (already clamped to `[lo, hi]`).
#[inline]
pub(crate) fn trilinear(lod: f32, hi: u8, mut bilinear: impl FnMut(u8) -> Texel) -> Texel {
    let l0 = lod as u8; // lod ≥ 0: truncation is the floor
    let t = lod - f32::from(l0);
    let a = bilinear(l0);
    if t > 0.0 && l0 < hi {
        lerp3(a, bilinear(l0 + 1), t)
    } else {
        a
    }
}

/// Gaussian probe layouts for `m = 1 ..= MAX_SIDE` probes per side: positions `u_k = 2k/m`
/// (`k = −m..=m`) scaled to unit variance, weights `∝ exp(−u_k²/2)` summing to one.
pub(crate) struct ProbeTables {
    /// `(unit offsets, weights)` for `m = index + 1`.
    tables: Vec<(Vec<f32>, Vec<f32>)>,
}

impl ProbeTables {
    pub fn new() -> ProbeTables {
        let tables = (1..=MAX_SIDE)
            .map(|m| {
                let u: Vec<f64> = (-(m as i64)..=m as i64).map(|k| 2.0 * k as f64 / m as f64).collect();
                let w: Vec<f64> = u.iter().map(|u| (-0.5 * u * u).exp()).collect();
                let sum: f64 = w.iter().sum();
                let var: f64 = u.iter().zip(&w).map(|(u, w)| w * u * u).sum::<f64>() / sum;
                let scale = var.sqrt().recip();
                (u.iter().map(|u| (u * scale) as f32).collect(), w.iter().map(|w| (w / sum) as f32).collect())
            })
            .collect();
        ProbeTables { tables }
    }
}

/// The anisotropic lookup of footprint `cov` (uv units) on a texture of level-0 density `d0`,
/// levels `lo..=hi`. `trilinear_at(offset, lod)` is the trilinear lookup at `uv + offset`.
///
/// The probes' common level is [`level_for`] of `σ²I` with
/// `σ = max(σ_minor, σ_major / max_anisotropy)`, clamped to `[lo, hi]`; at that level a probe
/// blurs isotropically with `σ_p = 2^lod / d0`. The remaining variance along the major axis,
/// `r² = λ_major − σ_p²`, is spread over `2m + 1` Gaussian-weighted probes whose offsets have
/// variance exactly `r²`, so the mixture's covariance is the footprint's.
pub(crate) fn anisotropic(
    cov: Mat2,
    d0: f32,
    lo: u8,
    hi: u8,
    max_anisotropy: f32,
    probes: &ProbeTables,
    mut trilinear_at: impl FnMut(Vec2, f32) -> Texel,
) -> Texel {
    let clamp = |lod: f32| lod.clamp(f32::from(lo), f32::from(hi));
    let (l1, l2, e1) = sym_eigen(cov);
    if !(l1.is_finite() && l2.is_finite()) {
        return trilinear_at(Vec2::ZERO, clamp(level_for(cov, d0)));
    }
    let aniso = f64::from(max_anisotropy.clamp(1.0, MAX_ANISOTROPY)); // NaN → 1
    let aniso = if aniso.is_nan() { 1.0 } else { aniso };
    let (s1, s2) = (l1.max(0.0).sqrt(), l2.max(0.0).sqrt());
    let s = s2.max(s1 / aniso);
    let lod = clamp(level_for(Mat2::from_diagonal(Vec2::splat((s * s) as f32)), d0));
    let sp = f64::from(lod).exp2() / f64::from(d0);
    let r2 = l1 - sp * sp;
    if r2.is_nan() || r2 <= MIN_RESIDUAL * sp * sp {
        return trilinear_at(Vec2::ZERO, lod);
    }
    let r = r2.sqrt();
    let m = ((PROBE_DENSITY * r / sp).ceil() as usize).clamp(1, MAX_SIDE);
    let (unit, weights) = &probes.tables[m - 1];
    let axis = Vec2::new(e1[0] as f32, e1[1] as f32);
    let mut acc = [0.0f32; 3];
    for (u, w) in unit.iter().zip(weights) {
        let v = trilinear_at(axis * (r as f32 * u), lod);
        for c in 0..3 {
            acc[c] += w * v[c];
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn probe_tables_have_unit_variance_and_weight() {
        let p = ProbeTables::new();
        for (m, (u, w)) in p.tables.iter().enumerate() {
            assert_eq!(u.len(), 2 * m + 3);
            let sum: f32 = w.iter().sum();
            let mean: f32 = u.iter().zip(w).map(|(u, w)| u * w).sum();
            let var: f32 = u.iter().zip(w).map(|(u, w)| u * u * w).sum();
            assert!((sum - 1.0).abs() < 1e-5 && mean.abs() < 1e-5 && (var - 1.0).abs() < 1e-5, "m {}", m + 1);
        }
    }

    #[test]
    fn trilinear_blends_two_levels() {
        let v = |l: u8| [f32::from(l), 0.0, 0.0];
        assert_eq!(trilinear(2.25, 5, v), [2.25, 0.0, 0.0]);
        assert_eq!(trilinear(5.0, 5, v), [5.0, 0.0, 0.0]);
        assert_eq!(trilinear(3.0, 5, v), [3.0, 0.0, 0.0]);
    }

    /// The probes' mixture reproduces the footprint's covariance: with a "texture" that is the
    /// quadratic form `(x·n)²` (a probe at offset `x` returns `(x·n)² + σ_p²`, its exact Gaussian
    /// blur), the anisotropic lookup at the origin returns `nᵀ Σ' n`, where `Σ'` is the footprint
    /// with its minor variance raised to `λ_major / max_anisotropy²` where it is smaller.
    #[test]
    fn probe_mixture_has_the_footprint_covariance() {
        let probes = ProbeTables::new();
        let d0 = 1024.0f32;
        for (l1, l2, psi) in [(1e-2f32, 1e-4f32, 0.3f32), (4e-3, 4e-3, 0.0), (1e-3, 1e-6, 2.0), (1e-2, 2e-3, -1.0)] {
            let r = Mat2::from_angle(psi);
            let cov = r * Mat2::from_diagonal(Vec2::new(l1, l2)) * r.transpose();
            let l2e = l2.max(l1 / 256.0);
            let cov_eff = r * Mat2::from_diagonal(Vec2::new(l1, l2e)) * r.transpose();
            for n in [Vec2::X, Vec2::Y, Vec2::new(0.6, 0.8)] {
                let got = anisotropic(cov, d0, 0, 12, 16.0, &probes, |off, lod| {
                    let sp = (lod.exp2() / d0) as f64;
                    let x = f64::from(off.dot(n));
                    [(x * x + sp * sp) as f32, 0.0, 0.0]
                })[0];
                let want = n.dot(cov_eff * n);
                assert!((got - want).abs() <= 1e-3 * l1, "{l1} {l2} {psi} {n}: {got} vs {want}");
            }
        }
    }
}
