//! Expectations of functions of Gaussian variables: the closed forms that filtered nodes use.
//!
//! Everything here answers "what is `E[f(X)]` for `X ~ N(m, s²)`" for the shapes of `f` that
//! the node library needs: piecewise polynomials (clamp, smoothstep, ramps, Perlin's fade
//! kernel) through partial moments of the standard normal, square waves (checkerboard) through
//! step sums or their Fourier series, sines and exponentials in closed form, and anything else
//! through a Gauss–Hermite rule. Arithmetic is in `f64`; `s = 0` always gives `f(m)` exactly.

use std::f64::consts::{FRAC_1_SQRT_2, PI};

/// Standard normal density φ(z).
#[inline]
pub fn pdf(z: f64) -> f64 {
    (-0.5 * z * z).exp() * (0.5 / PI).sqrt()
}

/// Standard normal cumulative distribution Φ(z), accurate in both tails.
#[inline]
pub fn cdf(z: f64) -> f64 {
    0.5 * libm::erfc(-z * FRAC_1_SQRT_2)
}

/// Φ(b) − Φ(a) without cancellation when both lie in the same tail.
#[inline]
pub fn mass(a: f64, b: f64) -> f64 {
    if a > 0.0 {
        // Upper tail: Q(a) − Q(b).
        cdf(-a) - cdf(-b)
    } else {
        cdf(b) - cdf(a)
    }
}

/// Highest polynomial degree supported by [`poly_expectation`].
pub const MAX_DEGREE: usize = 7;

/// A polynomial `Σ c_k x^k` of degree ≤ [`MAX_DEGREE`], lowest coefficient first.
pub type Poly = [f64; MAX_DEGREE + 1];

/// Evaluates a polynomial at `x` (Horner).
#[inline]
pub fn poly_eval(p: &Poly, x: f64) -> f64 {
    p.iter().rev().fold(0.0, |acc, &c| acc * x + c)
}

/// Coefficients of `q(z) = p(m + s z)`.
pub fn poly_shift_scale(p: &Poly, m: f64, s: f64) -> Poly {
    // Taylor shift by m (synthetic division repeated), then scale by s^k.
    let mut c = *p;
    for i in 0..MAX_DEGREE {
        for k in (i..MAX_DEGREE).rev() {
            c[k] += m * c[k + 1];
        }
    }
    let mut sk = 1.0;
    for ck in c.iter_mut() {
        *ck *= sk;
        sk *= s;
    }
    c
}

/// Partial moments `I_k = ∫_a^b z^k φ(z) dz` of the standard normal, k = 0..=MAX_DEGREE.
fn partial_moments(a: f64, b: f64) -> Poly {
    let mut i = [0.0; MAX_DEGREE + 1];
    let (pa, pb) = (pdf_or_zero(a), pdf_or_zero(b));
    i[0] = mass(a, b);
    i[1] = pa - pb;
    // I_k = (k−1) I_{k−2} + a^{k−1} φ(a) − b^{k−1} φ(b); the boundary terms vanish at ±∞.
    let (mut ak, mut bk) = (1.0, 1.0); // a^{k-1}, b^{k-1} for k = 1
    for k in 2..=MAX_DEGREE {
        ak *= if a.is_finite() { a } else { 0.0 };
        bk *= if b.is_finite() { b } else { 0.0 };
        i[k] = (k as f64 - 1.0) * i[k - 2] + ak * pa - bk * pb;
    }
    i
}

#[inline]
fn pdf_or_zero(z: f64) -> f64 {
    if z.is_finite() {
        pdf(z)
    } else {
        0.0
    }
}

/// `E[p(X) · 1{lo ≤ X < hi}]` for `X ~ N(m, s²)`; `lo`/`hi` may be infinite.
pub fn poly_expectation(p: &Poly, lo: f64, hi: f64, m: f64, s: f64) -> f64 {
    if s <= 0.0 {
        return if lo <= m && m < hi { poly_eval(p, m) } else { 0.0 };
    }
    let (a, b) = ((lo - m) / s, (hi - m) / s);
    if a >= 8.5 || b <= -8.5 || a >= b {
        return 0.0;
    }
    let q = poly_shift_scale(p, m, s);
    let i = partial_moments(a.max(-40.0), b.min(40.0));
    q.iter().zip(i.iter()).map(|(c, ik)| c * ik).sum()
}

/// Tail moments at a boundary `z`, from which interval moments follow by differences without
/// cancellation: below zero `J_k(z) = ∫_{−∞}^z t^k φ`, at or above zero `K_k(z) = ∫_z^∞ t^k φ`.
#[derive(Clone, Copy, Debug)]
pub struct TailMoments {
    upper: bool,
    m: Poly,
}

/// |z| beyond which [`TailMoments::at`] is zero.
pub const TAIL_ZERO: f64 = 10.0;

/// Full moments `E[Z^k]` of the standard normal.
const FULL_MOMENTS: Poly = [1.0, 0.0, 1.0, 0.0, 3.0, 0.0, 15.0, 0.0];

impl TailMoments {
    /// Tail moments at `z` (clamped to ±40).
    pub fn at(z: f64) -> TailMoments {
        let upper = z >= 0.0;
        // Beyond 10σ every tail moment is below 1e-15 (|z|⁷ φ(z) at z = 10): zero, without the
        // special functions (a wide cell around a narrow footprint meets this at both ends).
        if z.abs() > TAIL_ZERO {
            return TailMoments { upper, m: [0.0; MAX_DEGREE + 1] };
        }
        let p = pdf(z);
        let mut m = [0.0; MAX_DEGREE + 1];
        // J_0 = Φ, J_1 = −φ, J_k = (k−1) J_{k−2} − z^{k−1} φ;  K_0 = Q, K_1 = φ, K_k = (k−1) K_{k−2} + z^{k−1} φ.
        let sign = if upper { 1.0 } else { -1.0 };
        m[0] = if upper { cdf(-z) } else { cdf(z) };
        m[1] = sign * p;
        let mut zk = 1.0;
        for k in 2..=MAX_DEGREE {
            zk *= z;
            m[k] = (k as f64 - 1.0) * m[k - 2] + sign * zk * p;
        }
        TailMoments { upper, m }
    }

    /// `J_k(z)` for this boundary.
    #[inline]
    fn lower(&self, k: usize) -> f64 {
        if self.upper {
            FULL_MOMENTS[k] - self.m[k]
        } else {
            self.m[k]
        }
    }

    /// Interval moments `∫_a^b t^k φ` between boundaries `a ≤ b`.
    pub fn between(a: &TailMoments, b: &TailMoments) -> Poly {
        let mut i = [0.0; MAX_DEGREE + 1];
        for (k, ik) in i.iter_mut().enumerate() {
            *ik = if a.upper && b.upper { a.m[k] - b.m[k] } else { b.lower(k) - a.lower(k) };
        }
        i
    }
}

/// `E[p(X) 1{X ∈ piece}]` for `X ~ N(m, s²)` from precomputed interval moments `i` of the
/// piece's standardised ends (`s > 0`).
#[inline]
pub fn poly_expectation_with(p: &Poly, m: f64, s: f64, i: &Poly) -> f64 {
    let q = poly_shift_scale(p, m, s);
    q.iter().zip(i.iter()).map(|(c, ik)| c * ik).sum()
}

/// One piece of a piecewise polynomial: `p` on `[lo, hi)`.
#[derive(Clone, Copy, Debug)]
pub struct Piece {
    /// Lower end (may be −∞).
    pub lo: f64,
    /// Upper end (may be +∞).
    pub hi: f64,
    /// The polynomial on this piece.
    pub p: Poly,
}

/// A polynomial from its first coefficients.
pub const fn poly(c: &[f64]) -> Poly {
    let mut p = [0.0; MAX_DEGREE + 1];
    let mut k = 0;
    while k < c.len() {
        p[k] = c[k];
        k += 1;
    }
    p
}

/// Product of two polynomials (degrees must sum to ≤ MAX_DEGREE).
pub fn poly_mul(a: &Poly, b: &Poly) -> Poly {
    let mut r = [0.0; MAX_DEGREE + 1];
    for (i, ai) in a.iter().enumerate() {
        if *ai == 0.0 {
            continue;
        }
        for (j, bj) in b.iter().enumerate() {
            if i + j <= MAX_DEGREE {
                r[i + j] += ai * bj;
            } else {
                debug_assert!(*bj == 0.0, "polynomial degree overflow");
            }
        }
    }
    r
}

/// Derivative of a polynomial.
pub fn poly_deriv(p: &Poly) -> Poly {
    let mut r = [0.0; MAX_DEGREE + 1];
    for k in 1..=MAX_DEGREE {
        r[k - 1] = k as f64 * p[k];
    }
    r
}

/// Mean and variance of `f(X)` for a piecewise-polynomial `f` (pieces of degree ≤ 3 for the
/// variance to be exact; higher degrees give the mean only and `var = NaN`), plus
/// `d E[f(X)] / dm`.
pub fn piecewise_moments(pieces: &[Piece], m: f64, s: f64) -> (f64, f64, f64) {
    let mut mean = 0.0;
    let mut second = 0.0;
    let mut dmean = 0.0;
    for pc in pieces {
        mean += poly_expectation(&pc.p, pc.lo, pc.hi, m, s);
        second += poly_expectation(&poly_mul(&pc.p, &pc.p), pc.lo, pc.hi, m, s);
        dmean += poly_expectation(&poly_deriv(&pc.p), pc.lo, pc.hi, m, s);
        // Jumps at the piece ends also move the mean: + φ density × jump. Handled by callers
        // whose functions jump (steps) through `step_moments`; continuous pieces need nothing.
    }
    (mean, (second - mean * mean).max(0.0), dmean)
}

/// Mean, variance and `dE/dm` of the unit step `1{X ≥ c}`.
pub fn step_moments(c: f64, m: f64, s: f64) -> (f64, f64, f64) {
    if s <= 0.0 {
        let v = if m >= c { 1.0 } else { 0.0 };
        return (v, 0.0, 0.0);
    }
    let z = (m - c) / s;
    let p = cdf(z);
    (p, p * (1.0 - p), pdf(z) / s)
}

/// `E[sin(X)]`, `E[cos(X)]` for `X ~ N(m, s²)`: attenuated by `e^{−s²/2}`.
pub fn sin_cos_expectation(m: f64, s: f64) -> (f64, f64) {
    let a = (-0.5 * s * s).exp();
    (m.sin() * a, m.cos() * a)
}

/// Mean and `dE/dm` of the square wave `sq(x) = +1` on `[2k, 2k+1)`, `−1` on `[2k+1, 2k+2)`.
///
/// Small `s`: a sum of step masses over the few edges within ±7s. Large `s`: its Fourier series
/// `(4/π) Σ_{j odd} sin(πjx)/j`, whose terms the Gaussian damps by `e^{−π²j²s²/2}`; above
/// `s = 3.5` the mean is 0 to 1e-26 and nothing is evaluated.
pub fn square_wave_expectation(m: f64, s: f64) -> (f64, f64) {
    if s <= 0.0 {
        let k = m.floor();
        return (if (k as i64).rem_euclid(2) == 0 { 1.0 } else { -1.0 }, 0.0);
    }
    if s < 0.4 {
        let lo = (m - 7.0 * s).floor();
        let hi = (m + 7.0 * s).floor();
        let (mut e, mut de) = (0.0, 0.0);
        let mut k = lo;
        while k <= hi {
            let sign = if (k as i64).rem_euclid(2) == 0 { 1.0 } else { -1.0 };
            let (a, b) = ((k - m) / s, (k + 1.0 - m) / s);
            e += sign * mass(a, b);
            de += sign * (pdf(a) - pdf(b)) / s;
            k += 1.0;
        }
        (e, de)
    } else if s < 3.5 {
        let (mut e, mut de) = (0.0, 0.0);
        for j in [1.0, 3.0, 5.0] {
            let w = PI * j;
            let att = (-0.5 * w * w * s * s).exp();
            e += (w * m).sin() * att / j;
            de += w * (w * m).cos() * att / j;
        }
        (4.0 / PI * e, 4.0 / PI * de)
    } else {
        (0.0, 0.0)
    }
}

/// Nodes and weights of the 5-point Gauss–Hermite rule for `E[f(Z)]`, `Z ~ N(0, 1)`.
pub const HERMITE5: [(f64, f64); 5] = [
    (-2.856_970_013_872_805_6, 0.011_257_411_327_720_69),
    (-1.355_626_179_974_266, 0.222_075_922_005_612_6),
    (0.0, 0.533_333_333_333_333_3),
    (1.355_626_179_974_266, 0.222_075_922_005_612_6),
    (2.856_970_013_872_805_6, 0.011_257_411_327_720_69),
];

/// Nodes and weights of the 3-point Gauss–Hermite rule for `E[f(Z)]`, `Z ~ N(0, 1)`.
pub const HERMITE3: [(f64, f64); 3] =
    [(-1.732_050_807_568_877_2, 1.0 / 6.0), (0.0, 2.0 / 3.0), (1.732_050_807_568_877_2, 1.0 / 6.0)];

/// Mean and variance of `f(X)` by the 5-point Gauss–Hermite rule (exact for polynomials of
/// degree ≤ 9); `s = 0` evaluates `f(m)` once.
pub fn hermite_moments(f: impl Fn(f64) -> f64, m: f64, s: f64) -> (f64, f64) {
    if s <= 0.0 {
        return (f(m), 0.0);
    }
    let (e, v, _) = hermite_stein(f, m, s);
    (e, v)
}

/// Mean, variance and `dE/dm` of `f(X)`, `X ~ N(m, s²)`, `s > 0`, on the 5-point Gauss–Hermite
/// nodes; the slope by Stein's identity `E[f'(X)] = E[(X − m) f(X)] / s²`.
pub fn hermite_stein(f: impl Fn(f64) -> f64, m: f64, s: f64) -> (f64, f64, f64) {
    let (mut e, mut e2, mut ez) = (0.0, 0.0, 0.0);
    for (z, w) in HERMITE5 {
        let y = f(m + s * z);
        e += w * y;
        e2 += w * y * y;
        ez += w * z * y;
    }
    (e, (e2 - e * e).max(0.0), ez / s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(f: impl Fn(f64) -> f64, m: f64, s: f64) -> f64 {
        // Midpoint rule over ±9s.
        let n = 20000;
        let h = 18.0 * s / n as f64;
        (0..n)
            .map(|i| {
                let x = m - 9.0 * s + (i as f64 + 0.5) * h;
                f(x) * pdf((x - m) / s) / s * h
            })
            .sum()
    }

    #[test]
    fn cdf_matches_known_values() {
        assert!((cdf(0.0) - 0.5).abs() < 1e-15);
        assert!((cdf(1.0) - 0.841_344_746_068_542_9).abs() < 1e-12);
        assert!((cdf(-5.0) - 2.866_515_718_791_939e-7).abs() < 1e-18);
    }

    #[test]
    fn poly_expectation_matches_quadrature() {
        let p = poly(&[0.3, -1.0, 2.0, 0.5, -0.25, 0.1]);
        for &(lo, hi, m, s) in &[(0.0, 1.0, 0.3, 0.2), (-1.0, 0.5, 2.0, 1.5), (0.2, 0.3, 0.25, 1e-3)] {
            let exact = poly_expectation(&p, lo, hi, m, s);
            let b = brute(|x| if lo <= x && x < hi { poly_eval(&p, x) } else { 0.0 }, m, s);
            assert!((exact - b).abs() < 5e-5, "{exact} vs {b}");
        }
        // Full line: E[X²] = m² + s².
        let e = poly_expectation(&poly(&[0.0, 0.0, 1.0]), f64::NEG_INFINITY, f64::INFINITY, 3.0, 0.5);
        assert!((e - 9.25).abs() < 1e-12);
    }

    #[test]
    fn square_wave_branches_agree() {
        for &m in &[0.1, 0.5, 0.97, 1.3, -2.2] {
            for &s in &[0.01, 0.2, 0.39, 0.41, 1.0] {
                let (e, _) = square_wave_expectation(m, s);
                let b = brute(|x| if (x.floor() as i64).rem_euclid(2) == 0 { 1.0 } else { -1.0 }, m, s);
                assert!((e - b).abs() < 2e-3, "m {m} s {s}: {e} vs {b}");
            }
        }
    }
}
