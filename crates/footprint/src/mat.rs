//! Small 2×2 helpers on [`DMat2`]: a closed-form singular value decomposition, regularised
//! inverses built on it, and the symmetric eigen-decomposition used to keep covariances
//! positive semi-definite and bounded.
//!
//! glam matrices are column-major: `m.x_axis` is the first column, so the entry in row `r`,
//! column `c` is `m.col(c)[r]`.

use glam::{DMat2, DVec2};

/// `√(a² + b²)`. The libm `hypot` guards against overflow at a large cost; entries here are
/// bounded by the clamps (variances ≤ 1e16, so squares ≤ 1e32 ≪ f64::MAX), and the scaled form
/// below keeps the result finite for any finite input anyway.
#[inline]
fn hypot(a: f64, b: f64) -> f64 {
    let s = a * a + b * b;
    if s.is_finite() {
        s.sqrt()
    } else {
        a.hypot(b)
    }
}

/// A 2×2 singular value decomposition `M = R(φ) · diag(σ₁, σ₂) · R(θ)`, where `R(a)` is the
/// counter-clockwise rotation by `a`. `σ₁ ≥ |σ₂|`; `σ₂` carries the sign of `det M`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Svd2 {
    /// Angle of the left rotation `R(φ)`.
    pub phi: f64,
    /// Angle of the right rotation `R(θ)`.
    pub theta: f64,
    /// Largest singular value (≥ 0).
    pub s1: f64,
    /// Second singular value, signed like the determinant (`|s2| ≤ s1`).
    pub s2: f64,
}

impl Svd2 {
    /// Decomposes `m` in closed form (no iteration, no division; finite for finite input).
    pub fn new(m: DMat2) -> Self {
        let (m00, m10, m01, m11) = (m.x_axis.x, m.x_axis.y, m.y_axis.x, m.y_axis.y);
        let e = 0.5 * (m00 + m11);
        let f = 0.5 * (m00 - m11);
        let g = 0.5 * (m10 + m01);
        let h = 0.5 * (m10 - m01);
        let q = hypot(e, h);
        let r = hypot(f, g);
        let a1 = g.atan2(f);
        let a2 = h.atan2(e);
        Svd2 { phi: 0.5 * (a2 + a1), theta: 0.5 * (a2 - a1), s1: q + r, s2: q - r }
    }

    /// Largest singular value.
    pub fn max_singular(&self) -> f64 {
        self.s1
    }

    /// Smallest singular value (≥ 0).
    pub fn min_singular(&self) -> f64 {
        self.s2.abs()
    }

    /// Rebuilds `R(φ) diag(s1, s2) R(θ)`.
    pub fn matrix(&self) -> DMat2 {
        DMat2::from_angle(self.phi) * DMat2::from_diagonal(DVec2::new(self.s1, self.s2)) * DMat2::from_angle(self.theta)
    }

    /// `R(-θ) diag(f(s1), f(s2)) R(-φ)`: an inverse whose reciprocal singular values are chosen
    /// by `f` (which receives the signed singular value).
    fn inverse_with(&self, f: impl Fn(f64) -> f64) -> DMat2 {
        DMat2::from_angle(-self.theta)
            * DMat2::from_diagonal(DVec2::new(f(self.s1), f(self.s2)))
            * DMat2::from_angle(-self.phi)
    }

    /// Inverse with every singular value raised to at least `floor` in magnitude (sign kept).
    /// Equals the exact inverse when `min_singular() ≥ floor`; `floor` must be positive.
    pub fn clamped_inverse(&self, floor: f64) -> DMat2 {
        self.inverse_with(|s| {
            let m = s.abs().max(floor);
            if s < 0.0 {
                -1.0 / m
            } else {
                1.0 / m
            }
        })
    }

    /// Moore–Penrose pseudo-inverse treating singular values below `threshold` as zero.
    pub fn pseudo_inverse(&self, threshold: f64) -> DMat2 {
        self.inverse_with(|s| if s.abs() > threshold { 1.0 / s } else { 0.0 })
    }
}

/// Eigen-decomposition of the symmetric part of `m`: `(λ₁, λ₂, ψ)` with `λ₁ ≥ λ₂` and the
/// eigenvector of `λ₁` equal to `(cos ψ, sin ψ)`.
pub fn sym_eigen(m: DMat2) -> (f64, f64, f64) {
    let a = m.x_axis.x;
    let c = m.y_axis.y;
    let b = 0.5 * (m.x_axis.y + m.y_axis.x);
    let mean = 0.5 * (a + c);
    let d = hypot(0.5 * (a - c), b);
    let psi = 0.5 * (2.0 * b).atan2(a - c);
    (mean + d, mean - d, psi)
}

/// Rebuilds `R(ψ) diag(λ₁, λ₂) R(-ψ)`.
pub fn sym_from_eigen(l1: f64, l2: f64, psi: f64) -> DMat2 {
    let (s, c) = psi.sin_cos();
    // Columns of R(ψ) diag R(-ψ), written out to keep the result exactly symmetric.
    let xx = l1 * c * c + l2 * s * s;
    let yy = l1 * s * s + l2 * c * c;
    let xy = (l1 - l2) * s * c;
    DMat2::from_cols(DVec2::new(xx, xy), DVec2::new(xy, yy))
}

/// `(m + mᵀ) / 2`.
pub fn symmetrize(m: DMat2) -> DMat2 {
    let xy = 0.5 * (m.x_axis.y + m.y_axis.x);
    DMat2::from_cols(DVec2::new(m.x_axis.x, xy), DVec2::new(xy, m.y_axis.y))
}

/// Singular values `(σ₁, σ₂)` of `m` in closed form without trigonometry (`σ₂` signed like
/// `det m`), the same values [`Svd2::new`] computes.
#[inline]
pub fn singular_values(m: DMat2) -> (f64, f64) {
    let (m00, m10, m01, m11) = (m.x_axis.x, m.x_axis.y, m.y_axis.x, m.y_axis.y);
    let q = hypot(0.5 * (m00 + m11), 0.5 * (m10 - m01));
    let r = hypot(0.5 * (m00 - m11), 0.5 * (m10 + m01));
    (q + r, q - r)
}

/// Whether `m`'s smallest singular value is certainly at least `ratio` times its largest and at
/// least `min_abs`, decided without square roots: `|det m| = σ₁ |σ₂|` and
/// `‖m‖²_F = σ₁² + σ₂² ≥ σ₁²`, so `|det| ≥ 2 ratio ‖m‖²_F` gives `|σ₂| ≥ 2 ratio σ₁` and
/// `det² ≥ 4 min_abs² ‖m‖²_F` gives `|σ₂| ≥ 2 min_abs` (the factors of 2 cover rounding). Where
/// it holds, the regularised inverses below are the plain inverse; where it does not, they
/// decide with the singular values themselves.
#[inline]
pub fn certainly_conditioned(m: DMat2, ratio: f64, min_abs: f64) -> bool {
    let det = m.determinant();
    let f = m.x_axis.length_squared() + m.y_axis.length_squared();
    let a = det.abs();
    det != 0.0 && f.is_finite() && a >= 2.0 * ratio * f && a * a >= 4.0 * min_abs * min_abs * f
}

/// [`Svd2::clamped_inverse`] of `m`, taking the plain inverse when no singular value is below
/// `floor` (the common case: no trigonometry) and the decomposition otherwise.
#[inline]
pub fn clamped_inverse(m: DMat2, floor: f64) -> DMat2 {
    clamped_inverse_sv(m, singular_values(m), floor)
}

/// [`clamped_inverse`] of `m` whose [`singular_values`] are `sv`.
#[inline]
pub fn clamped_inverse_sv(m: DMat2, (_, s2): (f64, f64), floor: f64) -> DMat2 {
    if s2.abs() >= floor && s2 != 0.0 {
        m.inverse()
    } else {
        Svd2::new(m).clamped_inverse(floor)
    }
}

/// [`Svd2::pseudo_inverse`] of `m`, with the same fast path as [`clamped_inverse`].
#[inline]
pub fn pseudo_inverse(m: DMat2, threshold: f64) -> DMat2 {
    pseudo_inverse_sv(m, singular_values(m), threshold)
}

/// [`pseudo_inverse`] of `m` whose [`singular_values`] are `sv`.
#[inline]
pub fn pseudo_inverse_sv(m: DMat2, (s1, s2): (f64, f64), threshold: f64) -> DMat2 {
    if s2.abs() > threshold && s2 != 0.0 {
        m.inverse()
    } else if !(s1 > threshold) {
        DMat2::ZERO
    } else {
        Svd2::new(m).pseudo_inverse(threshold)
    }
}

/// The result of [`clamp_covariance`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clamped {
    /// The symmetric, positive semi-definite, bounded covariance.
    pub cov: DMat2,
    /// Whether an eigenvalue had to be lowered to `max_variance` (or the input was not finite).
    pub clamped_above: bool,
}

/// Symmetrises `m` and clamps its eigenvalues to `[0, max_variance]`. A non-finite input
/// becomes `max_variance · I`.
pub fn clamp_covariance(m: DMat2, max_variance: f64) -> Clamped {
    if !m.is_finite() {
        return Clamped { cov: DMat2::from_diagonal(DVec2::splat(max_variance)), clamped_above: true };
    }
    let s = symmetrize(m);
    // Eigenvalues without the angle first: most covariances need no clamping.
    let mean = 0.5 * (s.x_axis.x + s.y_axis.y);
    if comfortably_within(s, mean, max_variance) {
        return Clamped { cov: s, clamped_above: false };
    }
    let d = hypot(0.5 * (s.x_axis.x - s.y_axis.y), s.x_axis.y);
    if mean - d >= 0.0 && mean + d <= max_variance {
        return Clamped { cov: s, clamped_above: false };
    }
    let (l1, l2, psi) = sym_eigen(s);
    Clamped {
        cov: sym_from_eigen(l1.clamp(0.0, max_variance), l2.clamp(0.0, max_variance), psi),
        clamped_above: l1 > max_variance,
    }
}

/// Whether the symmetric `s` (eigenvalues `mean ± d`) is clearly positive definite and below
/// `max_variance`, decided without the square root of `d`: `det = λ₁λ₂ ≥ 1e-6 mean²` puts the
/// smaller eigenvalue at `det/λ₁ ≥ 5e-7 mean`, far above the rounding of `mean − d`, and the
/// larger is below the trace. Where it holds, [`clamp_covariance`]'s eigenvalue test holds too.
#[inline]
fn comfortably_within(s: DMat2, mean: f64, max_variance: f64) -> bool {
    let det = s.x_axis.x * s.y_axis.y - s.x_axis.y * s.y_axis.x;
    mean > 0.0 && det >= 1e-6 * mean * mean && 2.0 * mean <= 0.5 * max_variance
}

/// Outer product `a bᵀ`.
pub fn outer(a: DVec2, b: DVec2) -> DMat2 {
    DMat2::from_cols(a * b.x, a * b.y)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(state: &mut u64) -> f64 {
        *state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    #[test]
    fn svd_reconstructs_and_inverts() {
        let mut st = 7u64;
        for _ in 0..1000 {
            let m =
                DMat2::from_cols(DVec2::new(lcg(&mut st), lcg(&mut st)), DVec2::new(lcg(&mut st), lcg(&mut st))) * 3.0;
            let svd = Svd2::new(m);
            assert!(svd.s1 >= svd.s2.abs());
            assert!((svd.matrix() - m).abs_diff_eq(DMat2::ZERO, 1e-12));
            assert!((svd.s1 * svd.s2 - m.determinant()).abs() < 1e-12);
            if svd.min_singular() > 1e-3 {
                let inv = svd.clamped_inverse(1e-9);
                assert!((inv * m).abs_diff_eq(DMat2::IDENTITY, 1e-9));
                let pinv = svd.pseudo_inverse(1e-9);
                assert!((pinv * m).abs_diff_eq(DMat2::IDENTITY, 1e-9));
            }
        }
    }

    #[test]
    fn fast_inverses_agree_with_the_decomposition() {
        let mut st = 11u64;
        for k in 0..2000 {
            let mut m =
                DMat2::from_cols(DVec2::new(lcg(&mut st), lcg(&mut st)), DVec2::new(lcg(&mut st), lcg(&mut st)));
            if k % 3 == 0 {
                // Nearly singular: the slow path must be taken.
                m.y_axis = m.x_axis * 0.5 + DVec2::splat(1e-7 * lcg(&mut st));
            }
            let svd = Svd2::new(m);
            let (s1, s2) = singular_values(m);
            assert!((s1 - svd.s1).abs() < 1e-12 && (s2 - svd.s2).abs() < 1e-12);
            for floor in [1e-9, 1e-3, 0.3] {
                // Relative to the size of the inverse (ill-conditioned inverses are large).
                let close = |a: DMat2, b: DMat2| {
                    let scale = 1.0 + b.abs().to_cols_array().iter().fold(0.0f64, |m, v| m.max(*v));
                    // Both routes lose about ε·cond(m) relative precision.
                    let cond = s1 / s2.abs().max(floor);
                    (a - b).abs_diff_eq(DMat2::ZERO, (1e-9 + 1e-14 * cond) * scale)
                };
                assert!(close(clamped_inverse(m, floor), svd.clamped_inverse(floor)));
                assert!(close(pseudo_inverse(m, floor), svd.pseudo_inverse(floor)));
            }
        }
    }

    /// Where `certainly_conditioned` holds, the decomposition agrees: the smallest singular value
    /// is at least the ratio times the largest and at least the absolute floor (so the
    /// regularised inverses are the plain one). Matrices from well to badly conditioned.
    #[test]
    fn certainly_conditioned_never_claims_a_badly_conditioned_matrix() {
        let mut st = 5u64;
        let (mut claimed, mut total) = (0, 0);
        for k in 0..20_000 {
            let mut m =
                DMat2::from_cols(DVec2::new(lcg(&mut st), lcg(&mut st)), DVec2::new(lcg(&mut st), lcg(&mut st)));
            // Second column near a multiple of the first, at spreads from 1 down to 1e-15.
            let spread = 10f64.powi(-(k % 16));
            m.y_axis = m.x_axis * lcg(&mut st) + m.y_axis * spread;
            let scale = 10f64.powi((k % 7) * 4 - 12);
            let m = m * scale;
            for (ratio, min_abs) in [(1e-6, 0.0), (1e-4, 1e-12), (0.3, 0.0)] {
                let svd = Svd2::new(m);
                let (lo, hi) = (svd.min_singular(), svd.max_singular());
                if certainly_conditioned(m, ratio, min_abs) {
                    claimed += 1;
                    assert!(lo >= ratio * hi, "{m} {ratio}");
                    assert!(lo >= min_abs, "{m} {min_abs}");
                } else {
                    // And it misses only matrices within a small factor of either bound
                    // (`‖m‖²_F ≤ 2σ₁²`): the fast path is taken where it matters.
                    assert!(lo < 4.1 * ratio * hi || lo < 2.9 * min_abs, "{m} {ratio} {min_abs}");
                }
                total += 1;
            }
        }
        assert!(claimed > 0 && claimed < total, "{claimed} of {total}");
        assert!(!certainly_conditioned(DMat2::ZERO, 1e-6, 0.0));
        assert!(!certainly_conditioned(DMat2::from_cols(DVec2::NAN, DVec2::Y), 1e-6, 0.0));
    }

    #[test]
    fn pseudo_inverse_of_rank_one() {
        // M = a bᵀ; M⁺ = b aᵀ / (|a|² |b|²).
        let a = DVec2::new(1.0, 2.0);
        let b = DVec2::new(-0.5, 0.25);
        let m = outer(a, b);
        let p = Svd2::new(m).pseudo_inverse(1e-12);
        let expect = outer(b, a) / (a.length_squared() * b.length_squared());
        assert!((p - expect).abs_diff_eq(DMat2::ZERO, 1e-12));
        // Clamped inverse keeps the weak direction at 1/floor.
        let c = Svd2::new(m).clamped_inverse(1e-3);
        // M's range is span(a); the inverse maps the orthogonal complement by 1/floor.
        let w = DVec2::new(-a.y, a.x).normalize();
        assert!(((c * w).length() - 1e3).abs() < 1e-6);
    }

    /// Where the root-free test claims a matrix, the eigenvalue test would have passed it too
    /// (so the clamp returns the same matrix either way); it claims most covariances.
    #[test]
    fn comfortably_within_implies_the_eigenvalue_test() {
        let mut st = 3u64;
        let (mut claimed, mut total) = (0, 0);
        for k in 0..50_000 {
            let a = DVec2::new(lcg(&mut st), lcg(&mut st));
            let b = DVec2::new(lcg(&mut st), lcg(&mut st)) * 10f64.powi(-(k % 12));
            let scale = 10f64.powi((k % 9) * 4 - 16);
            // Σ = a aᵀ + b bᵀ: positive semi-definite, from well to badly conditioned.
            let m = symmetrize((outer(a, a) + outer(b, b)) * scale);
            for max in [MAX_VARIANCE_TEST, 1e-3] {
                total += 1;
                let mean = 0.5 * (m.x_axis.x + m.y_axis.y);
                if comfortably_within(m, mean, max) {
                    claimed += 1;
                    let d = hypot(0.5 * (m.x_axis.x - m.y_axis.y), m.x_axis.y);
                    assert!(mean - d >= 0.0 && mean + d <= max, "{m} {max}");
                }
            }
        }
        // A fifth of these (most are built badly conditioned or above the lower maximum).
        assert!(claimed > total / 10 && claimed < total, "{claimed} of {total}");
    }

    const MAX_VARIANCE_TEST: f64 = 1e16;

    #[test]
    fn covariance_clamp() {
        let m = DMat2::from_cols(DVec2::new(1.0, 2.0), DVec2::new(2.0, 1.0)); // eigen 3, -1
        let c = clamp_covariance(m, 10.0);
        let (l1, l2, _) = sym_eigen(c.cov);
        assert!((l1 - 3.0).abs() < 1e-12 && l2.abs() < 1e-12 && !c.clamped_above);
        let c = clamp_covariance(m * 100.0, 10.0);
        let (l1, _, _) = sym_eigen(c.cov);
        assert!((l1 - 10.0).abs() < 1e-9 && c.clamped_above);
        let c = clamp_covariance(DMat2::from_cols(DVec2::NAN, DVec2::ONE), 10.0);
        assert_eq!(c.cov, DMat2::from_diagonal(DVec2::splat(10.0)));
    }
}
