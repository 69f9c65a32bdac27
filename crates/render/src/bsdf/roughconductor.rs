//! Mitsuba's `roughconductor`: a metal with microfacet roughness (Cook–Torrance with Smith
//! masking, Walter et al. 2007); one-sided (black from the back).
//!
//! | parameter              | type               | meaning                                          |
//! |------------------------|--------------------|--------------------------------------------------|
//! | `material`, `eta`, `k` | string / spectrum  | complex IOR as for `conductor` (default `none`)  |
//! | `specular_reflectance` | spectrum / texture | multiplier (default 1)                           |
//! | `distribution`         | string             | `beckmann` (default) or `ggx`                    |
//! | `alpha` or `alpha_u`, `alpha_v` | float     | roughness (default 0.1); RMS slope for Beckmann |
//!
//! With `h = normalize(wi + wo)`:
//! `f · cos θ_o = F(wi·h) D(h) G1(wi, h) G1(wo, h) / (4 cos θ_i)`.
//! Sampling draws a visible normal `m` from `wi` and reflects about it, so
//! `pdf = D_wi(m) / (4 wo·m) = D(m) G1(wi, m) / (4 cos θ_i)` and the weight is
//! `F(wi·m) G1(wo, m) · specular_reflectance`.
//!
//! ```xml
//! <bsdf type="roughconductor">
//!     <string name="material" value="Cu"/>
//!     <string name="distribution" value="ggx"/>
//!     <float name="alpha_u" value="0.05"/>
//!     <float name="alpha_v" value="0.3"/>
//! </bsdf>
//! ```

use super::fresnel::fresnel_conductor;
use super::microfacet::Microfacet;
use super::{lobe_alpha, positive_finite, BsdfSample, LobeKind};
use crate::math::Spectrum;
use glam::{Vec2, Vec3};

/// A rough conductor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughConductor {
    /// Microfacet distribution and roughness.
    pub distribution: Microfacet,
    /// Real part of the relative complex IOR, per channel (0 with `k = 1` for a perfect mirror).
    pub eta: Spectrum,
    /// Imaginary part, per channel.
    pub k: Spectrum,
    /// Multiplier of the Fresnel reflectance.
    pub specular_reflectance: Spectrum,
}

impl RoughConductor {
    /// Visible-normal sample; `None` from below or when the reflected direction goes under the
    /// surface.
    pub fn sample(&self, wi: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let md = &self.distribution;
        let m = md.sample_visible(wi, u);
        let wi_m = wi.dot(m);
        if m.z <= 0.0 || wi_m <= 0.0 {
            return None;
        }
        let wo = (2.0 * wi_m * m - wi).normalize_or_zero();
        if wo.z <= 0.0 {
            return None;
        }
        let pdf = md.pdf_visible(wi, m) / (4.0 * wi_m);
        let g1_o = md.g1(wo, m);
        if !positive_finite(pdf) || g1_o <= 0.0 {
            return None;
        }
        let f = fresnel_conductor(wi_m, self.eta, self.k);
        Some(BsdfSample {
            wo,
            weight: self.specular_reflectance * f * g1_o,
            pdf,
            kind: LobeKind::Glossy,
            transmitted: false,
            eta: 1.0,
            alpha: lobe_alpha(md),
        })
    }

    /// `f · cos θ_o` and the density of [`RoughConductor::sample`].
    pub fn eval_pdf(&self, wi: Vec3, wo: Vec3) -> (Spectrum, f32) {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return (Spectrum::ZERO, 0.0);
        }
        let h = wi + wo;
        let len2 = h.length_squared();
        if !(len2.is_finite() && len2 > 1e-12) {
            return (Spectrum::ZERO, 0.0);
        }
        let h = h / len2.sqrt();
        let md = &self.distribution;
        let d = md.d(h);
        let g1_i = md.g1(wi, h);
        let g1_o = md.g1(wo, h);
        if d <= 0.0 || g1_i <= 0.0 {
            return (Spectrum::ZERO, 0.0);
        }
        let common = d * g1_i / (4.0 * wi.z);
        if !common.is_finite() {
            return (Spectrum::ZERO, 0.0);
        }
        let f = fresnel_conductor(wi.dot(h), self.eta, self.k);
        (self.specular_reflectance * f * (common * g1_o), common)
    }
}
