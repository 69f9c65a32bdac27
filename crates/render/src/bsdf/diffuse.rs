//! Mitsuba's `diffuse`: an ideal Lambertian reflector, one-sided.
//!
//! | parameter     | type               | meaning                          |
//! |---------------|--------------------|----------------------------------|
//! | `reflectance` | spectrum / texture | albedo ρ (default 0.5)           |
//!
//! `f = ρ/π` when both `wi` and `wo` are above the surface, zero otherwise (the back is black;
//! wrap it in `twosided` for a two-sided surface). Sampling is cosine-weighted, so the sample
//! weight is exactly ρ.
//!
//! ```xml
//! <bsdf type="diffuse">
//!     <rgb name="reflectance" value="0.2, 0.25, 0.7"/>
//! </bsdf>
//! ```

use super::{BsdfSample, LobeKind};
use crate::math::Spectrum;
use crate::sampling::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Lambertian reflection with albedo `reflectance`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Diffuse {
    /// Albedo ρ.
    pub reflectance: Spectrum,
}

impl Diffuse {
    /// Cosine-weighted sample of the upper hemisphere; `None` from below.
    pub fn sample(&self, wi: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let wo = square_to_cosine_hemisphere(u);
        let pdf = cosine_hemisphere_pdf(wo);
        if pdf <= 0.0 {
            return None;
        }
        Some(BsdfSample {
            wo,
            weight: self.reflectance,
            pdf,
            kind: LobeKind::Diffuse,
            transmitted: false,
            eta: 1.0,
            alpha: 1.0,
        })
    }

    /// `ρ/π · cos θ_o` above the surface, zero otherwise.
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Spectrum {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Spectrum::ZERO;
        }
        self.reflectance * (FRAC_1_PI * wo.z.min(1.0))
    }

    /// `cos θ_o / π` above the surface, zero otherwise.
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        cosine_hemisphere_pdf(wo)
    }
}
