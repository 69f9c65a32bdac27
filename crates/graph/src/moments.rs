//! Propagating [`Moments`] through arithmetic: the algebra that linear and nonlinear nodes share.
//!
//! Linear maps are exact: means and gradients map linearly, variances by `k² var` plus the
//! covariance of the two operands, which we estimate from their gradients (`gₐ Σ g_bᵀ`, clamped
//! to the Cauchy–Schwarz bound) — exact for affine functions of uv, and zero for operands that
//! merely look independent. Products use the Gaussian product moments. Nonlinear functions of
//! one channel use closed forms or a Gauss–Hermite rule ([`unary`]); of several channels a
//! spherical cubature over their (assumed independent) spreads ([`nary`]).

use crate::gaussian;
use crate::value::{Footprint, Moments};
use glam::Vec2;

/// Whether every part of `m` is finite (one sum; an overflowing sum of finite parts only sends a
/// caller to its exact path).
#[inline]
fn all_finite(m: &Moments) -> bool {
    (m.mean + m.grad.x + m.grad.y + m.var).is_finite()
}

// The algebra below computes in f32 first (the common case, and the values MaterialX's f32
// shaders give) and redoes the computation in f64, saturating to the f32 range, only when the
// f32 result is not finite: huge operands then never make a 0 · ∞ or ∞ − ∞.

/// Estimated covariance of two channels over the footprint.
#[inline(always)]
pub fn cov(a: &Moments, b: &Moments, fp: &Footprint) -> f32 {
    let c = fp.quad(a.grad, b.grad);
    let vv = a.var.max(0.0) * b.var.max(0.0);
    // Well inside the Cauchy–Schwarz bound (the common case): `c` itself, as the clamp below
    // would give it (the margin covers the rounding of both squares), without its square root.
    // A NaN or an overflow fails the test and takes the full path.
    if c * c <= vv * 0.999_99 && vv <= f32::MAX {
        return c;
    }
    let bound = vv.sqrt();
    if c.is_finite() && bound.is_finite() {
        return c.max(-bound).min(bound);
    }
    let (g, h) = (a.grad.as_dvec2(), b.grad.as_dvec2());
    let c = g.dot(fp.cov.as_dmat2() * h);
    let bound = (a.var.max(0.0) as f64 * b.var.max(0.0) as f64).sqrt();
    // max/min rather than clamp: no panic should a bound be NaN.
    sat(c.max(-bound).min(bound))
}

/// `k a + c`.
#[inline(always)]
pub fn affine(a: Moments, k: f32, c: f32) -> Moments {
    let r = Moments { mean: k * a.mean + c, grad: a.grad * k, var: k * k * a.var };
    if all_finite(&r) {
        return r;
    }
    let (k, m) = (sat64(k as f64), a.mean as f64);
    Moments { mean: sat(k * m + c as f64), grad: scale_grad(a.grad, k), var: sat(k * k * a.var as f64) }
}

/// `a + k b`.
#[inline(always)]
pub fn add_scaled(a: Moments, b: Moments, k: f32, fp: &Footprint) -> Moments {
    let c = cov(&a, &b, fp);
    let r = Moments {
        mean: a.mean + k * b.mean,
        grad: a.grad + b.grad * k,
        var: (a.var + k * k * b.var + 2.0 * k * c).max(0.0),
    };
    if all_finite(&r) {
        return r;
    }
    let (c, k) = (c as f64, k as f64);
    let g = scale_grad(b.grad, k);
    Moments {
        mean: sat(a.mean as f64 + k * b.mean as f64),
        grad: Vec2::new(sat(a.grad.x as f64 + g.x as f64), sat(a.grad.y as f64 + g.y as f64)),
        var: sat((a.var as f64 + k * k * b.var as f64 + 2.0 * k * c).max(0.0)),
    }
}

/// `Σ kᵢ xᵢ` (up to four terms), with every pair's covariance: the variance of each term is
/// its own, the cross terms are estimated from gradients. Exact where [`add_scaled`] chained
/// over a sum that shares its terms (a channel and a luminance made of it) would lose the
/// shared part's covariance to the gradient estimate.
pub fn linear(k: &[f32], xs: &[Moments], fp: &Footprint) -> Moments {
    debug_assert!(k.len() == xs.len() && xs.len() <= 4);
    let (mut mean, mut grad, mut var) = (0.0f64, Vec2::ZERO, 0.0f64);
    for (i, (ki, xi)) in k.iter().zip(xs).enumerate() {
        mean += *ki as f64 * xi.mean as f64;
        grad = add_grad(grad, scale_grad(xi.grad, *ki as f64));
        var += (*ki as f64).powi(2) * xi.var as f64;
        for (kj, xj) in k.iter().zip(xs).skip(i + 1) {
            var += 2.0 * *ki as f64 * *kj as f64 * cov(xi, xj, fp) as f64;
        }
    }
    Moments { mean: sat(mean), grad, var: sat(var.max(0.0)) }
}

/// `a · b` for jointly Gaussian operands.
#[inline(always)]
pub fn mul(a: Moments, b: Moments, fp: &Footprint) -> Moments {
    if b.var == 0.0 && b.grad == Vec2::ZERO {
        return affine(a, b.mean, 0.0);
    }
    if a.var == 0.0 && a.grad == Vec2::ZERO {
        return affine(b, a.mean, 0.0);
    }
    let c = cov(&a, &b, fp);
    let r = Moments {
        mean: a.mean * b.mean + c,
        grad: a.grad * b.mean + b.grad * a.mean,
        var: (a.mean * a.mean * b.var + b.mean * b.mean * a.var + 2.0 * a.mean * b.mean * c + a.var * b.var + c * c)
            .max(0.0),
    };
    if all_finite(&r) {
        return r;
    }
    let c = c as f64;
    let (am, bm, av, bv) = (a.mean as f64, b.mean as f64, a.var as f64, b.var as f64);
    let (ga, gb) = (scale_grad(a.grad, bm), scale_grad(b.grad, am));
    Moments {
        mean: sat(am * bm + c),
        grad: Vec2::new(sat(ga.x as f64 + gb.x as f64), sat(ga.y as f64 + gb.y as f64)),
        var: sat((am * am * bv + bm * bm * av + 2.0 * am * bm * c + av * bv + c * c).max(0.0)),
    }
}

/// `bg + (fg − bg) t`.
#[inline(always)]
pub fn mix(bg: Moments, fg: Moments, t: Moments, fp: &Footprint) -> Moments {
    let d = add_scaled(fg, bg, -1.0, fp);
    add_scaled(bg, mul(d, t, fp), 1.0, fp)
}

/// Moments of `f(X)` from mean, variance and `dE/dm` of a scalar function, chaining the
/// gradient through `x`'s.
#[inline]
pub fn chain(x: Moments, (mean, var, dmean): (f64, f64, f64)) -> Moments {
    Moments { mean: sat(mean), grad: scale_grad(x.grad, dmean), var: sat(var) }
}

/// `x` as an `f32`, saturated to ±`f32::MAX` (NaN stays NaN): the overflow rule of every node.
#[inline]
pub fn sat(x: f64) -> f32 {
    x.clamp(-(f32::MAX as f64), f32::MAX as f64) as f32
}

/// `x / y`, total: 0 where `y = 0` (OSL's convention, shared by every node that divides).
#[inline]
pub fn safe_div(x: f64, y: f64) -> f64 {
    if y == 0.0 {
        0.0
    } else {
        sat64(x / y)
    }
}

/// `x` clamped to the f32 range, staying in f64 (NaN stays NaN): for intermediate values of
/// point functions, so that a later `0 · x` or `x − x` cannot make a NaN of an overflow.
#[inline]
pub fn sat64(x: f64) -> f64 {
    x.clamp(-(f32::MAX as f64), f32::MAX as f64)
}

/// `1 / x` with [`safe_div`]'s rule (0 at 0), in f32.
#[inline]
pub fn recip(x: f32) -> f32 {
    if x == 0.0 {
        0.0
    } else {
        sat(1.0 / x as f64)
    }
}

/// `g + h`, saturated.
#[inline]
pub fn add_grad(g: Vec2, h: Vec2) -> Vec2 {
    let r = g + h;
    if r.is_finite() {
        return r;
    }
    Vec2::new(sat(g.x as f64 + h.x as f64), sat(g.y as f64 + h.y as f64))
}

/// `g · k` for a gradient `g` and a slope `k`, in f64 then saturated: a zero gradient stays zero
/// whatever the slope (never `0 · ∞`).
#[inline]
pub fn scale_grad(g: Vec2, k: f64) -> Vec2 {
    let r = g * k as f32;
    if r.is_finite() {
        return r;
    }
    let one = |x: f32| if x == 0.0 { 0.0 } else { sat(x as f64 * k) };
    Vec2::new(one(g.x), one(g.y))
}

/// A nonlinear function of one channel, `f`, with its derivative `df` (for the point case):
/// mean and variance by 5-point Gauss–Hermite, `dE/dm` by Stein's identity
/// `E[f'(X)] = E[(X − m) f(X)] / s²` on the same nodes.
pub fn unary(x: Moments, f: impl Fn(f64) -> f64, df: impl Fn(f64) -> f64) -> Moments {
    let m = x.mean as f64;
    let s = x.sigma() as f64;
    if s == 0.0 {
        return Moments { mean: sat(f(m)), grad: scale_grad(x.grad, df(m)), var: 0.0 };
    }
    // Values in the f32 range (saturated), so that the rule's sums of squares stay finite.
    chain(x, gaussian::hermite_stein(|v| sat64(f(v)), m, s))
}

/// Maximum number of channels [`nary`] combines.
pub const NARY_MAX: usize = 16;

/// A nonlinear function of several channels: spherical cubature (points `m ± √n σ_k e_k`,
/// weights `1/2n`) over the channels that vary, treated as independent; exact for cubic `f`.
/// The gradient is the chain rule with slopes from the same points (finite differences of
/// width `1e-3` where a channel has a gradient but no spread).
pub fn nary(xs: &[Moments], f: impl Fn(&[f64]) -> f64) -> Moments {
    debug_assert!(xs.len() <= NARY_MAX);
    let mut p = [0.0f64; NARY_MAX];
    for (pi, x) in p.iter_mut().zip(xs) {
        *pi = x.mean as f64;
    }
    let n = xs.len();
    let varying = xs.iter().filter(|x| x.var > 0.0).count();
    // Every value of f is taken in the f32 range (saturated), so that sums of squares stay
    // finite in f64.
    let f = |q: &[f64]| sat64(f(q));
    let f0 = f(&p[..n]);
    let mut grad = Vec2::ZERO;
    if varying == 0 {
        for k in 0..n {
            if xs[k].grad != Vec2::ZERO {
                let h = 1e-3 * (1.0 + p[k].abs());
                let mk = p[k];
                p[k] = mk + h;
                let fp = f(&p[..n]);
                p[k] = mk - h;
                let fm = f(&p[..n]);
                p[k] = mk;
                grad = add_grad(grad, scale_grad(xs[k].grad, (fp - fm) / (2.0 * h)));
            }
        }
        return Moments { mean: sat(f0), grad, var: 0.0 };
    }
    let r = (varying as f64).sqrt();
    let w = 0.5 / varying as f64;
    let (mut e, mut e2) = (0.0, 0.0);
    for k in 0..n {
        if xs[k].var <= 0.0 {
            continue;
        }
        let d = r * xs[k].sigma() as f64;
        let mk = p[k];
        p[k] = mk + d;
        let fp = f(&p[..n]);
        p[k] = mk - d;
        let fm = f(&p[..n]);
        p[k] = mk;
        e += w * (fp + fm);
        e2 += w * (fp * fp + fm * fm);
        grad = add_grad(grad, scale_grad(xs[k].grad, (fp - fm) / (2.0 * d)));
    }
    Moments { mean: sat(e), grad, var: sat((e2 - e * e).max(0.0)) }
}

/// Moments of `frac(X)` (`x − floor x`) for `X ~ N(m, s²)`, and the mean of `floor(X)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FracMoments {
    /// `E[frac X]`.
    pub mean: f64,
    /// `Var[frac X]`.
    pub var: f64,
    /// `d E[frac X] / dm` (1 minus the density of the integers the footprint crosses).
    pub dmean: f64,
    /// `E[floor X]`, exactly the cell's integer when the footprint lies within one cell.
    pub floor: f64,
}

/// [`FracMoments`] of `N(m, s²)`.
pub fn frac_moments(m: f64, s: f64) -> FracMoments {
    use std::f64::consts::PI;
    if s <= 0.0 {
        let f = m - m.floor();
        return FracMoments { mean: f, var: 0.0, dmean: 1.0, floor: m.floor() };
    }
    if s < 0.4 {
        // Shifted by the lowest cell within 7σ, `X' = X − lo` has the same fraction and floor
        // `N = Σ_k 1{X' ≥ k}` over the integers k in between, which each cut the footprint:
        // E[N] = Σ Q_k, E[X' N] = Σ (m' Q_k + s φ_k), E[N²] = Σ (2k − 1) Q_k (N² = Σ_{j ≤ N} 2j − 1),
        // with Q_k = P(X' ≥ k) and φ_k the density there over s. One erfc and one exp per integer;
        // a footprint inside one cell needs neither, and its floor is that cell's integer exactly
        // (no spread: a cell noise of it is the cell's own value, not a blend with the next).
        let lo = (m - 7.0 * s).floor();
        let hi = (m + 7.0 * s).floor();
        let m1 = m - lo;
        let (mut en, mut exn, mut en2, mut dens) = (0.0, 0.0, 0.0, 0.0);
        for k in gaussian::cells(1.0, hi - lo) {
            let z = (k - m1) / s;
            let q = gaussian::cdf(-z);
            let phi = gaussian::pdf(z);
            en += q;
            exn += m1 * q + s * phi;
            en2 += (2.0 * k - 1.0) * q;
            dens += phi / s;
        }
        // frac = X' − N: Var = s² + Var N − 2 Cov(X', N), each part central (no cancellation
        // against m'²), and exactly s² when nothing is crossed.
        let var_n = (en2 - en * en).max(0.0);
        let cov = exn - m1 * en;
        let var = (s * s + var_n - 2.0 * cov).max(0.0);
        FracMoments { mean: m1 - en, var, dmean: 1.0 - dens, floor: lo + en }
    } else {
        // frac(x) = 1/2 − Σ sin(2πnx)/(πn);  frac² = 1/3 + Σ [cos(2πnx)/(π²n²) − sin(2πnx)/(πn)].
        let (mut e, mut e2, mut de) = (0.5, 1.0 / 3.0, 0.0);
        for n in 1..=4 {
            let nf = n as f64;
            let w = 2.0 * PI * nf;
            let att = gaussian::exp_damping(-0.5 * w * w * s * s);
            if att < 1e-12 {
                break;
            }
            let (sn, cs) = (w * m).sin_cos();
            e -= sn * att / (PI * nf);
            e2 += (cs / (PI * PI * nf * nf) - sn / (PI * nf)) * att;
            de -= w * cs * att / (PI * nf);
        }
        FracMoments { mean: e, var: (e2 - e * e).max(0.0), dmean: de, floor: m - e }
    }
}

/// Mean, variance and `dE/dm` of the triangle wave `tri(X)`, the distance from `X` to the
/// nearest integer (MaterialX's `trianglewave`, `0.5 − |mod(|x|, 1) − 0.5|`), for
/// `X ~ N(m, s²)`.
///
/// Below 0.4 periods of spread: exact, as the wave's linear pieces over the half-cells within
/// ±7σ (the centre moved into [0, 1) first, the wave being periodic). Above: its Fourier series
/// `tri = 1/4 − (2/π²) Σ_{k odd} cos(2πkx)/k²` and `tri² = 1/12 + Σ_k (−1)^k cos(2πkx)/(π²k²)`,
/// each mode damped by `e^{−2π²k²s²}` (below 1e-12 from k = 3 on).
pub fn tri_moments(m: f64, s: f64) -> (f64, f64, f64) {
    use gaussian::{cells, piecewise_moments, poly, Piece};
    use std::f64::consts::PI;
    let f = m - m.floor();
    if s <= 0.0 || !f.is_finite() {
        let slope = if f < 0.5 { 1.0 } else { -1.0 };
        return (f.min(1.0 - f), 0.0, slope);
    }
    if s < 0.4 {
        const MAX: usize = 16;
        let empty = Piece { lo: 0.0, hi: 0.0, p: poly(&[]) };
        let mut pieces = [empty; MAX];
        let mut n = 0;
        for h in cells((2.0 * (f - 7.0 * s)).floor(), (2.0 * (f + 7.0 * s)).floor()).take(MAX) {
            let (lo, j) = (0.5 * h, (0.5 * h).floor());
            // Rising from the integer j on its first half, falling to j + 1 on its second.
            let p = if lo == j { poly(&[-j, 1.0]) } else { poly(&[j + 1.0, -1.0]) };
            pieces[n] = Piece { lo, hi: lo + 0.5, p };
            n += 1;
        }
        return piecewise_moments(&pieces[..n], f, s);
    }
    let (mut e, mut e2, mut de) = (0.25, 1.0 / 12.0, 0.0);
    for k in 1..=4 {
        let kf = k as f64;
        let w = 2.0 * PI * kf;
        let att = gaussian::exp_damping(-0.5 * w * w * s * s);
        if att < 1e-12 {
            break;
        }
        let (sn, cs) = (w * f).sin_cos();
        if k % 2 == 1 {
            e -= 2.0 / (PI * PI * kf * kf) * cs * att;
            de += 4.0 / (PI * kf) * sn * att;
        }
        let sign = if k % 2 == 1 { -1.0 } else { 1.0 };
        e2 += sign * cs * att / (PI * PI * kf * kf);
    }
    (e, (e2 - e * e).max(0.0), de)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `E[g(X)]` for `X ~ N(m, s²)` by the midpoint rule over ±9σ (400 000 points).
    fn quadrature(m: f64, s: f64, g: impl Fn(f64) -> f64) -> f64 {
        let n = 400_000;
        let (lo, h) = (m - 9.0 * s, 18.0 * s / n as f64);
        let (mut acc, mut wsum) = (0.0, 0.0);
        for i in 0..n {
            let x = lo + (i as f64 + 0.5) * h;
            let w = (-0.5 * ((x - m) / s).powi(2)).exp();
            acc += w * g(x);
            wsum += w;
        }
        acc / wsum
    }

    /// Mean, variance, slope and the floor's mean of frac against direct integration, on both
    /// sides of the small-spread / Fourier switch and far from the origin.
    #[test]
    fn frac_moments_match_direct_integration() {
        for &(m, s) in
            &[(0.3, 0.05), (2.97, 0.02), (-7.5, 0.2), (1234.6, 0.35), (0.1, 0.45), (-40.2, 1.3), (3.0, 0.001)]
        {
            let f = frac_moments(m, s);
            let frac = |x: f64| x - x.floor();
            let e = quadrature(m, s, frac);
            let var = quadrature(m, s, |x| (frac(x) - e).powi(2));
            let fl = quadrature(m, s, f64::floor);
            // A step of a hundredth of σ: the quadrature's grid moves with m, so a smaller one
            // would difference its discretisation of the jump.
            let h = 1e-2 * s;
            let slope = (quadrature(m + h, s, frac) - quadrature(m - h, s, frac)) / (2.0 * h);
            let tol = 2e-4;
            assert!((f.mean - e).abs() < tol, "m {m} s {s}: mean {} vs {e}", f.mean);
            assert!((f.var - var).abs() < tol, "m {m} s {s}: var {} vs {var}", f.var);
            assert!((f.floor - fl).abs() < tol, "m {m} s {s}: floor {} vs {fl}", f.floor);
            assert!((f.dmean - slope).abs() < 2e-2 * (1.0 + slope.abs()), "m {m} s {s}: slope {} vs {slope}", f.dmean);
        }
    }

    /// A footprint inside one cell: the floor is that cell's integer, with no spread or slope (a
    /// spread made of rounding noise put cell noise of it on a cell edge).
    #[test]
    fn floor_inside_one_cell_is_exact() {
        for &(m, s) in &[(0.5, 0.01), (1e4 + 0.37, 0.02), (-3.6, 1e-6), (7.9, 1e-3)] {
            let f = frac_moments(m, s);
            assert_eq!(f.floor, m.floor(), "m {m} s {s}");
            assert_eq!(f.dmean, 1.0, "m {m} s {s}");
            assert_eq!(f.var, s * s, "m {m} s {s}");
        }
    }

    /// The triangle wave's moments against direct integration, on both sides of the switch to
    /// the Fourier series, far from the origin and at negative centres.
    #[test]
    fn triangle_wave_moments_match_direct_integration() {
        let tri = |x: f64| 0.5 - ((x.abs() - x.abs().floor()) - 0.5).abs();
        for &(m, s) in
            &[(0.3, 0.05), (2.97, 0.02), (-7.5, 0.2), (1234.6, 0.35), (0.1, 0.45), (-40.2, 1.3), (3.0, 0.001)]
        {
            let (e, v, de) = tri_moments(m, s);
            let want = quadrature(m, s, tri);
            let want2 = quadrature(m, s, |x| tri(x).powi(2)) - want * want;
            let h = 1e-4 * s.max(1e-3);
            let slope = (quadrature(m + h, s, tri) - quadrature(m - h, s, tri)) / (2.0 * h);
            assert!((e - want).abs() < 1e-6, "mean m {m} s {s}: {e} vs {want}");
            assert!((v - want2).abs() < 1e-6, "var m {m} s {s}: {v} vs {want2}");
            assert!((de - slope).abs() < 1e-3, "slope m {m} s {s}: {de} vs {slope}");
        }
    }
}
