//! Mitsuba's `conductor`: a smooth metal, an ideal mirror scaled by the conductor Fresnel
//! reflectance; one-sided (black from the back).
//!
//! | parameter              | type               | meaning                                          |
//! |------------------------|--------------------|--------------------------------------------------|
//! | `material`             | string             | preset `eta`/`k` (`Au`, `Ag`, `Cu`, `Al`); default `none` = 100 % mirror |
//! | `eta`, `k`             | spectrum           | real and imaginary part of the complex IOR, relative to the exterior |
//! | `specular_reflectance` | spectrum / texture | multiplier (default 1)                           |
//!
//! The only lobe is a Dirac delta: `sample` returns the mirror direction with weight
//! `specular_reflectance · F(cos θ_i)` and pdf 1; `eval` and `pdf` are zero.
//!
//! ```xml
//! <bsdf type="conductor">
//!     <string name="material" value="Au"/>
//! </bsdf>
//! ```

use super::fresnel::fresnel_conductor;
use super::{BsdfSample, LobeKind};
use crate::math::Spectrum;
use glam::Vec3;

/// A smooth conductor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conductor {
    /// Real part of the relative complex IOR, per channel (0 with `k = 1` for a perfect mirror).
    pub eta: Spectrum,
    /// Imaginary part, per channel.
    pub k: Spectrum,
    /// Multiplier of the Fresnel reflectance.
    pub specular_reflectance: Spectrum,
}

impl Conductor {
    /// The mirror direction; `None` from below.
    pub fn sample(&self, wi: Vec3) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let f = fresnel_conductor(wi.z, self.eta, self.k);
        Some(BsdfSample {
            wo: Vec3::new(-wi.x, -wi.y, wi.z),
            weight: self.specular_reflectance * f,
            pdf: 1.0,
            kind: LobeKind::Specular,
            transmitted: false,
            eta: 1.0,
            alpha: 0.0,
        })
    }
}
