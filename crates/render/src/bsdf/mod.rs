//! BSDFs of the Mitsuba 3 subset: `diffuse`, `conductor`, `roughconductor`, `dielectric`,
//! `roughdielectric` and the `twosided` adapter, matching Mitsuba 3's `rgb` variants.
//!
//! Two levels:
//! - [`BsdfDesc`] is the scene-level description with textured parameters, built by the scene
//!   loader; [`BsdfDesc::at`] evaluates its textures at a uv and returns a
//! - [`Bsdf`]: small, `Copy`, allocation-free, with [`Bsdf::sample`], [`Bsdf::eval`],
//!   [`Bsdf::pdf`] for the integrator.
//!
//! All directions are in the local shading frame: +z is the shading normal as the shape reports
//! it (never flipped by the caller). `wi` points toward the previous path vertex (the camera
//! side) and `wo` toward the next vertex or light; transport is of radiance (camera paths), so
//! refraction scales by `1/η²` as in Mitsuba's `TransportMode::Radiance`.
//!
//! Each model lives in its own file with its parameters and an XML example at the top:
//! [`diffuse`], [`conductor`], [`roughconductor`], [`dielectric`], [`roughdielectric`];
//! [`microfacet`] holds the distributions and [`fresnel`] the interface reflectances.

pub mod conductor;
pub mod dielectric;
pub mod diffuse;
pub mod fresnel;
pub mod microfacet;
pub mod roughconductor;
pub mod roughdielectric;
mod special;
pub mod standard_surface;
#[cfg(test)]
mod tests;

pub use conductor::Conductor;
pub use dielectric::Dielectric;
pub use diffuse::Diffuse;
pub use fresnel::{fresnel_conductor, fresnel_dielectric, fresnel_dielectric_polarized, DielectricFresnel};
pub use microfacet::{Microfacet, MicrofacetKind};
pub use roughconductor::RoughConductor;
pub use roughdielectric::RoughDielectric;

use crate::math::Spectrum;
use crate::texture::{ShadeContext, Texture};
use glam::{Vec2, Vec3};

/// Mitsuba's default interior IOR of dielectrics (`bk7`).
pub const DEFAULT_INT_IOR: f32 = 1.5046;
/// Mitsuba's default exterior IOR of dielectrics (`air`).
pub const DEFAULT_EXT_IOR: f32 = 1.000277;
/// Mitsuba's default roughness of rough BSDFs.
pub const DEFAULT_ALPHA: f32 = 0.1;
/// Mitsuba's default `diffuse` reflectance.
pub const DEFAULT_DIFFUSE_REFLECTANCE: f32 = 0.5;

/// The kind of lobe a sample came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LobeKind {
    /// Lambertian.
    Diffuse,
    /// Rough (microfacet) reflection or transmission.
    Glossy,
    /// A Dirac delta (smooth mirror or smooth refraction).
    Specular,
}

/// The result of [`Bsdf::sample`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    /// Sampled direction toward the next vertex (local frame, unit length).
    pub wo: Vec3,
    /// `f(wi, wo) |cos θ_o| / pdf`, including the `1/η²` radiance scaling on refraction.
    pub weight: Spectrum,
    /// Solid-angle density of `wo`; for delta lobes the discrete probability of the lobe.
    pub pdf: f32,
    /// Which kind of lobe produced the sample.
    pub kind: LobeKind,
    /// True when `wo` lies on the other side of the surface than `wi`.
    pub transmitted: bool,
    /// Relative IOR `η_t/η_i` of the interface crossed (1 for reflection), as Mitsuba's `bs.eta`.
    pub eta: f32,
    /// Beckmann-equivalent roughness of the sampled lobe: 1 for diffuse, 0 for delta lobes.
    pub alpha: f32,
}

/// The evaluated scattering model behind a [`Bsdf`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BsdfModel {
    /// Lambertian reflection.
    Diffuse(Diffuse),
    /// Smooth conductor (mirror with complex Fresnel).
    Conductor(Conductor),
    /// Microfacet conductor.
    RoughConductor(RoughConductor),
    /// Smooth dielectric interface.
    Dielectric(Dielectric),
    /// Microfacet dielectric interface.
    RoughDielectric(RoughDielectric),
    /// Autodesk Standard Surface (MaterialX `standard_surface`) subset.
    StandardSurface(standard_surface::StandardSurface),
}

/// A BSDF with its textures already evaluated at a hit point (cheap, `Copy`, no allocation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bsdf {
    /// The scattering model.
    pub model: BsdfModel,
    /// Mitsuba's `twosided`: the back side behaves like the front (directions mirrored in z).
    pub two_sided: bool,
}

/// True for a finite, strictly positive value (false for NaN).
#[inline]
pub(crate) fn positive_finite(x: f32) -> bool {
    x.is_finite() && x > 0.0
}

/// Mirrors a local direction through the tangent plane.
#[inline]
fn flip_z(v: Vec3) -> Vec3 {
    Vec3::new(v.x, v.y, -v.z)
}

impl Bsdf {
    /// A one-sided BSDF of the given model.
    pub fn new(model: BsdfModel) -> Self {
        Bsdf { model, two_sided: false }
    }

    /// The same model, also used on the back side.
    pub fn two_sided(self) -> Self {
        Bsdf { two_sided: true, ..self }
    }

    /// For a two-sided BSDF seen from the back, mirrors the directions to the front.
    #[inline]
    fn side(&self, wi: Vec3) -> bool {
        self.two_sided && wi.z < 0.0
    }

    /// Samples `wo` given `wi`, with `u_lobe` choosing between lobes and `u` driving the
    /// direction. `None` when nothing can be sampled (e.g. the back of a one-sided BSDF, or a
    /// microfacet sample that leaves through the wrong side).
    pub fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if self.side(wi) {
            let mut s = self.model.sample(flip_z(wi), u_lobe, u)?;
            s.wo = flip_z(s.wo);
            return Some(s);
        }
        self.model.sample(wi, u_lobe, u)
    }

    /// `f(wi, wo) |cos θ_o|`; zero for delta lobes.
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Spectrum {
        if self.side(wi) {
            return self.model.eval(flip_z(wi), flip_z(wo));
        }
        self.model.eval(wi, wo)
    }

    /// Solid-angle density with which [`Bsdf::sample`] produces `wo`; zero for delta lobes.
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        if self.side(wi) {
            return self.model.pdf(flip_z(wi), flip_z(wo));
        }
        self.model.pdf(wi, wo)
    }

    /// [`Bsdf::eval`] and [`Bsdf::pdf`] together (shares the half-vector work).
    pub fn eval_pdf(&self, wi: Vec3, wo: Vec3) -> (Spectrum, f32) {
        if self.side(wi) {
            return self.model.eval_pdf(flip_z(wi), flip_z(wo));
        }
        self.model.eval_pdf(wi, wo)
    }

    /// True if the BSDF has a non-delta lobe (the integrator then samples emitters).
    pub fn has_smooth(&self) -> bool {
        matches!(
            self.model,
            BsdfModel::Diffuse(_)
                | BsdfModel::RoughConductor(_)
                | BsdfModel::RoughDielectric(_)
                | BsdfModel::StandardSurface(_)
        )
    }
}

impl BsdfModel {
    fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        match self {
            BsdfModel::Diffuse(b) => b.sample(wi, u),
            BsdfModel::Conductor(b) => b.sample(wi),
            BsdfModel::RoughConductor(b) => b.sample(wi, u),
            BsdfModel::Dielectric(b) => b.sample(wi, u_lobe),
            BsdfModel::RoughDielectric(b) => b.sample(wi, u_lobe, u),
            BsdfModel::StandardSurface(b) => b.sample(wi, u_lobe, u),
        }
    }

    fn eval_pdf(&self, wi: Vec3, wo: Vec3) -> (Spectrum, f32) {
        match self {
            BsdfModel::Diffuse(b) => (b.eval(wi, wo), b.pdf(wi, wo)),
            BsdfModel::Conductor(_) | BsdfModel::Dielectric(_) => (Spectrum::ZERO, 0.0),
            BsdfModel::RoughConductor(b) => b.eval_pdf(wi, wo),
            BsdfModel::RoughDielectric(b) => b.eval_pdf(wi, wo),
            BsdfModel::StandardSurface(b) => b.eval_pdf(wi, wo),
        }
    }

    fn eval(&self, wi: Vec3, wo: Vec3) -> Spectrum {
        match self {
            BsdfModel::Diffuse(b) => b.eval(wi, wo),
            _ => self.eval_pdf(wi, wo).0,
        }
    }

    fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        match self {
            BsdfModel::Diffuse(b) => b.pdf(wi, wo),
            _ => self.eval_pdf(wi, wo).1,
        }
    }
}

/// Scene-level BSDF description with textured parameters, filled by the scene loader.
#[derive(Clone, Debug)]
#[allow(clippy::large_enum_variant)] // one per material, never per sample
pub enum BsdfDesc {
    /// Mitsuba `diffuse`.
    Diffuse {
        /// Albedo (default 0.5).
        reflectance: Texture,
    },
    /// Mitsuba `conductor` (smooth). `eta`/`k` are relative to the exterior IOR (Mitsuba's
    /// `ext_eta`, default 1); `material="none"` is `eta = 0, k = 1` (see [`conductor_preset`]).
    Conductor {
        /// Real part of the complex IOR, per channel.
        eta: Spectrum,
        /// Imaginary part (absorption), per channel.
        k: Spectrum,
        /// Multiplier of the Fresnel reflectance (default 1).
        specular_reflectance: Texture,
    },
    /// Mitsuba `roughconductor`.
    RoughConductor {
        /// Real part of the complex IOR, per channel.
        eta: Spectrum,
        /// Imaginary part (absorption), per channel.
        k: Spectrum,
        /// Multiplier of the Fresnel reflectance (default 1).
        specular_reflectance: Texture,
        /// Normal distribution (default Beckmann).
        distribution: MicrofacetKind,
        /// Roughness along the tangent (default 0.1; `alpha` sets both); a float texture.
        alpha_u: Texture,
        /// Roughness along the bitangent.
        alpha_v: Texture,
    },
    /// Mitsuba `dielectric` (smooth).
    Dielectric {
        /// Relative IOR `int_ior / ext_ior` (default 1.5046 / 1.000277).
        eta: f32,
        /// Multiplier of reflection (default 1).
        specular_reflectance: Texture,
        /// Multiplier of transmission (default 1).
        specular_transmittance: Texture,
    },
    /// Mitsuba `roughdielectric`.
    RoughDielectric {
        /// Relative IOR `int_ior / ext_ior`.
        eta: f32,
        /// Multiplier of reflection (default 1).
        specular_reflectance: Texture,
        /// Multiplier of transmission (default 1).
        specular_transmittance: Texture,
        /// Normal distribution (default Beckmann).
        distribution: MicrofacetKind,
        /// Roughness along the tangent (default 0.1); a float texture.
        alpha_u: Texture,
        /// Roughness along the bitangent.
        alpha_v: Texture,
    },
    /// Autodesk Standard Surface / MaterialX `standard_surface` (see [`standard_surface`] for
    /// the subset rendered and the defaults). Scalar inputs are float textures.
    StandardSurface {
        /// `base` (default 0.8).
        base: Texture,
        /// `base_color` (default 1).
        base_color: Texture,
        /// `metalness` (default 0).
        metalness: Texture,
        /// `specular` (default 1).
        specular: Texture,
        /// `specular_color` (default 1).
        specular_color: Texture,
        /// `specular_roughness` (default 0.2); GGX `α = roughness²`.
        specular_roughness: Texture,
        /// `specular_IOR` (default 1.5).
        specular_ior: Texture,
        /// `transmission` (default 0).
        transmission: Texture,
        /// `transmission_color` (default 1).
        transmission_color: Texture,
    },
    /// Mitsuba `twosided`: the nested BSDF on both faces.
    TwoSided(Box<BsdfDesc>),
    /// Partial opacity (Mitsuba's `mask`, MaterialX's `opacity`): the surface is the nested BSDF
    /// with weight `o` and a straight pass-through with weight `1 − o`. [`BsdfDesc::at`] gives
    /// the nested BSDF; the integrator makes the pass-through (see [`crate::integrator`]).
    Mask {
        /// The opacity `o`, clamped to [0, 1] per channel.
        opacity: Texture,
        /// Read `opacity` as one value (its luminance for a colour texture), as Mitsuba's
        /// `mask` does; otherwise per channel (MaterialX's colour `opacity`).
        scalar: bool,
        /// What the opaque part is.
        bsdf: Box<BsdfDesc>,
    },
}

impl Default for BsdfDesc {
    /// Mitsuba's default material: `diffuse` with reflectance 0.5.
    fn default() -> Self {
        BsdfDesc::Diffuse { reflectance: Texture::Constant(Spectrum::splat(DEFAULT_DIFFUSE_REFLECTANCE)) }
    }
}

impl BsdfDesc {
    /// Evaluates the textures at the shading point (no allocation).
    #[inline]
    pub fn at(&self, ctx: &ShadeContext) -> Bsdf {
        let model = match self {
            BsdfDesc::TwoSided(inner) => return inner.at(ctx).two_sided(),
            BsdfDesc::Mask { bsdf, .. } => return bsdf.at(ctx),
            BsdfDesc::Diffuse { reflectance } => BsdfModel::Diffuse(Diffuse { reflectance: reflectance.eval(ctx) }),
            BsdfDesc::Conductor { eta, k, specular_reflectance } => BsdfModel::Conductor(Conductor {
                eta: *eta,
                k: *k,
                specular_reflectance: specular_reflectance.eval(ctx),
            }),
            BsdfDesc::RoughConductor { eta, k, specular_reflectance, distribution, alpha_u, alpha_v } => {
                BsdfModel::RoughConductor(RoughConductor {
                    distribution: Microfacet::new(*distribution, alpha_u.eval_float(ctx), alpha_v.eval_float(ctx)),
                    eta: *eta,
                    k: *k,
                    specular_reflectance: specular_reflectance.eval(ctx),
                })
            }
            BsdfDesc::Dielectric { eta, specular_reflectance, specular_transmittance } => {
                BsdfModel::Dielectric(Dielectric {
                    eta: *eta,
                    specular_reflectance: specular_reflectance.eval(ctx),
                    specular_transmittance: specular_transmittance.eval(ctx),
                })
            }
            BsdfDesc::RoughDielectric {
                eta,
                specular_reflectance,
                specular_transmittance,
                distribution,
                alpha_u,
                alpha_v,
            } => BsdfModel::RoughDielectric(RoughDielectric {
                distribution: Microfacet::new(*distribution, alpha_u.eval_float(ctx), alpha_v.eval_float(ctx)),
                eta: *eta,
                specular_reflectance: specular_reflectance.eval(ctx),
                specular_transmittance: specular_transmittance.eval(ctx),
            }),
            BsdfDesc::StandardSurface {
                base,
                base_color,
                metalness,
                specular,
                specular_color,
                specular_roughness,
                specular_ior,
                transmission,
                transmission_color,
            } => BsdfModel::StandardSurface(standard_surface::StandardSurface::new(
                &standard_surface::StandardSurfaceParams {
                    base: base.eval_float(ctx),
                    base_color: base_color.eval(ctx),
                    metalness: metalness.eval_float(ctx),
                    specular: specular.eval_float(ctx),
                    specular_color: specular_color.eval(ctx),
                    specular_roughness: specular_roughness.eval_float(ctx),
                    specular_ior: specular_ior.eval_float(ctx),
                    transmission: transmission.eval_float(ctx),
                    transmission_color: transmission_color.eval(ctx),
                },
            )),
        };
        Bsdf::new(model)
    }

    /// True if the evaluated BSDF will have a non-delta lobe (see [`Bsdf::has_smooth`]).
    pub fn has_smooth(&self) -> bool {
        match self {
            BsdfDesc::TwoSided(inner) | BsdfDesc::Mask { bsdf: inner, .. } => inner.has_smooth(),
            BsdfDesc::Diffuse { .. }
            | BsdfDesc::RoughConductor { .. }
            | BsdfDesc::RoughDielectric { .. }
            | BsdfDesc::StandardSurface { .. } => true,
            BsdfDesc::Conductor { .. } | BsdfDesc::Dielectric { .. } => false,
        }
    }

    /// True if any of its textures varies over the surface, i.e. reads the hit's uv (a graph
    /// output counts as varying). Without one, and without footprints, a hit's uv and its
    /// derivatives are never read ([`crate::geometry::interaction_with`]).
    pub fn reads_uv(&self) -> bool {
        let varies = |t: &Texture| !matches!(t, Texture::Constant(_));
        match self {
            BsdfDesc::TwoSided(inner) => inner.reads_uv(),
            BsdfDesc::Mask { opacity, bsdf, .. } => varies(opacity) || bsdf.reads_uv(),
            BsdfDesc::Diffuse { reflectance } => varies(reflectance),
            BsdfDesc::Conductor { specular_reflectance, .. } => varies(specular_reflectance),
            BsdfDesc::RoughConductor { specular_reflectance, alpha_u, alpha_v, .. } => {
                [specular_reflectance, alpha_u, alpha_v].into_iter().any(varies)
            }
            BsdfDesc::Dielectric { specular_reflectance, specular_transmittance, .. } => {
                varies(specular_reflectance) || varies(specular_transmittance)
            }
            BsdfDesc::RoughDielectric { specular_reflectance, specular_transmittance, alpha_u, alpha_v, .. } => {
                [specular_reflectance, specular_transmittance, alpha_u, alpha_v].into_iter().any(varies)
            }
            BsdfDesc::StandardSurface {
                base,
                base_color,
                metalness,
                specular,
                specular_color,
                specular_roughness,
                specular_ior,
                transmission,
                transmission_color,
            } => [
                base,
                base_color,
                metalness,
                specular,
                specular_color,
                specular_roughness,
                specular_ior,
                transmission,
                transmission_color,
            ]
            .into_iter()
            .any(varies),
        }
    }

    /// True if the surface is (possibly) partly transparent: a [`BsdfDesc::Mask`], at any depth.
    pub fn is_masked(&self) -> bool {
        match self {
            BsdfDesc::Mask { .. } => true,
            BsdfDesc::TwoSided(inner) => inner.is_masked(),
            _ => false,
        }
    }

    /// The opacity at the shading point, per channel in [0, 1] (NaN → 0): the product of the
    /// nested masks' opacities, 1 without a mask.
    pub fn opacity(&self, ctx: &ShadeContext) -> Spectrum {
        match self {
            BsdfDesc::Mask { opacity, scalar, bsdf } => {
                let o = if *scalar { Spectrum::splat(opacity.eval_float(ctx)) } else { opacity.eval(ctx) };
                // `max` first maps NaN to 0.
                o.max(Spectrum::ZERO).min(Spectrum::ONE) * bsdf.opacity(ctx)
            }
            BsdfDesc::TwoSided(inner) => inner.opacity(ctx),
            _ => Spectrum::ONE,
        }
    }
}

/// Converts a roughness of distribution `kind` to the Beckmann roughness used by the footprint
/// model (slope standard deviation `σ = α/√2` per axis).
///
/// GGX has infinite slope variance, so variances cannot be matched. The footprint is a measure
/// of spread, so we match the **median slope magnitude**: for GGX `P(|m| < r) = r²/(α² + r²)`
/// has median `α`, for Beckmann `1 − exp(−r²/α_b²)` has median `α_b √(ln 2)`, hence
/// `α_b = α_ggx / √(ln 2) ≈ 1.2011 α_ggx`. The conversion itself lives in the footprint crate
/// ([`footprint::ggx_to_beckmann_alpha`]) so the whole system uses one definition.
pub fn beckmann_equivalent_alpha(kind: MicrofacetKind, alpha: f32) -> f32 {
    match kind {
        MicrofacetKind::Beckmann => alpha,
        MicrofacetKind::Ggx => footprint::ggx_to_beckmann_alpha(alpha),
    }
}

pub(crate) fn lobe_alpha(md: &Microfacet) -> f32 {
    let a = (0.5 * (md.alpha_u * md.alpha_u + md.alpha_v * md.alpha_v)).sqrt();
    beckmann_equivalent_alpha(md.kind, a)
}

/// Mitsuba's RGB conductor presets `(eta, k)` by `material` name: `"Au"`, `"Ag"`, `"Cu"`,
/// `"Al"`, and `"none"` — a perfect mirror, `eta = 0, k = 1`, for which the Fresnel reflectance
/// is exactly 1 at every angle.
pub fn conductor_preset(name: &str) -> Option<(Spectrum, Spectrum)> {
    let v = Spectrum::new;
    Some(match name {
        "none" => (Spectrum::ZERO, Spectrum::ONE),
        "Au" => (v(0.1430, 0.3753, 1.4421), v(3.9830, 2.3856, 1.6034)),
        "Ag" => (v(0.1553, 0.1167, 0.1384), v(4.8284, 3.1222, 2.1469)),
        "Cu" => (v(0.2010, 0.9238, 1.1022), v(3.9133, 2.4531, 2.1421)),
        "Al" => (v(1.6575, 0.8804, 0.5212), v(9.2238, 6.2695, 4.8370)),
        _ => return None,
    })
}

/// Mitsuba's named dielectric IORs (`int_ior="bk7"` etc.), for the loader.
pub fn dielectric_ior_preset(name: &str) -> Option<f32> {
    Some(match name {
        "vacuum" => 1.0,
        "helium" => 1.000036,
        "hydrogen" => 1.000132,
        "air" => 1.000277,
        "carbon dioxide" => 1.00045,
        "water" => 1.3330,
        "acetone" => 1.36,
        "ethanol" => 1.361,
        "carbon tetrachloride" => 1.461,
        "glycerol" => 1.4729,
        "benzene" => 1.501,
        "silicone oil" => 1.52045,
        "bromine" => 1.661,
        "water ice" => 1.31,
        "fused quartz" => 1.458,
        "pyrex" => 1.470,
        "acrylic glass" => 1.49,
        "polypropylene" => 1.49,
        "bk7" => 1.5046,
        "sodium chloride" => 1.544,
        "amber" => 1.55,
        "pet" => 1.5750,
        "diamond" => 2.419,
        _ => return None,
    })
}

#[cfg(test)]
mod mask_tests {
    use super::*;

    fn mask(o: Spectrum, scalar: bool, inner: BsdfDesc) -> BsdfDesc {
        BsdfDesc::Mask { opacity: Texture::Constant(o), scalar, bsdf: Box::new(inner) }
    }

    #[test]
    fn masks_clamp_multiply_and_leave_the_bsdf_to_the_nested_one() {
        let ctx = ShadeContext::uv(Vec2::ZERO);
        let bare = BsdfDesc::default();
        assert!(!bare.is_masked());
        assert_eq!(bare.opacity(&ctx), Spectrum::ONE);
        // Per channel (MaterialX), clamped to [0, 1], NaN read as 0.
        let m = mask(Spectrum::new(-0.5, f32::NAN, 2.0), false, bare.clone());
        assert!(m.is_masked());
        assert_eq!(m.opacity(&ctx), Spectrum::new(0.0, 0.0, 1.0));
        // Scalar (Mitsuba's mask): the luminance of a colour.
        let c = Spectrum::new(0.2, 0.4, 0.6);
        let s = mask(c, true, bare.clone()).opacity(&ctx);
        assert!((s - Spectrum::splat(crate::math::luminance(c))).abs().max_element() < 1e-7);
        // Nested masks multiply, also through twosided; the BSDF is the innermost one.
        let nested = BsdfDesc::TwoSided(Box::new(mask(
            Spectrum::splat(0.5),
            true,
            mask(Spectrum::new(0.2, 0.4, 1.0), false, bare.clone()),
        )));
        assert!(nested.is_masked() && nested.has_smooth());
        assert_eq!(nested.opacity(&ctx), Spectrum::new(0.1, 0.2, 0.5));
        assert_eq!(nested.at(&ctx), bare.at(&ctx).two_sided());
    }
}
