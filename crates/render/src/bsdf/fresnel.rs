//! Fresnel reflectance of smooth interfaces: dielectric–dielectric (real relative IOR) and
//! dielectric–conductor (complex IOR `η + iκ`, evaluated per RGB channel), for unpolarised light.
//!
//! Conventions follow Mitsuba 3: `cos_i` is the cosine between the incident direction and the
//! interface normal, signed; a negative cosine means the light arrives from the interior side,
//! where the relative IOR `eta = η_int / η_ext` is inverted.

use crate::math::Spectrum;

/// Result of [`fresnel_dielectric`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DielectricFresnel {
    /// Unpolarised reflectance `F` in [0, 1] (1 under total internal reflection).
    pub r: f32,
    /// Signed cosine of the refracted direction: its sign is opposite to `cos_i` (the refracted
    /// ray continues to the other side); 0 under total internal reflection.
    pub cos_t: f32,
    /// Relative IOR `η_t / η_i` of the crossing in the direction of travel.
    pub eta_it: f32,
    /// Its reciprocal `η_i / η_t`.
    pub eta_ti: f32,
}

/// Reflectances `(R_s, R_p)` of the s- and p-polarised components for a dielectric interface.
///
/// `cos_i` is signed as in [`fresnel_dielectric`]. Under total internal reflection both are 1.
pub fn fresnel_dielectric_polarized(cos_i: f32, eta: f32) -> (f32, f32) {
    let (eta_it, eta_ti) = if cos_i >= 0.0 { (eta, 1.0 / eta) } else { (1.0 / eta, eta) };
    let ci = cos_i.abs().min(1.0);
    let cos_t2 = 1.0 - (1.0 - ci * ci) * eta_ti * eta_ti;
    if cos_t2 <= 0.0 || ci == 0.0 {
        return (1.0, 1.0);
    }
    let ct = cos_t2.sqrt();
    // Amplitude ratios with η = η_t/η_i: r_s = (cos_i − η cos_t)/(cos_i + η cos_t),
    // r_p = (η cos_i − cos_t)/(η cos_i + cos_t).
    let rs = (ci - eta_it * ct) / (ci + eta_it * ct);
    let rp = (eta_it * ci - ct) / (eta_it * ci + ct);
    (rs * rs, rp * rp)
}

/// Unpolarised Fresnel reflectance of a dielectric interface with relative IOR
/// `eta = η_int / η_ext`, plus the refracted cosine and the relative IORs of the crossing
/// (Mitsuba's `fresnel()`): index-matched interfaces (`eta == 1`) reflect nothing.
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> DielectricFresnel {
    let outside = cos_i >= 0.0;
    let (eta_it, eta_ti) = if outside { (eta, 1.0 / eta) } else { (1.0 / eta, eta) };
    let ci = cos_i.abs().min(1.0);
    let cos_t2 = 1.0 - (1.0 - ci * ci) * eta_ti * eta_ti;
    let ct = cos_t2.max(0.0).sqrt();
    let r = if eta == 1.0 {
        0.0
    } else {
        let (rs, rp) = fresnel_dielectric_polarized(cos_i, eta);
        0.5 * (rs + rp)
    };
    DielectricFresnel { r, cos_t: if outside { -ct } else { ct }, eta_it, eta_ti }
}

/// Unpolarised Fresnel reflectance of a conductor with complex relative IOR `eta + i·k` per
/// channel, for `cos_i` in [0, 1] (clamped).
///
/// Uses the closed form for an absorbing medium (e.g. K. D. Möller, *Optics*, 1988): with
/// `a² + b² = √((η² − κ² − sin²θ)² + 4η²κ²)` and `a = √((a² + b² + η² − κ² − sin²θ)/2)`,
/// `R_s = (a² + b² + cos²θ − 2a cosθ)/(a² + b² + cos²θ + 2a cosθ)` and
/// `R_p = R_s (cos²θ (a² + b²) + sin⁴θ − 2a cosθ sin²θ)/(… + 2a cosθ sin²θ)`.
/// `eta = 0, k = 1` (Mitsuba's `material="none"`) gives exactly 1 at every angle.
pub fn fresnel_conductor(cos_i: f32, eta: Spectrum, k: Spectrum) -> Spectrum {
    let c = cos_i.clamp(0.0, 1.0);
    let c2 = c * c;
    let s2 = 1.0 - c2;
    let s4 = s2 * s2;
    let channel = |n: f32, kk: f32| -> f32 {
        let t = n * n - kk * kk - s2;
        let a2b2 = (t * t + 4.0 * n * n * kk * kk).max(0.0).sqrt();
        let a = (0.5 * (a2b2 + t)).max(0.0).sqrt();
        let t1 = a2b2 + c2;
        let t2 = 2.0 * a * c;
        let rs = if t1 + t2 > 0.0 { (t1 - t2) / (t1 + t2) } else { 1.0 };
        let t3 = a2b2 * c2 + s4;
        let t4 = t2 * s2;
        let rp = if t3 + t4 > 0.0 { rs * (t3 - t4) / (t3 + t4) } else { rs };
        (0.5 * (rs + rp)).clamp(0.0, 1.0)
    };
    Spectrum::new(channel(eta.x, k.x), channel(eta.y, k.y), channel(eta.z, k.z))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Minimal complex arithmetic for an independent Fresnel reference.
    #[derive(Clone, Copy, Debug)]
    struct C(f64, f64);
    impl C {
        fn add(self, o: C) -> C {
            C(self.0 + o.0, self.1 + o.1)
        }
        fn sub(self, o: C) -> C {
            C(self.0 - o.0, self.1 - o.1)
        }
        fn mul(self, o: C) -> C {
            C(self.0 * o.0 - self.1 * o.1, self.0 * o.1 + self.1 * o.0)
        }
        fn div(self, o: C) -> C {
            let d = o.0 * o.0 + o.1 * o.1;
            C((self.0 * o.0 + self.1 * o.1) / d, (self.1 * o.0 - self.0 * o.1) / d)
        }
        fn norm2(self) -> f64 {
            self.0 * self.0 + self.1 * self.1
        }
        /// Principal square root.
        fn sqrt(self) -> C {
            let r = self.norm2().sqrt();
            let re = ((r + self.0) * 0.5).max(0.0).sqrt();
            let im = ((r - self.0) * 0.5).max(0.0).sqrt().copysign(self.1);
            C(re, im)
        }
    }

    /// Fresnel equations with complex n directly: cos_t = √(1 − sin²θ/n²), r_s and r_p as
    /// amplitude ratios.
    fn reference(cos_i: f64, n: C) -> f64 {
        let ci = C(cos_i, 0.0);
        let s2 = C(1.0 - cos_i * cos_i, 0.0);
        let ct = C(1.0, 0.0).sub(s2.div(n.mul(n))).sqrt();
        let rs = ci.sub(n.mul(ct)).div(ci.add(n.mul(ct)));
        let rp = n.mul(ci).sub(ct).div(n.mul(ci).add(ct));
        0.5 * (rs.norm2() + rp.norm2())
    }

    #[test]
    fn bsdf_fresnel_conductor_normal_incidence_and_angles() {
        for (name, (eta, k)) in ["Au", "Ag", "Cu", "Al"].iter().map(|n| (n, super::super::conductor_preset(n).unwrap()))
        {
            let f = fresnel_conductor(1.0, eta, k);
            for c in 0..3 {
                let (n, kk) = (eta[c], k[c]);
                let expect = ((n - 1.0).powi(2) + kk * kk) / ((n + 1.0).powi(2) + kk * kk);
                assert!((f[c] - expect).abs() < 1e-5, "{name}[{c}]: {} vs {expect}", f[c]);
                for i in 0..=20 {
                    let cos_i = i as f32 / 20.0;
                    let got = fresnel_conductor(cos_i, eta, k)[c] as f64;
                    let want = reference(cos_i as f64, C(n as f64, kk as f64));
                    assert!((got - want).abs() < 2e-5, "{name}[{c}] cos {cos_i}: {got} vs {want}");
                }
            }
            // Grazing incidence reflects everything.
            assert!((fresnel_conductor(0.0, eta, k) - Spectrum::ONE).abs().max_element() < 1e-5);
        }
        // Mitsuba's material "none": a perfect mirror at every angle.
        let (eta, k) = super::super::conductor_preset("none").unwrap();
        for i in 0..=10 {
            let f = fresnel_conductor(i as f32 / 10.0, eta, k);
            assert!((f - Spectrum::ONE).abs().max_element() < 1e-6, "{f}");
        }
    }

    #[test]
    fn bsdf_fresnel_dielectric_properties() {
        for &eta in &[1.5f32, 1.333, 2.4, 1.1] {
            // Normal incidence, both sides.
            let f0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
            assert!((fresnel_dielectric(1.0, eta).r - f0).abs() < 1e-6);
            assert!((fresnel_dielectric(-1.0, eta).r - f0).abs() < 1e-6);
            // Brewster angle: p-polarised reflection vanishes.
            let cos_b = (1.0 / (1.0 + eta * eta)).sqrt(); // θ_B = atan(η)
            let (rs, rp) = fresnel_dielectric_polarized(cos_b, eta);
            assert!(rp < 1e-10 && rs > 1e-3, "Brewster rs {rs} rp {rp}");
            // Agreement with the complex-arithmetic reference (k = 0), from outside.
            for i in 0..=20 {
                let c = i as f32 / 20.0;
                let want = reference(c as f64, C(eta as f64, 0.0));
                assert!((fresnel_dielectric(c, eta).r as f64 - want).abs() < 1e-5, "eta {eta} cos {c}");
            }
            // Symmetry: entering at θ_i equals leaving at θ_t; Snell's law for cos_t.
            for i in 1..=20 {
                let c = i as f32 / 20.0;
                let a = fresnel_dielectric(c, eta);
                assert!(a.cos_t <= 0.0 && a.eta_it == eta && (a.eta_ti - 1.0 / eta).abs() < 1e-7);
                let sin_i = (1.0 - c * c).sqrt();
                let sin_t = (1.0 - a.cos_t * a.cos_t).sqrt();
                assert!((sin_t - sin_i / eta).abs() < 1e-5, "Snell");
                let ct = -a.cos_t;
                let b = fresnel_dielectric(-ct, eta);
                assert!((a.r - b.r).abs() < 1e-5, "F(cos_i, η) = {} vs F(−cos_t, η) = {}", a.r, b.r);
                let b2 = fresnel_dielectric(ct, 1.0 / eta);
                assert!((a.r - b2.r).abs() < 1e-5, "F(cos_i, η) vs F(cos_t, 1/η)");
                assert!((b.cos_t - c).abs() < 1e-4, "reverse refraction returns to θ_i");
            }
            // Total internal reflection beyond the critical angle from inside.
            let cos_crit = (1.0 - 1.0 / (eta * eta)).sqrt();
            let tir = fresnel_dielectric(-(cos_crit * 0.9), eta);
            assert_eq!(tir.r, 1.0);
            assert_eq!(tir.cos_t, 0.0);
            assert!(fresnel_dielectric(-(cos_crit * 1.1).min(1.0), eta).r < 1.0);
            // Grazing incidence reflects everything.
            assert_eq!(fresnel_dielectric(0.0, eta).r, 1.0);
        }
        // Index-matched interfaces do not reflect.
        assert_eq!(fresnel_dielectric(0.3, 1.0).r, 0.0);
    }
}
