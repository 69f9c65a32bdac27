//! Mitsuba's `roughdielectric`: a rough interface between two dielectrics (frosted glass),
//! after Walter et al. 2007, "Microfacet Models for Refraction through Rough Surfaces"; both
//! sides.
//!
//! | parameter                | type               | meaning                                        |
//! |--------------------------|--------------------|------------------------------------------------|
//! | `int_ior`, `ext_ior`     | float / string     | as for `dielectric` (defaults 1.5046 / 1.000277) |
//! | `specular_reflectance`   | spectrum / texture | reflection multiplier (default 1)              |
//! | `specular_transmittance` | spectrum / texture | transmission multiplier (default 1)            |
//! | `distribution`           | string             | `beckmann` (default) or `ggx`                  |
//! | `alpha` or `alpha_u`, `alpha_v` | float       | roughness (default 0.1)                        |
//!
//! Let `η` be the relative IOR seen from `wi`'s side (`eta` outside, `1/eta` inside) and `m` the
//! (generalised) half vector oriented to +z: `m ∝ wi + wo` for reflection, `m ∝ wi + η wo` for
//! refraction. Then, with `G = G1(wi, m) G1(wo, m)`,
//! - reflection: `f · |cos θ_o| = F D G / (4 |cos θ_i|)`,
//! - refraction (radiance, the `1/η²` factor included):
//!   `f · |cos θ_o| = (1 − F) D G |wi·m| |wo·m| / (|cos θ_i| (wi·m + η wo·m)²)`.
//!
//! Sampling draws a visible normal from `wi` (mirrored to the upper side), picks reflection with
//! probability `F(wi·m)` and refraction otherwise, and converts the density with the Jacobian of
//! the half-vector map: `1/(4 |wo·m|)` or `η² |wo·m| / (wi·m + η wo·m)²`. The weight is
//! `G1(wo, m)`, times `η_ti²` for refraction, times the multipliers.
//!
//! ```xml
//! <bsdf type="roughdielectric">
//!     <string name="distribution" value="ggx"/>
//!     <float name="alpha" value="0.2"/>
//!     <float name="int_ior" value="1.5"/>
//!     <float name="ext_ior" value="1.0"/>
//! </bsdf>
//! ```

use super::fresnel::fresnel_dielectric;
use super::microfacet::Microfacet;
use super::{lobe_alpha, positive_finite, BsdfSample, LobeKind};
use crate::math::Spectrum;
use glam::{Vec2, Vec3};

/// A rough dielectric interface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughDielectric {
    /// Microfacet distribution and roughness.
    pub distribution: Microfacet,
    /// Relative IOR `η_int / η_ext`.
    pub eta: f32,
    /// Reflection multiplier.
    pub specular_reflectance: Spectrum,
    /// Transmission multiplier.
    pub specular_transmittance: Spectrum,
}

impl RoughDielectric {
    /// Samples reflection or refraction off a visible microfacet. `None` at grazing incidence
    /// or when the scattered direction ends on the wrong side of the macro-surface.
    pub fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let cos_i = wi.z;
        if cos_i == 0.0 || !cos_i.is_finite() {
            return None;
        }
        let md = &self.distribution;
        let wi_up = if cos_i > 0.0 { wi } else { -wi };
        let m = md.sample_visible(wi_up, u);
        let pdf_m = md.pdf_visible(wi_up, m);
        if !positive_finite(pdf_m) {
            return None;
        }
        let wi_m = wi.dot(m);
        let fr = fresnel_dielectric(wi_m, self.eta);
        let reflect = u_lobe < fr.r;
        let (wo, weight, lobe_prob, jacobian, eta) = if reflect {
            let wo = (2.0 * wi_m * m - wi).normalize_or_zero();
            let wo_m = wo.dot(m);
            (wo, self.specular_reflectance, fr.r, 1.0 / (4.0 * wo_m.abs()), 1.0)
        } else {
            // Refraction about m: wo = (η_ti (wi·m) + cos_t) m − η_ti wi, with cos_t signed.
            let wo = ((wi_m * fr.eta_ti + fr.cos_t) * m - fr.eta_ti * wi).normalize_or_zero();
            let wo_m = wo.dot(m);
            let denom = wi_m + fr.eta_it * wo_m;
            let jac = fr.eta_it * fr.eta_it * wo_m.abs() / (denom * denom);
            (wo, self.specular_transmittance * (fr.eta_ti * fr.eta_ti), 1.0 - fr.r, jac, fr.eta_it)
        };
        // The scattered direction must leave on the expected side (G1 checks the facet side).
        let transmitted = wo.z * cos_i < 0.0;
        if transmitted == reflect || wo.z == 0.0 {
            return None;
        }
        let g1_o = md.g1(wo, m);
        let pdf = pdf_m * lobe_prob * jacobian;
        if g1_o <= 0.0 || !positive_finite(pdf) {
            return None;
        }
        Some(BsdfSample {
            wo,
            weight: weight * g1_o,
            pdf,
            kind: LobeKind::Glossy,
            transmitted,
            eta,
            alpha: lobe_alpha(md),
        })
    }

    /// `f · |cos θ_o|` and the density of [`RoughDielectric::sample`].
    pub fn eval_pdf(&self, wi: Vec3, wo: Vec3) -> (Spectrum, f32) {
        const ZERO: (Spectrum, f32) = (Spectrum::ZERO, 0.0);
        let (cos_i, cos_o) = (wi.z, wo.z);
        if cos_i == 0.0 || cos_o == 0.0 || !(cos_i * cos_o).is_finite() {
            return ZERO;
        }
        let reflect = cos_i * cos_o > 0.0;
        let eta = if cos_i > 0.0 { self.eta } else { 1.0 / self.eta };
        let Some((m, wi_m, wo_m)) = super::microfacet::half_vector(wi, wo, eta) else { return ZERO };
        let md = &self.distribution;
        let d = md.d(m);
        if d <= 0.0 {
            return ZERO;
        }
        let g1_i = md.g1(wi, m);
        let g = g1_i * md.g1(wo, m);
        let f = fresnel_dielectric(wi_m, self.eta).r;
        // Visible-normal density from the upper-side copy of wi (Λ does not depend on the side).
        let pdf_m = d * g1_i * wi_m.abs() / cos_i.abs();
        let (value, pdf) = if reflect {
            let value = self.specular_reflectance * (f * d * g / (4.0 * cos_i.abs()));
            (value, pdf_m * f / (4.0 * wo_m.abs()))
        } else {
            let denom = wi_m + eta * wo_m;
            let denom2 = denom * denom;
            // Radiance scaling 1/η² cancels the η² of the Jacobian.
            let t = (1.0 - f) * d * g * (wi_m * wo_m).abs() / (cos_i.abs() * denom2);
            let value = self.specular_transmittance * t;
            (value, pdf_m * (1.0 - f) * eta * eta * wo_m.abs() / denom2)
        };
        if !pdf.is_finite() || !value.is_finite() {
            return ZERO;
        }
        (value, pdf.max(0.0))
    }
}
