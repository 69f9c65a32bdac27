//! Mitsuba's `dielectric`: a smooth interface between two dielectrics (glass, water), with
//! Fresnel-weighted specular reflection and refraction; both sides.
//!
//! | parameter                | type               | meaning                                        |
//! |--------------------------|--------------------|------------------------------------------------|
//! | `int_ior`                | float / string     | interior IOR (default `bk7`, 1.5046)           |
//! | `ext_ior`                | float / string     | exterior IOR (default `air`, 1.000277)         |
//! | `specular_reflectance`   | spectrum / texture | reflection multiplier (default 1)              |
//! | `specular_transmittance` | spectrum / texture | transmission multiplier (default 1)            |
//!
//! The exterior is the side the normal points to (`wi.z > 0`); `eta = int_ior / ext_ior`.
//! Sampling picks reflection with probability `F` and refraction with `1 − F` (Mitsuba's
//! choice), so the weights are `specular_reflectance` and `specular_transmittance · η_ti²`,
//! the latter being the radiance compression `(η_i/η_t)²` on crossing. Beyond the critical angle
//! `F = 1` (total internal reflection). Both lobes are deltas: `eval` and `pdf` are zero.
//!
//! ```xml
//! <bsdf type="dielectric">
//!     <float name="int_ior" value="1.5"/>
//!     <float name="ext_ior" value="1.0"/>
//! </bsdf>
//! ```

use super::fresnel::fresnel_dielectric;
use super::{BsdfSample, LobeKind};
use crate::math::Spectrum;
use glam::Vec3;

/// A smooth dielectric interface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dielectric {
    /// Relative IOR `η_int / η_ext`.
    pub eta: f32,
    /// Reflection multiplier.
    pub specular_reflectance: Spectrum,
    /// Transmission multiplier.
    pub specular_transmittance: Spectrum,
}

impl Dielectric {
    /// Chooses reflection when `u_lobe < F`, refraction otherwise. `None` at exactly grazing
    /// incidence.
    pub fn sample(&self, wi: Vec3, u_lobe: f32) -> Option<BsdfSample> {
        let cos_i = wi.z;
        if cos_i == 0.0 || !cos_i.is_finite() {
            return None;
        }
        let fr = fresnel_dielectric(cos_i, self.eta);
        if u_lobe < fr.r {
            Some(BsdfSample {
                wo: Vec3::new(-wi.x, -wi.y, wi.z),
                weight: self.specular_reflectance,
                pdf: fr.r,
                kind: LobeKind::Specular,
                transmitted: false,
                eta: 1.0,
                alpha: 0.0,
            })
        } else {
            let wo = Vec3::new(-fr.eta_ti * wi.x, -fr.eta_ti * wi.y, fr.cos_t);
            Some(BsdfSample {
                wo,
                weight: self.specular_transmittance * (fr.eta_ti * fr.eta_ti),
                pdf: 1.0 - fr.r,
                kind: LobeKind::Specular,
                transmitted: true,
                eta: fr.eta_it,
                alpha: 0.0,
            })
        }
    }
}
