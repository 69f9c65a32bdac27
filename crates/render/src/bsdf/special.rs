//! Special functions needed by the Beckmann distribution: `erf`, `erfc` and `erfinv`, in `f64`.
//!
//! Accuracy target is single precision (the renderer's `f32`): `erfc` has a relative error below
//! about 1.2e-7 everywhere, so the tails of the Beckmann slope distribution and the exact Smith
//! masking term stay accurate. `erfinv` is polished by Newton steps against [`erf`], so the two
//! are inverses of each other to that accuracy, which is what a CDF inversion needs.

use std::f64::consts::FRAC_2_SQRT_PI;

/// 1/√π.
pub const FRAC_1_SQRT_PI: f64 = 0.564_189_583_547_756_3;

/// Complementary error function `erfc(x) = 1 − erf(x)`.
///
/// For x ≥ 0 it is `t · exp(−x² + P(t))` with `t = 1/(1 + x/2)` and a degree-9 polynomial `P`
/// fitted by Chebyshev economisation (the `erfcc` approximation of Press et al., *Numerical
/// Recipes*, §6.2), whose relative error is below 1.2e-7 for every x; negative x use
/// `erfc(−x) = 2 − erfc(x)`.
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    const C: [f64; 10] = [
        -1.265_512_23,
        1.000_023_68,
        0.374_091_96,
        0.096_784_18,
        -0.186_288_06,
        0.278_868_07,
        -1.135_203_98,
        1.488_515_87,
        -0.822_152_23,
        0.170_872_77,
    ];
    // Horner from the highest coefficient down.
    let poly = C.iter().rev().fold(0.0, |acc, &c| acc * t + c);
    let r = t * (poly - z * z).exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Error function. Near zero a Taylor series keeps the relative accuracy that `1 − erfc` loses.
pub fn erf(x: f64) -> f64 {
    if x.abs() < 0.5 {
        // erf(x) = 2/√π Σ (−1)ⁿ x^(2n+1) / (n! (2n+1)); seven terms reach 1e-10 at |x| = 0.5.
        let x2 = x * x;
        let mut term = x; // (−1)ⁿ x^(2n+1) / n!
        let mut sum = x;
        for n in 1..8 {
            term *= -x2 / n as f64;
            sum += term / (2 * n + 1) as f64;
        }
        FRAC_2_SQRT_PI * sum
    } else {
        1.0 - erfc(x)
    }
}

/// Giles' single-precision approximation of `erfinv` (M. Giles, "Approximating the erfinv
/// function", GPU Computing Gems, 2011): a polynomial in `w = −ln(1 − v²)`, relative error
/// about 1e-7 for |v| ≤ 1 − 1e-7 (its fitted range), growing beyond.
fn erfinv_giles(v: f64) -> f64 {
    let w = -((1.0 - v) * (1.0 + v)).ln();
    let p = if w < 5.0 {
        let w = w - 2.5;
        const A: [f64; 9] = [
            2.810_226_36e-08,
            3.432_739_39e-07,
            -3.523_387_7e-06,
            -4.391_506_54e-06,
            0.000_218_580_87,
            -0.001_253_725_03,
            -0.004_177_681_64,
            0.246_640_727,
            1.501_409_41,
        ];
        A.iter().skip(1).fold(A[0], |acc, &c| acc * w + c)
    } else {
        let w = w.sqrt() - 3.0;
        const B: [f64; 9] = [
            -0.000_200_214_257,
            0.000_100_950_558,
            0.001_349_343_22,
            -0.003_673_428_44,
            0.005_739_507_73,
            -0.007_622_461_3,
            0.009_438_870_47,
            1.001_674_06,
            2.832_976_82,
        ];
        B.iter().skip(1).fold(B[0], |acc, &c| acc * w + c)
    };
    p * v
}

/// Fast inverse error function for samplers: [`erfinv_giles`] inside its fitted range (about
/// 1e-7 relative accuracy, enough for `f32` results), the polished [`erfinv`] outside.
pub fn erfinv_fast(v: f64) -> f64 {
    if v.abs() <= 1.0 - 1e-7 {
        erfinv_giles(v)
    } else {
        erfinv(v)
    }
}

/// Inverse error function on (−1, 1); ±∞ at ±1, NaN-free. Accurate to about 1e-7 relative in
/// `1 − |v|` for |v| ≤ 1 − 1e-12 (the samplers stay well inside that).
///
/// Starts from [`erfinv_giles`] and applies Newton steps on [`erf`] (with the residual taken
/// through [`erfc`] so that it does not cancel near ±1).
pub fn erfinv(v: f64) -> f64 {
    if v.is_nan() {
        return 0.0;
    }
    if v >= 1.0 {
        return f64::INFINITY;
    }
    if v <= -1.0 {
        return f64::NEG_INFINITY;
    }
    let mut x = erfinv_giles(v);
    // Newton steps on erf(x) = v. The residual is computed the way `erf` is (series near 0)
    // and without cancellation near ±1, so that `erf(erfinv(v))` reproduces v. One step
    // suffices inside Giles' single-precision range; further out (|v| > 1 − 1e-7) a few more.
    for _ in 0..4 {
        let residual = if x.abs() < 0.5 {
            erf(x) - v
        } else if x > 0.0 {
            (1.0 - v) - erfc(x)
        } else {
            erfc(-x) - (1.0 + v)
        };
        let slope = FRAC_2_SQRT_PI * (-x * x).exp();
        if slope.is_nan() || slope <= 0.0 || !residual.is_finite() {
            break;
        }
        let step = residual / slope;
        x -= step;
        if step.abs() <= 1e-13 * x.abs() {
            break;
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference erf by its Taylor series (|x| < 3) or the continued fraction of erfc
    /// (Lentz's method), summed in f64 to full precision: independent of the approximation.
    fn erfc_reference(x: f64) -> f64 {
        if x < 0.0 {
            return 2.0 - erfc_reference(-x);
        }
        if x < 3.0 {
            let x2 = x * x;
            let mut term = x;
            let mut sum = x;
            let mut n = 1.0;
            while term.abs() > 1e-18 * sum.abs() {
                term *= -x2 / n;
                sum += term / (2.0 * n + 1.0);
                n += 1.0;
            }
            return 1.0 - FRAC_2_SQRT_PI * sum;
        }
        // erfc(x) = e^{-x²}/√π · 1/(x + (1/2)/(x + 1/(x + (3/2)/(x + 2/(x + ...)))))
        let tiny = 1e-300;
        let mut f = x;
        let mut c = x;
        let mut d = 0.0;
        for k in 1..200 {
            let a = k as f64 * 0.5;
            d = x + a * d;
            d = if d.abs() < tiny { tiny } else { d };
            c = x + a / c;
            c = if c.abs() < tiny { tiny } else { c };
            d = 1.0 / d;
            let delta = c * d;
            f *= delta;
            if (delta - 1.0).abs() < 1e-16 {
                break;
            }
        }
        (-x * x).exp() * FRAC_1_SQRT_PI / f
    }

    #[test]
    fn bsdf_special_erfc_matches_reference() {
        for i in -600..=900 {
            let x = i as f64 * 0.01;
            let r = erfc_reference(x);
            let e = erfc(x);
            assert!((e - r).abs() <= 1.5e-7 * r, "erfc({x}) = {e}, reference {r}");
            let ef = erf(x);
            assert!((ef - (1.0 - r)).abs() <= 2e-7 * (1.0 - r).abs().max(1e-3), "erf({x}) = {ef}");
        }
        // Known values.
        assert!((erf(1.0) - 0.842_700_792_949_714_9).abs() < 2e-8);
        assert!((erfc(2.0) - 0.004_677_734_981_047_266).abs() < 1e-9);
    }

    #[test]
    fn bsdf_special_erfinv_inverts_erf() {
        for i in -999..=999 {
            let v = i as f64 * 1e-3;
            let x = erfinv(v);
            assert!((erf(x) - v).abs() < 1e-12, "erf(erfinv({v})) = {}", erf(x));
        }
        // Deep tails: erfinv(1 − δ) must reproduce erfc(x) = δ in relative terms.
        for &d in &[1e-3, 1e-5, 1e-7, 1e-9, 1e-12] {
            let v: f64 = 1.0 - d;
            let d = 1.0 - v; // exactly representable tail mass
            let x = erfinv(v);
            let back = erfc_reference(x);
            assert!((back - d).abs() < 3e-7 * d, "erfc(erfinv(1-{d})) = {back}");
            assert!((erfinv(-v) + x).abs() < 1e-12, "odd symmetry");
        }
        assert_eq!(erfinv(0.0), 0.0);
        // The fast variant agrees to single precision.
        for i in -9999..=9999 {
            let v = i as f64 * 1e-4;
            let (a, b) = (erfinv(v), erfinv_fast(v));
            assert!((a - b).abs() <= 5e-7 * a.abs().max(1e-3), "erfinv_fast({v}) = {b} vs {a}");
        }
        assert!(erfinv(1.0).is_infinite() && erfinv(-1.0).is_infinite());
    }
}
