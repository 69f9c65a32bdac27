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
    // Far beyond the footprint (a piece's end, a cell's edge) without libm's underflow path.
    exp_damping(-0.5 * z * z) * (0.5 / PI).sqrt()
}

/// `eˣ`, with the exact 0 of every `x < −746` (`eˣ` rounds to 0 below −745.14) returned without
/// libm's underflow path, which costs as much as a filtered node: for the Gaussian densities and
/// dampings (Fourier series, octaves) whose exponents grow without bound with the footprint.
#[inline]
pub fn exp_damping(x: f64) -> f64 {
    if x < -746.0 {
        0.0
    } else {
        x.exp()
    }
}

/// Standard normal cumulative distribution Φ(z), accurate in both tails.
#[inline]
pub fn cdf(z: f64) -> f64 {
    0.5 * erfc(-z * FRAC_1_SQRT_2)
}

extern "C" {
    /// The C library's complementary error function (glibc, musl, macOS's and the Universal C
    /// Runtime's all have one; Rust's standard library links it already).
    #[link_name = "erfc"]
    fn c_erfc(x: f64) -> f64;
}

/// Below this `|x|` the `libm` crate's erfc is a rational function without an exponential,
/// faster than the C library's call (3 ns against 5.5 ns on this project's machine).
const ERFC_RATIONAL_LIMIT: f64 = 0.84375;

/// `erfc(x)`, accurate to a few units in the last place everywhere: the `libm` crate's near 0,
/// the C library's beyond [`ERFC_RATIONAL_LIMIT`], where `libm`'s takes two of its own `exp`s
/// and measured 1.7–4× slower (16–22 ns against 10–12 ns from 0.85 to 27, 22 ns against 5 ns
/// for negative arguments). The two differ by at most 5 ulp; filtered values are rounded to
/// `f32` after.
#[inline]
pub fn erfc(x: f64) -> f64 {
    // NaN fails the comparison and goes to the C library, whose erfc(NaN) is NaN.
    if x.abs() < ERFC_RATIONAL_LIMIT {
        libm::erfc(x)
    } else {
        // SAFETY: `erfc` is a pure function of one double with no preconditions.
        unsafe { c_erfc(x) }
    }
}

/// `(Φ(z), 1 − Φ(z))` from one erfc, each accurate in its own tail.
#[inline]
pub fn tails(z: f64) -> (f64, f64) {
    if z > 0.0 {
        let q = cdf(-z);
        (1.0 - q, q)
    } else {
        let p = cdf(z);
        (p, 1.0 - p)
    }
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
    match piece_moments(lo, hi, m, s) {
        Some(i) => dot(&poly_shift_scale(p, m, s), &i),
        None => 0.0,
    }
}

/// Beyond this many σ a piece's end counts as infinite (the normal's mass beyond is 1e-17).
const PIECE_REACH: f64 = 8.5;

/// The standardised partial moments of the piece `[lo, hi)` under `N(m, s²)` (`s > 0`), or
/// `None` when it carries no mass. A piece that holds the whole footprint gets the full moments,
/// without special functions.
#[inline]
fn piece_moments(lo: f64, hi: f64, m: f64, s: f64) -> Option<Poly> {
    let (a, b) = ((lo - m) / s, (hi - m) / s);
    if a >= PIECE_REACH || b <= -PIECE_REACH || a >= b {
        return None;
    }
    Some(if a <= -PIECE_REACH && b >= PIECE_REACH { FULL_MOMENTS } else { partial_moments(a.max(-40.0), b.min(40.0)) })
}

#[inline]
fn dot(p: &Poly, i: &Poly) -> f64 {
    p.iter().zip(i.iter()).map(|(c, ik)| c * ik).sum()
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
    /// Tail moments at `z` (zero beyond ±[`TAIL_ZERO`]).
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
/// variance to be exact; the square of a higher degree loses its terms beyond
/// [`MAX_DEGREE`]), plus `d E[f(X)] / dm`.
///
/// Each piece's polynomial is shifted and scaled to the standard normal once: its square and its
/// derivative follow from that (`q(z) = p(m + sz)` gives `p² → q²` and `p′ → q′/s`). Each
/// boundary's special functions ([`TailMoments::at`], one `exp` and one `erfc`) are computed once
/// and shared by the two pieces that meet there, and a constant piece needs only its mass.
pub fn piecewise_moments(pieces: &[Piece], m: f64, s: f64) -> (f64, f64, f64) {
    let mut mean = 0.0;
    let mut second = 0.0;
    let mut dmean = 0.0;
    if s <= 0.0 {
        for pc in pieces {
            if pc.lo <= m && m < pc.hi {
                mean += poly_eval(&pc.p, m);
                second += poly_eval(&pc.p, m).powi(2);
                dmean += poly_eval(&poly_deriv(&pc.p), m);
            }
        }
        return (mean, (second - mean * mean).max(0.0), dmean);
    }
    // The boundary last evaluated: a piece's upper end is usually the next one's lower end.
    let mut last: Option<(f64, TailMoments)> = None;
    let mut tail_at = |z: f64| match last {
        Some((lz, t)) if lz == z => t,
        _ => {
            let t = TailMoments::at(z);
            last = Some((z, t));
            t
        }
    };
    for pc in pieces {
        let (a, b) = ((pc.lo - m) / s, (pc.hi - m) / s);
        if a >= PIECE_REACH || b <= -PIECE_REACH || a >= b {
            continue;
        }
        let i = if a <= -PIECE_REACH && b >= PIECE_REACH {
            FULL_MOMENTS
        } else {
            let ta = tail_at(a);
            TailMoments::between(&ta, &tail_at(b))
        };
        // Jumps at the piece ends also move the mean: + φ density × jump. Handled by callers
        // whose functions jump (steps) through `step_moments`; continuous pieces need nothing.
        if pc.p[1..].iter().all(|&c| c == 0.0) {
            let c = pc.p[0];
            mean += c * i[0];
            second += c * c * i[0];
            continue;
        }
        let q = poly_shift_scale(&pc.p, m, s);
        mean += dot(&q, &i);
        second += dot(&poly_mul(&q, &q), &i);
        let mut dq = 0.0;
        for k in 1..=MAX_DEGREE {
            dq += k as f64 * q[k] * i[k - 1];
        }
        dmean += dq / s;
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

/// The whole numbers `lo, lo + 1, …, hi` (`lo`, `hi` whole; none if `hi < lo`), at most 4097:
/// the cells a footprint covers. Counted in integers, so that the loop ends even where f64 no
/// longer tells `k` from `k + 1` (callers reach a few dozen cells).
#[inline]
pub fn cells(lo: f64, hi: f64) -> impl Iterator<Item = f64> {
    let n = if hi >= lo { (hi - lo).min(4096.0) as u32 + 1 } else { 0 };
    (0..n).map(move |i| lo + i as f64)
}

/// `E[sin(X)]`, `E[cos(X)]` for `X ~ N(m, s²)`: attenuated by `e^{−s²/2}`.
pub fn sin_cos_expectation(m: f64, s: f64) -> (f64, f64) {
    let a = exp_damping(-0.5 * s * s);
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
        // Counted in integers: far out, `k + 1` would equal `k` and never pass `hi`.
        for k in cells(lo, hi) {
            let sign = if (k as i64).rem_euclid(2) == 0 { 1.0 } else { -1.0 };
            let (a, b) = ((k - m) / s, (k + 1.0 - m) / s);
            e += sign * mass(a, b);
            de += sign * (pdf(a) - pdf(b)) / s;
        }
        (e, de)
    } else if s < 3.5 {
        let (mut e, mut de) = (0.0, 0.0);
        for j in [1.0, 3.0, 5.0] {
            let w = PI * j;
            let att = exp_damping(-0.5 * w * w * s * s);
            e += (w * m).sin() * att / j;
            de += w * (w * m).cos() * att / j;
        }
        (4.0 / PI * e, 4.0 / PI * de)
    } else {
        (0.0, 0.0)
    }
}

/// `E[sq(U) sq(V)]` for `(U, V)` jointly Gaussian with means `m` and covariance
/// `[[c[0], c[1]], [c[1], c[2]]]` (a checkerboard's parity, [`square_wave_expectation`]'s wave
/// on each axis); `axes` are the axes' own means `E[sq(U)]`, `E[sq(V)]`, which the caller has.
///
/// Uncorrelated spreads give the product of the two axes' expectations. A correlated footprint
/// is a turned ellipse, which the product blurs as the box around it: a thin footprint along a
/// diagonal meets checks of one colour only. Up to `|ρ| = 0.6`, Mehler's expansion
/// (`checker_mehler`); beyond, with principal spreads `a ≥ b` (cells):
/// - the double Fourier series `(16/π²) Σ_{j,k odd} E[sin(πjU) sin(πkV)]/(jk)`, each term a
///   cosine times the Gaussian's characteristic function, summed over the band of `(j, k)`
///   where that damping exceeds 1e-9 (`checker_fourier`, about `1.7/(ab)` terms);
/// - when that band would hold more than 400 terms (footprints both small and very thin), the
///   ellipse as 32 lines along its major axis across ±6σ of its width (midpoint rule), each
///   integrated exactly (`checker_line`). The mean of a line is only piecewise smooth across
///   (it kinks where the line passes a grid corner), hence the plain midpoint rule; lines
///   crossing more than [`CHECKER_MAX_CROSSINGS`] grid lines fall back to the product.
pub fn checker_expectation(m: [f64; 2], c: [f64; 3], axes: [f64; 2]) -> f64 {
    let (su, sv) = (c[0].max(0.0).sqrt(), c[2].max(0.0).sqrt());
    let product = || axes[0] * axes[1];
    if su == 0.0 || sv == 0.0 {
        return product();
    }
    // An axis whose spread stays inside one cell (no grid line within ±10σ, where the normal's
    // tail is below 1e-23) keeps its wave constant, ±1, over the whole ellipse: the expectation
    // is that sign times the other axis's own, whatever the correlation. Thin ellipses seen at
    // grazing angles often lie so; the series and line integrals below cost 1–7 µs.
    let clear = |m: f64, s: f64| (m - 10.0 * s).floor() == (m + 10.0 * s).floor();
    if clear(m[0], su) || clear(m[1], sv) {
        return product();
    }
    let rho = c[1] / (su * sv);
    if rho.abs() <= 0.6 {
        return checker_mehler(m, [su, sv], rho, axes);
    }
    // Principal axes: λ₁ ≥ λ₂, e₁ the major direction.
    let half_tr = 0.5 * (c[0] + c[2]);
    let disc = (0.25 * (c[0] - c[2]).powi(2) + c[1] * c[1]).sqrt();
    let (l1, l2) = (half_tr + disc, (half_tr - disc).max(0.0));
    let (a, b) = (l1.sqrt(), l2.sqrt());
    if a * b >= 1.7 / 400.0 {
        return checker_fourier(m, c, (c[0] * c[2] - c[1] * c[1]).max(a * a * b * b));
    }
    let e1 = if c[0] >= c[2] { (l1 - c[2], c[1]) } else { (c[1], l1 - c[0]) };
    let n = (e1.0 * e1.0 + e1.1 * e1.1).sqrt();
    let e1 = (e1.0 / n, e1.1 / n);
    const LINES: usize = 32;
    let h = 12.0 / LINES as f64;
    let mut e = 0.0;
    for i in 0..LINES {
        let z = -6.0 + h * (i as f64 + 0.5);
        let Some(l) = checker_line([m[0] - b * z * e1.1, m[1] + b * z * e1.0], [a * e1.0, a * e1.1]) else {
            return product();
        };
        e += pdf(z) * h * l;
    }
    e
}

/// Mehler's expansion of a bivariate normal with correlation ρ:
/// `E[f(U) g(V)] = Σₙ ρⁿ/n! · σᵤⁿ E[f⁽ⁿ⁾(U)] · σᵥⁿ E[g⁽ⁿ⁾(V)]`, with `E[f⁽ⁿ⁾(U)] = dⁿE[f(U)]/dmⁿ`
/// ([`square_wave_derivatives`]), summed until two successive terms fall below 1e-9 (at most
/// `20.7/(−ln|ρ|) + 4` terms: 45 at `|ρ| = 0.6`, 13 at 0.1).
fn checker_mehler(m: [f64; 2], s: [f64; 2], rho: f64, axes: [f64; 2]) -> f64 {
    const N: usize = 64;
    // Terms shrink about like |ρ|ⁿ: enough of them for 1e-9, plus a margin.
    let n = if rho == 0.0 { 0 } else { ((20.7 / -rho.abs().ln()).ceil() as usize + 4).min(N) };
    let (mut du, mut dv) = ([0.0; N], [0.0; N]);
    square_wave_derivatives(m[0], s[0], &mut du[..n]);
    square_wave_derivatives(m[1], s[1], &mut dv[..n]);
    let mut e = axes[0] * axes[1];
    let mut coef = 1.0;
    let mut small = 0;
    for k in 1..=n {
        coef *= rho / k as f64;
        let t = coef * du[k - 1] * dv[k - 1];
        e += t;
        small = if t.abs() < 1e-9 { small + 1 } else { 0 };
        if small == 2 {
            break;
        }
    }
    e
}

/// `out[n − 1] = sⁿ dⁿ/dmⁿ E[sq(X)]` for `n = 1..=out.len()`, `X ~ N(m, s²)`, `s > 0` (the mean
/// itself is [`square_wave_expectation`]'s): below `s = 0.4` a sum over the wave's jumps
/// `Δₖ = 2(−1)ᵏ` at integers `k` of `Δₖ Heₙ₋₁(zₖ) φ(zₖ)`, `zₖ = (k − m)/s` (probabilists'
/// Hermite polynomials); above, the derivatives of its damped Fourier series.
pub fn square_wave_derivatives(m: f64, s: f64, out: &mut [f64]) {
    out.fill(0.0);
    let n_max = out.len();
    if s < 0.4 {
        let reach = 10.0 + (2.0 * n_max as f64).sqrt();
        let k0 = (m - reach * s).ceil();
        for k in cells(k0, (m + reach * s).floor()) {
            let z = (k - m) / s;
            let jump = if (k as i64).rem_euclid(2) == 0 { 2.0 } else { -2.0 };
            let w = jump * pdf(z);
            let (mut h0, mut h1) = (1.0, z); // Heₙ₋₁, Heₙ for n = 1
            for (i, o) in out.iter_mut().enumerate() {
                *o += w * h0;
                let h2 = z * h1 - (i + 1) as f64 * h0;
                (h0, h1) = (h1, h2);
            }
        }
    } else {
        let mut j = 1.0;
        loop {
            let w = PI * j;
            let damp = exp_damping(-0.5 * w * w * s * s);
            if damp < 1e-14 {
                break;
            }
            let a = 4.0 / (PI * j) * damp;
            // sin(wm + nπ/2) cycles through sin, cos, −sin, −cos.
            let (sn, cs) = (w * m).sin_cos();
            let cycle = [sn, cs, -sn, -cs];
            let mut ws = 1.0;
            for (i, o) in out.iter_mut().enumerate() {
                ws *= w * s;
                *o += a * ws * cycle[(i + 1) % 4];
            }
            j += 2.0;
        }
    }
}

/// The double Fourier series of [`checker_expectation`] over the band where the Gaussian's
/// damping `exp(−π² q/2)`, `q = j²c₀ ∓ 2jk c₁ + k²c₂`, exceeds 1e-9: for each odd `j`, the odd
/// `k` within the quadratic's interval.
///
/// Along one run of `k` (step 2) the cosine's phase grows by a constant and `q` by a step that
/// grows linearly, so each term follows from the one before by multiplications alone: the
/// phase by a rotation, the damping by a ratio that itself changes by a constant factor. Only
/// a run's first term calls `cos`, `sin` and `exp` (a band holds up to a few hundred terms;
/// each had cost a cosine and an exponential). Over a run of `n` terms the recurrences drift
/// by about `n` roundings, relative to each term, far below the band's 1e-9 cut.
fn checker_fourier(m: [f64; 2], c: [f64; 3], det: f64) -> f64 {
    // Damping ratio's own factor per step: exp(−π²/2 · 8c₂).
    let ratio_step = exp_damping(-4.0 * PI * PI * c[2]);
    fourier_band(c, det, |jf, sign, mut k, hi| {
        // E[cos(π(jU ± kV))] = cos(phase) · damp.
        let kf = k as f64;
        let q = jf * jf * c[0] + 2.0 * sign * jf * kf * c[1] + kf * kf * c[2];
        let mut damp = exp_damping(-0.5 * PI * PI * q);
        // q(k + 2) − q(k) = 4(±j c₁ + c₂(k + 1)).
        let mut ratio = exp_damping(-2.0 * PI * PI * (sign * jf * c[1] + c[2] * (kf + 1.0)));
        let (mut sn, mut cs) = (PI * (jf * m[0] + sign * kf * m[1])).sin_cos();
        let (dsn, dcs) = (2.0 * PI * sign * m[1]).sin_cos();
        let mut run = 0.0;
        while (k as f64) <= hi {
            run += cs * damp / k as f64;
            (sn, cs) = (sn * dcs + cs * dsn, cs * dcs - sn * dsn);
            damp *= ratio;
            ratio *= ratio_step;
            k += 2;
        }
        run
    })
}

/// [`checker_fourier`]'s band: for each odd `j`, the runs of odd `k ≥ 1` (one per sign of the
/// `±` in `q`) within the quadratic's interval, `run(j, ±1, first k, last k bound)` giving a
/// run's sum of `E[cos(π(jU ± kV))]/k`; the series is `(16/π²) Σ ∓ ½ run / j` (the sine product
/// is `(cos(−) − cos(+))/2`).
fn fourier_band(c: [f64; 3], det: f64, mut run: impl FnMut(f64, f64, i64, f64) -> f64) -> f64 {
    const Q: f64 = 2.0 * 20.723 / (PI * PI); // ln 1e9 = 20.723
    let j_max = ((Q * c[2] / det).sqrt() as i64).min(4095);
    let mut e = 0.0;
    let mut j = 1;
    while j <= j_max {
        let jf = j as f64;
        // q(k) = c₂ (k ∓ j c₁/c₂)² + j² det/c₂ < Q.
        let room = Q - jf * jf * det / c[2];
        if room > 0.0 {
            let hw = (room / c[2]).sqrt();
            for sign in [-1.0, 1.0] {
                let centre = -sign * jf * c[1] / c[2];
                let lo = (centre - hw).max(1.0);
                let mut k = lo.ceil() as i64;
                if k % 2 == 0 {
                    k += 1;
                }
                let hi = centre + hw;
                if (k as f64) <= hi {
                    e -= sign * 0.5 * run(jf, sign, k, hi) / jf;
                }
            }
        }
        j += 2;
    }
    16.0 / (PI * PI) * e
}

/// Most grid lines a line of [`checker_expectation`] may cross before it gives up.
pub const CHECKER_MAX_CROSSINGS: usize = 96;

/// `E[sq(o + d t)_u · sq(o + d t)_v]` for `t ~ N(0, 1)`: the parity is constant between the
/// crossings of integer u or v within |t| ≤ 6 and flips at each. `None` past
/// [`CHECKER_MAX_CROSSINGS`].
fn checker_line(o: [f64; 2], d: [f64; 2]) -> Option<f64> {
    const T: f64 = 6.0;
    // Crossings of each axis, as an increasing arithmetic progression in t: (first, step, count).
    let axis = |o: f64, d: f64| -> (f64, f64, f64) {
        if d.abs() < 1e-12 {
            return (0.0, 0.0, 0.0);
        }
        // floor(o + d t) changes at every integer k in (min, max] of o + d t over [−T, T]
        // (a decreasing coordinate leaves k just after reaching it).
        let (lo, hi) = ((o - d.abs() * T).floor() + 1.0, (o + d.abs() * T).floor());
        if hi < lo {
            return (0.0, 0.0, 0.0);
        }
        // Counted in f64: far from the origin the count can exceed any integer type.
        let count = hi - lo + 1.0;
        // t = (k − o)/d, increasing in k for d > 0, decreasing for d < 0.
        let first = if d > 0.0 { (lo - o) / d } else { (hi - o) / d };
        (first, 1.0 / d.abs(), count)
    };
    let (u0, ustep, un) = axis(o[0], d[0]);
    let (v0, vstep, vn) = axis(o[1], d[1]);
    if !(un + vn <= CHECKER_MAX_CROSSINGS as f64) {
        return None;
    }
    let (un, vn) = (un as usize, vn as usize);
    let parity = |x: f64| if (x.floor() as i64).rem_euclid(2) == 0 { 1.0 } else { -1.0 };
    // The parity at t = −T, before every crossing counted (below −T lies under 1e-9 of the mass).
    let mut sign = parity(o[0] - d[0] * T) * parity(o[1] - d[1] * T);
    let (mut i, mut j) = (0usize, 0usize);
    // Each crossing's normal tail is computed once and serves the segments on both sides of it
    // (as `mass` would, each in its own tail): `(t, Φ(t) for t ≤ 0, else Q(t))`.
    let tail = |t: f64| (t, if t > 0.0 { cdf(-t) } else { cdf(t) });
    let segment = |(a, ca): (f64, f64), (b, cb): (f64, f64)| {
        if a > 0.0 {
            ca - cb
        } else if b <= 0.0 {
            cb - ca
        } else {
            (1.0 - cb) - ca
        }
    };
    let mut prev = (f64::NEG_INFINITY, 0.0);
    let mut e = 0.0;
    while i < un || j < vn {
        let tu = if i < un { u0 + ustep * i as f64 } else { f64::INFINITY };
        let tv = if j < vn { v0 + vstep * j as f64 } else { f64::INFINITY };
        let t = if tu <= tv {
            i += 1;
            tu
        } else {
            j += 1;
            tv
        };
        let here = tail(t);
        e += sign * segment(prev, here);
        sign = -sign;
        prev = here;
    }
    Some(e + sign * segment(prev, (f64::INFINITY, 0.0)))
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

    /// The C library's erfc agrees with the `libm` crate's (an independent implementation) to a
    /// few ulp from deep in the lower tail to underflow, and both ends give its limits.
    #[test]
    fn erfc_agrees_with_libm() {
        let mut worst = 0u64;
        for i in 0..=600_000 {
            let x = -6.0 + 34.0 * i as f64 / 600_000.0;
            let (a, b) = (erfc(x), libm::erfc(x));
            if b == 0.0 || b < f64::MIN_POSITIVE {
                assert!(a.abs() <= f64::MIN_POSITIVE, "erfc({x}) = {a}, libm {b}");
                continue;
            }
            worst = worst.max(a.to_bits().abs_diff(b.to_bits()));
        }
        assert!(worst <= 8, "{worst} ulp");
        assert_eq!(erfc(f64::INFINITY), 0.0);
        assert_eq!(erfc(f64::NEG_INFINITY), 2.0);
        assert!(erfc(f64::NAN).is_nan());
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

    /// Mean, variance and `dE/dm` of piecewise polynomials against the midpoint rule (the slope
    /// against a central difference of brute-force means): contiguous pieces that share their
    /// boundaries, gaps, constants, lines and cubics, footprints inside, across and far beyond
    /// the pieces (where a boundary's tail moments are zero and `pdf` would underflow).
    #[test]
    fn piecewise_moments_match_quadrature() {
        let mut rng = crate::testing::uniform(0x9e37);
        let mut worst = [0.0f64; 3];
        for case in 0..400 {
            let n = 1 + (rng() * 4.0) as usize;
            let mut pieces = Vec::new();
            let mut x = -2.0 + 2.0 * rng();
            for k in 0..n {
                let w = 0.05 + 1.5 * rng();
                // Every third piece leaves a gap before the next.
                let lo = if k > 0 && case % 3 == 0 { x + 0.3 * rng() } else { x };
                let deg = (rng() * 4.0) as usize;
                let c: Vec<f64> = (0..=deg).map(|_| 2.0 * rng() - 1.0).collect();
                let lo = if k == 0 && case % 5 == 0 { f64::NEG_INFINITY } else { lo };
                let hi = if k + 1 == n && case % 7 == 0 { f64::INFINITY } else { x.max(lo) + w };
                pieces.push(Piece { lo, hi, p: poly(&c) });
                x = hi;
            }
            let m = -3.0 + 6.0 * rng();
            let s = [1e-3, 0.05, 0.3, 1.0, 4.0][case % 5] * (0.5 + rng());
            let (mean, var, dmean) = piecewise_moments(&pieces, m, s);
            // E[g(f(X))] by the midpoint rule on each piece's part of m ± 12s (f is smooth
            // there), 20000 nodes each (its own error is below 5e-8 here).
            let brute_at = |m: f64, g: &dyn Fn(&Poly, f64) -> f64| -> f64 {
                pieces
                    .iter()
                    .map(|pc| {
                        let (lo, hi) = (pc.lo.max(m - 12.0 * s), pc.hi.min(m + 12.0 * s));
                        if lo >= hi {
                            return 0.0;
                        }
                        let h = (hi - lo) / 20000.0;
                        (0..20000)
                            .map(|i| {
                                let x = lo + (i as f64 + 0.5) * h;
                                g(&pc.p, x) * pdf((x - m) / s) / s * h
                            })
                            .sum::<f64>()
                    })
                    .sum()
            };
            let bm = brute_at(m, &|p, x| poly_eval(p, x));
            let bv = brute_at(m, &|p, x| poly_eval(p, x).powi(2)) - bm * bm;
            // The slope the function promises: E[f′(X)] (jumps are the callers' to add).
            let bd = brute_at(m, &|p, x| poly_eval(&poly_deriv(p), x));
            // Relative to the size of what each is computed from.
            let err = [
                (mean - bm).abs() / (1.0 + bm.abs()),
                (var - bv).abs() / (1.0 + bv + bm * bm),
                (dmean - bd).abs() / (1.0 + bd.abs()),
            ];
            for (w, e) in worst.iter_mut().zip(err) {
                *w = w.max(e);
            }
            assert!(
                err.iter().all(|&e| e < 2e-7),
                "case {case}: mean {mean} vs {bm}, var {var} vs {bv}, slope {dmean} vs {bd} ({pieces:?}, m {m}, s {s})"
            );
        }
        // A continuous function's slope is the mean's derivative: smoothstep against a central
        // difference of brute-force means.
        let ss = [
            Piece { lo: 0.2, hi: 0.7, p: poly_shift_scale(&poly(&[0.0, 0.0, 3.0, -2.0]), -0.4, 2.0) },
            Piece { lo: 0.7, hi: f64::INFINITY, p: poly(&[1.0]) },
        ];
        let f = |x: f64| ss.iter().filter(|pc| pc.lo <= x && x < pc.hi).map(|pc| poly_eval(&pc.p, x)).sum::<f64>();
        for &(m, s) in &[(0.3, 0.05), (0.69, 0.2), (-0.5, 0.4), (1.5, 0.6)] {
            let (_, _, d) = piecewise_moments(&ss, m, s);
            let h = 1e-3 * s;
            let fd = (brute(f, m + h, s) - brute(f, m - h, s)) / (2.0 * h);
            assert!((d - fd).abs() < 1e-3 * (1.0 + fd.abs()), "smoothstep slope at m {m} s {s}: {d} vs {fd}");
        }
        eprintln!("worst relative errors: mean {:.1e}, variance {:.1e}, slope {:.1e}", worst[0], worst[1], worst[2]);
        // A footprint far from every piece sees nothing, and finds it without underflow.
        let pc = [Piece { lo: 0.0, hi: 1.0, p: poly(&[1.0]) }];
        assert_eq!(piecewise_moments(&pc, 1e6, 1.0), (0.0, 0.0, 0.0));
        assert_eq!(pdf(38.62), 0.0);
        assert!(pdf(38.5) > 0.0);
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

    /// The checkerboard's parity over turned, thin and wide ellipses against brute force:
    /// 2²⁰ points of a shifted R2 low-discrepancy sequence through Box–Muller, mapped onto each
    /// ellipse (long σ `a`, short `b`, angle θ). Independent of `checker_expectation`'s
    /// Fourier sums and crossing lists.
    #[test]
    fn checker_expectation_matches_brute_force() {
        let sq = |x: f64| if (x.floor() as i64).rem_euclid(2) == 0 { 1.0 } else { -1.0 };
        let mut worst: f64 = 0.0;
        let mut cases = 0;
        for &(a, b) in &[
            (0.6, 0.03),
            (2.0, 0.05),
            (0.6, 0.2),
            (3.0, 0.3),
            (0.2, 0.01),
            (1.0, 0.12),
            (0.4, 0.35),
            (1.0, 0.8),
            (0.05, 0.002),
        ] {
            for &th in &[0.0, 0.1, 0.3, 0.785, 1.2, 2.5] {
                for &(mu, mv) in &[(0.37, 0.11), (-3.2, 5.05)] {
                    let (c, s) = (f64::cos(th), f64::sin(th));
                    let cov = [a * a * c * c + b * b * s * s, (a * a - b * b) * c * s, a * a * s * s + b * b * c * c];
                    let axes =
                        [square_wave_expectation(mu, cov[0].sqrt()).0, square_wave_expectation(mv, cov[2].sqrt()).0];
                    let got = checker_expectation([mu, mv], cov, axes);
                    let n = 1u32 << 20;
                    let mut sum = 0.0;
                    for i in 0..n {
                        let u1 = (0.31 + 0.754_877_666_246_692_7 * (i as f64 + 0.5)).fract().max(1e-300);
                        let u2 = (0.77 + 0.569_840_290_998_053_3 * (i as f64 + 0.5)).fract();
                        let r = (-2.0 * u1.ln()).sqrt();
                        let (z1, z2) = (r * (2.0 * PI * u2).cos(), r * (2.0 * PI * u2).sin());
                        let (u, v) = (mu + a * z1 * c - b * z2 * s, mv + a * z1 * s + b * z2 * c);
                        sum += sq(u) * sq(v);
                    }
                    let want = sum / n as f64;
                    worst = worst.max((got - want).abs());
                    cases += 1;
                    assert!((got - want).abs() < 1e-3, "a {a} b {b} θ {th} m ({mu}, {mv}): {got} vs {want}");
                }
            }
        }
        println!("{cases} ellipses: largest difference {worst:.1e}");
    }

    #[test]
    fn checker_fourier_recurrences_match_terms_computed_alone() {
        // Turned ellipses over the Fourier band's whole range of sizes and aspect ratios, at
        // centres up to 3000 cells out (where the phase's first cosine has large arguments).
        let mut worst: f64 = 0.0;
        let mut cases = 0;
        for i in 0..20000 {
            let x = i as f64;
            let a = 0.05 + (x * 0.618_034).fract() * 0.6;
            let b = a * (0.05 + (x * 0.414_214).fract() * 0.5);
            if a * b < 1.7 / 400.0 {
                continue;
            }
            let th = (x * 0.754_878).fract() * PI;
            let (c, s) = (th.cos(), th.sin());
            let cov = [a * a * c * c + b * b * s * s, (a * a - b * b) * c * s, a * a * s * s + b * b * c * c];
            let det = (cov[0] * cov[2] - cov[1] * cov[1]).max(a * a * b * b);
            let m = [(x * 0.3).fract() * 50.0 - 20.0, (x * 0.17).fract() * 3000.0];
            worst = worst.max((checker_fourier(m, cov, det) - checker_fourier_direct(m, cov, det)).abs());
            cases += 1;
        }
        assert!(cases > 5000, "{cases}");
        assert!(worst < 1e-12, "{worst:e}");
    }

    /// [`checker_fourier`] term by term, each with its own cosine and exponential (what it
    /// computed before its recurrences).
    fn checker_fourier_direct(m: [f64; 2], c: [f64; 3], det: f64) -> f64 {
        fourier_band(c, det, |jf, sign, mut k, hi| {
            let mut run = 0.0;
            while (k as f64) <= hi {
                let kf = k as f64;
                let q = jf * jf * c[0] + 2.0 * sign * jf * kf * c[1] + kf * kf * c[2];
                run += (PI * (jf * m[0] + sign * kf * m[1])).cos() * exp_damping(-0.5 * PI * PI * q) / kf;
                k += 2;
            }
            run
        })
    }
}
