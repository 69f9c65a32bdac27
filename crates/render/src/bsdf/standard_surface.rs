//! Autodesk Standard Surface (MaterialX `standard_surface`), the subset tessera renders: a
//! metal/dielectric mix of GGX microfacet lobes over a Lambertian base, with rough transmission.
//!
//! | input (MaterialX)     | type   | default     | meaning here                                           |
//! |-----------------------|--------|-------------|--------------------------------------------------------|
//! | `base`                | float  | 0.8         | multiplier of `base_color`                             |
//! | `base_color`          | color3 | (1, 1, 1)   | diffuse albedo; metal reflectivity at normal incidence |
//! | `metalness`           | float  | 0           | mix weight of the metal lobe                           |
//! | `specular`            | float  | 1           | weight of the dielectric specular layer; metal edge    |
//! | `specular_color`      | color3 | (1, 1, 1)   | tint of dielectric reflection; metal edge tint         |
//! | `specular_roughness`  | float  | 0.2         | GGX roughness `r`, `α = r²` (clamped to `α ≥ 1e-4`)   |
//! | `specular_IOR`        | float  | 1.5         | IOR `η` of the dielectric interface, clamped to [¼, 4] |
//! | `specular_anisotropy` | float  | 0           | **ignored** (isotropic GGX)                            |
//! | `transmission`        | float  | 0           | weight of rough refraction versus the diffuse base     |
//! | `transmission_color`  | color3 | (1, 1, 1)   | tint of the refracted light                            |
//! | `coat`, `sheen`, `subsurface`, `thin_film_*`, `emission` | | | **ignored**                      |
//! | `opacity`, `normal`   |        |             | handled by the renderer, not by this BSDF              |
//!
//! The defaults are those of `standard_surface` 1.0.0 (`base` 0.8, `base_color` 1); version 1.0.1,
//! the default nodedef in MaterialX 1.39, swaps them to `base` 1, `base_color` 0.8 — the product
//! is the same.
//! Weights and colours are clamped to [0, 1] (NaN → 0) so that energy is conserved.
//!
//! ```xml
//! <materialx version="1.38">
//!   <standard_surface name="SR_red_plastic" type="surfaceshader">
//!     <input name="base" type="float" value="1.0"/>
//!     <input name="base_color" type="color3" value="0.8, 0.1, 0.1"/>
//!     <input name="metalness" type="float" value="0.0"/>
//!     <input name="specular" type="float" value="1.0"/>
//!     <input name="specular_roughness" type="float" value="0.3"/>
//!     <input name="specular_IOR" type="float" value="1.5"/>
//!     <input name="transmission" type="float" value="0.0"/>
//!   </standard_surface>
//!   <surfacematerial name="M_red_plastic" type="material">
//!     <input name="surfaceshader" type="surfaceshader" nodename="SR_red_plastic"/>
//!   </surfacematerial>
//! </materialx>
//! ```
//!
//! # The model
//!
//! With `m` = metalness, `s` = specular, `t` = transmission, `ρ = base·base_color`, GGX with
//! `α = specular_roughness²` and Smith's uncorrelated masking `G = G1(wi) G1(wo)` for all lobes:
//!
//! ```text
//! f = m · f_metal  +  (1 − m) · [ s·specular_color·f_spec  +  t·transmission_color·f_trans
//!                                 + (1 − t) · f_diffuse ]
//! ```
//!
//! - **metal** `f_metal = F_c(wi·h) D G / (4 cos_i cos_o)`, where `F_c` is the exact conductor
//!   Fresnel ([`fresnel_conductor`]) of the complex IOR `n + ik` obtained, as MaterialX's
//!   `artistic_ior` node does, from Gulbrandsen's "Artist Friendly Metallic Fresnel" (JCGT 2014)
//!   with reflectivity `r = clamp(base·base_color, 0, 0.99)` and edge colour
//!   `g = clamp(specular·specular_color, 0, 1)`: `n = lerp(n_max, n_min, g)` with
//!   `n_min = (1 − r)/(1 + r)`, `n_max = (1 + √r)/(1 − √r)`, and
//!   `k = √max(0, ((n + 1)² r − (n − 1)²)/(1 − r))` ([`artistic_ior`]). So `F_c(1) = r` exactly
//!   and `g` steers the curve toward grazing. (This is MaterialX's choice, not a Schlick curve.)
//! - **dielectric specular** `f_spec = F(wi·h, η) D G / (4 cos_i cos_o)` with the exact
//!   unpolarised dielectric Fresnel `F` ([`fresnel_dielectric`]).
//! - **transmission** `f_trans = (1 − s F(wi·m, η)) D G |wi·m| |wo·m| / (cos_i cos_o (wi·m + η wo·m)²)`
//!   (radiance transport, `1/η²` included), `m` the generalised half vector — Walter et al.'s
//!   rough-dielectric refraction in which the specular layer leaves `1 − s·F` of each
//!   microfacet's light; zero under total internal reflection. With `s = 1` and white tints,
//!   reflection + transmission is exactly [`super::RoughDielectric`] (GGX).
//! - **diffuse** under the specular layer, attenuated by the energy the layer leaves, by albedo
//!   scaling in Kelemen & Szirmay-Kalos's symmetric form:
//!   `f_diffuse = ρ/π · (1 − s E(cos_i)) (1 − s E(cos_o)) / (1 − s E_avg)`,
//!   where `E(μ)` is the directional albedo of the **untinted** dielectric reflection lobe
//!   (`F D G / (4 cos_i)` integrated over `wo`) and `E_avg = 2∫ E(μ) μ dμ`. Its directional
//!   albedo is exactly `ρ (1 − s E(cos_i))` — MaterialX's layer throughput — so reflection plus
//!   diffuse does not exceed 1 beyond the table's error, and unlike a `(1 − F(cos_i))` factor
//!   it is reciprocal. (`1 − F` is not reciprocal, is too dark for rough surfaces, where
//!   `E ≪ F` off normal incidence, and at low roughness lets the sum exceed 1 slightly, since
//!   there `E` is up to ~2 % above `F` near normal incidence.)
//!   `E` comes from a 32 × 21 × 41 table over (√cos θ, √roughness, a function of
//!   (η − 1)/(η + 1)), computed by quadrature once and embedded in the binary
//!   (`albedo_table.bin`, which `regenerate_albedo_table` rewrites), read trilinearly; its error is ≤ 2.4e-3 for η > 1 and up to
//!   ~2e-2 for η < 1 (where `E` has an edge at the critical angle). `E_avg` is integrated from
//!   the same interpolant, so the normalisation is exact.
//!
//! One-sided like `roughconductor` when `t = 0` (black from below). With `t > 0`, from below
//! (inside the object) only the dielectric reflection and the transmission act, with relative IOR
//! `1/η`, as in `roughdielectric`; the metal and diffuse parts are opaque and not seen from inside.
//!
//! # Sampling
//!
//! Two strategies, chosen with probabilities proportional to estimated weights at `wi`:
//! cosine-weighted diffuse (weight `(1 − m)(1 − t) lum(ρ) (1 − s E(cos_i))`) and the microfacet
//! interface (weight `m lum(F_c(cos_i)) + (1 − m)[s lum(specular_color) F(cos_i) +
//! t lum(transmission_color)(1 − s F(cos_i))]`). The microfacet strategy draws a GGX visible
//! normal `m` and then reflects or refracts with probability proportional to the luminances of
//! the two branches' facet weights at `m`. The returned pdf is the one-sample mixture density
//! `p_d pdf_d(wo) + p_mf pdf_mf(wo)`, which [`StandardSurface::eval_pdf`] reproduces, and the
//! weight is `f |cos θ_o| / pdf`.

use super::fresnel::{fresnel_conductor, fresnel_dielectric, DielectricFresnel};
use super::microfacet::{Microfacet, MicrofacetKind};
use super::{lobe_alpha, positive_finite, BsdfSample, LobeKind};
use crate::math::{luminance, Spectrum};
use crate::sampling::square_to_cosine_hemisphere;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;
use std::sync::OnceLock;

/// Smallest and largest accepted `specular_IOR` (the range of the albedo table).
pub const MIN_IOR: f32 = 0.25;
/// See [`MIN_IOR`].
pub const MAX_IOR: f32 = 4.0;

/// The `standard_surface` inputs tessera uses, as plain values (textures already evaluated).
/// Field names are MaterialX's (`specular_ior` is `specular_IOR`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StandardSurfaceParams {
    /// Multiplier of `base_color`.
    pub base: f32,
    /// Diffuse albedo and metal reflectivity.
    pub base_color: Spectrum,
    /// Metal weight.
    pub metalness: f32,
    /// Dielectric specular weight; metal edge-tint multiplier.
    pub specular: f32,
    /// Dielectric specular tint; metal edge tint.
    pub specular_color: Spectrum,
    /// GGX roughness; `α = specular_roughness²`.
    pub specular_roughness: f32,
    /// Index of refraction of the dielectric (relative to the outside).
    pub specular_ior: f32,
    /// Transmission weight (versus the diffuse base).
    pub transmission: f32,
    /// Transmission tint.
    pub transmission_color: Spectrum,
}

impl StandardSurfaceParams {
    /// MaterialX `standard_surface` 1.0.0 defaults.
    pub const DEFAULT: StandardSurfaceParams = StandardSurfaceParams {
        base: 0.8,
        base_color: Spectrum::ONE,
        metalness: 0.0,
        specular: 1.0,
        specular_color: Spectrum::ONE,
        specular_roughness: 0.2,
        specular_ior: 1.5,
        transmission: 0.0,
        transmission_color: Spectrum::ONE,
    };
}

impl Default for StandardSurfaceParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The evaluated `standard_surface` BSDF: `Copy`, no allocation. Build it with
/// [`StandardSurface::new`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StandardSurface {
    /// Inputs after clamping.
    params: StandardSurfaceParams,
    /// GGX with `α = specular_roughness²`.
    distribution: Microfacet,
    /// Metal complex IOR from [`artistic_ior`].
    metal_eta: Spectrum,
    metal_k: Spectrum,
    /// Where the albedo table is read for this roughness and IOR.
    albedo: AlbedoLookup,
}

/// Clamps to [0, 1], NaN → 0.
#[inline]
fn unit(x: f32) -> f32 {
    if x >= 0.0 {
        x.min(1.0)
    } else {
        0.0
    }
}

#[inline]
fn unit3(c: Spectrum) -> Spectrum {
    Spectrum::new(unit(c.x), unit(c.y), unit(c.z))
}

/// Gulbrandsen's artist-friendly metallic Fresnel (JCGT 3(4), 2014), as MaterialX's
/// `artistic_ior`: the complex IOR `(n, k)` whose normal-incidence reflectance is `reflectivity`
/// (clamped to [0, 0.99]) and whose curve toward grazing follows `edge_color` (clamped to [0, 1]).
pub fn artistic_ior(reflectivity: Spectrum, edge_color: Spectrum) -> (Spectrum, Spectrum) {
    let channel = |r: f32, g: f32| {
        let r = if r >= 0.0 { r.min(0.99) } else { 0.0 };
        let g = unit(g);
        let rs = r.sqrt();
        let n_min = (1.0 - r) / (1.0 + r);
        let n_max = (1.0 + rs) / (1.0 - rs);
        let n = n_max + (n_min - n_max) * g;
        let k2 = ((n + 1.0) * (n + 1.0) * r - (n - 1.0) * (n - 1.0)) / (1.0 - r);
        (n, k2.max(0.0).sqrt())
    };
    let (a, b, c) = (
        channel(reflectivity.x, edge_color.x),
        channel(reflectivity.y, edge_color.y),
        channel(reflectivity.z, edge_color.z),
    );
    (Spectrum::new(a.0, b.0, c.0), Spectrum::new(a.1, b.1, c.1))
}

/// What sampling and evaluation need about `wi`.
#[derive(Clone, Copy)]
struct Incident {
    /// `wi.z > 0`.
    outside: bool,
    /// `s · E(cos θ_i)` (0 inside).
    s_e_i: f32,
    /// Probability of the diffuse strategy.
    p_diffuse: f32,
}

impl StandardSurface {
    /// Clamps the inputs, converts the metal colours to a complex IOR and locates the albedo
    /// table (built on first use, once per process).
    pub fn new(p: &StandardSurfaceParams) -> Self {
        let params = StandardSurfaceParams {
            base: unit(p.base),
            base_color: unit3(p.base_color),
            metalness: unit(p.metalness),
            specular: unit(p.specular),
            specular_color: unit3(p.specular_color),
            specular_roughness: unit(p.specular_roughness),
            specular_ior: if p.specular_ior.is_finite() { p.specular_ior.clamp(MIN_IOR, MAX_IOR) } else { 1.5 },
            transmission: unit(p.transmission),
            transmission_color: unit3(p.transmission_color),
        };
        let r = params.specular_roughness;
        let distribution = Microfacet::new(MicrofacetKind::Ggx, r * r, r * r);
        let (metal_eta, metal_k) =
            artistic_ior(params.base * params.base_color, params.specular * params.specular_color);
        let albedo = AlbedoLookup::new(distribution.alpha_u.sqrt(), params.specular_ior);
        StandardSurface { params, distribution, metal_eta, metal_k, albedo }
    }

    /// The (clamped) inputs.
    pub fn params(&self) -> &StandardSurfaceParams {
        &self.params
    }

    /// The GGX distribution shared by all microfacet lobes.
    pub fn distribution(&self) -> &Microfacet {
        &self.distribution
    }

    /// The metal's complex IOR `(n, k)`.
    pub fn metal_ior(&self) -> (Spectrum, Spectrum) {
        (self.metal_eta, self.metal_k)
    }

    /// Directional albedo `E(μ)` of the untinted dielectric reflection lobe (table lookup).
    pub fn specular_albedo(&self, cos_theta: f32) -> f32 {
        self.albedo.e(cos_theta)
    }

    /// `E_avg = 2∫ E(μ) μ dμ` of the same interpolant.
    pub fn specular_albedo_average(&self) -> f32 {
        self.albedo.avg
    }

    /// Lobe selection at `wi`; `None` where the BSDF is black for every `wo`.
    fn incident(&self, wi: Vec3) -> Option<Incident> {
        let p = &self.params;
        let cos_i = wi.z;
        if !cos_i.is_finite() || cos_i == 0.0 {
            return None;
        }
        if cos_i < 0.0 {
            if p.transmission <= 0.0 || p.metalness >= 1.0 {
                return None;
            }
            return Some(Incident { outside: false, s_e_i: 0.0, p_diffuse: 0.0 });
        }
        let s_e_i = p.specular * self.albedo.e(cos_i);
        let dielectric = 1.0 - p.metalness;
        let w_d = dielectric * (1.0 - p.transmission) * luminance(p.base * p.base_color) * (1.0 - s_e_i);
        let f = fresnel_dielectric(cos_i, p.specular_ior).r;
        let w_mf = p.metalness * luminance(fresnel_conductor(cos_i, self.metal_eta, self.metal_k))
            + dielectric
                * (p.specular * luminance(p.specular_color) * f
                    + p.transmission * luminance(p.transmission_color) * (1.0 - p.specular * f).max(1e-4));
        let total = w_d + w_mf;
        let p_diffuse = if total > 0.0 && total.is_finite() { (w_d / total).clamp(0.0, 1.0) } else { 0.0 };
        Some(Incident { outside: true, s_e_i, p_diffuse })
    }

    /// Reflection and transmission weights of a microfacet with `c = wi·m` (signed like `wi.z`),
    /// without the `D G` geometry.
    #[inline]
    fn facet_weights(&self, inc: &Incident, c: f32, fr: &DielectricFresnel) -> (Spectrum, Spectrum) {
        let p = &self.params;
        let dielectric = 1.0 - p.metalness;
        let mut refl = (dielectric * p.specular * fr.r) * p.specular_color;
        if inc.outside && p.metalness > 0.0 {
            refl += p.metalness * fresnel_conductor(c, self.metal_eta, self.metal_k);
        }
        let trans = if fr.cos_t == 0.0 || p.transmission <= 0.0 {
            Spectrum::ZERO // total internal reflection: nothing refracts
        } else {
            (dielectric * p.transmission * (1.0 - p.specular * fr.r)) * p.transmission_color
        };
        (refl, trans)
    }

    /// Probability of reflecting off a facet with the given weights.
    #[inline]
    fn reflect_prob(refl: Spectrum, trans: Spectrum) -> f32 {
        let (r, t) = (luminance(refl), luminance(trans));
        if r + t > 0.0 {
            r / (r + t)
        } else {
            1.0
        }
    }

    /// Diffuse `f · cos θ_o` (`wi` outside).
    #[inline]
    fn diffuse_value(&self, inc: &Incident, wo: Vec3) -> Spectrum {
        let p = &self.params;
        if !inc.outside || wo.z <= 0.0 || p.transmission >= 1.0 || p.metalness >= 1.0 {
            return Spectrum::ZERO;
        }
        let s = p.specular;
        let s_e_o = s * self.albedo.e(wo.z);
        let norm = (1.0 - s * self.albedo.avg).max(1e-6);
        let att = (1.0 - inc.s_e_i) * (1.0 - s_e_o) / norm;
        let k = (1.0 - p.metalness) * (1.0 - p.transmission) * p.base;
        (k * att * FRAC_1_PI * wo.z.min(1.0)) * p.base_color
    }

    /// Microfacet `f · |cos θ_o|` and the density of the microfacet strategy (not multiplied by
    /// its selection probability).
    fn microfacet_eval_pdf(&self, inc: &Incident, wi: Vec3, wo: Vec3) -> (Spectrum, f32) {
        const ZERO: (Spectrum, f32) = (Spectrum::ZERO, 0.0);
        let (cos_i, cos_o) = (wi.z, wo.z);
        if cos_o == 0.0 || !cos_o.is_finite() {
            return ZERO;
        }
        let reflect = cos_i * cos_o > 0.0;
        let eta = self.params.specular_ior;
        let eta_rel = if inc.outside { eta } else { 1.0 / eta };
        let Some((m, wi_m, wo_m)) = super::microfacet::half_vector(wi, wo, eta_rel) else { return ZERO };
        let md = &self.distribution;
        let d = md.d(m);
        if d <= 0.0 {
            return ZERO;
        }
        let g1_i = md.g1(wi, m);
        let g1_o = md.g1(wo, m);
        let fr = fresnel_dielectric(wi_m, eta);
        let (refl, trans) = self.facet_weights(inc, wi_m, &fr);
        let p_r = Self::reflect_prob(refl, trans);
        // Visible-normal density from the upper-side copy of wi.
        let pdf_m = d * g1_i * wi_m.abs() / cos_i.abs();
        let (value, pdf) = if reflect {
            (refl * (d * g1_i * g1_o / (4.0 * cos_i.abs())), pdf_m * p_r / (4.0 * wo_m.abs()))
        } else {
            let denom = wi_m + eta_rel * wo_m;
            let denom2 = denom * denom;
            let t = d * g1_i * g1_o * (wi_m * wo_m).abs() / (cos_i.abs() * denom2);
            (trans * t, pdf_m * (1.0 - p_r) * eta_rel * eta_rel * wo_m.abs() / denom2)
        };
        if !pdf.is_finite() || !value.is_finite() {
            return ZERO;
        }
        (value, pdf.max(0.0))
    }

    /// `f · |cos θ_o|` and the density of [`StandardSurface::sample`].
    pub fn eval_pdf(&self, wi: Vec3, wo: Vec3) -> (Spectrum, f32) {
        let Some(inc) = self.incident(wi) else { return (Spectrum::ZERO, 0.0) };
        if !wo.z.is_finite() || wo.z == 0.0 {
            return (Spectrum::ZERO, 0.0);
        }
        let (mf_value, mf_pdf) = self.microfacet_eval_pdf(&inc, wi, wo);
        let mut value = mf_value;
        let mut pdf = (1.0 - inc.p_diffuse) * mf_pdf;
        if inc.outside && wo.z > 0.0 {
            value += self.diffuse_value(&inc, wo);
            pdf += inc.p_diffuse * wo.z.min(1.0) * FRAC_1_PI;
        }
        (value, pdf)
    }

    /// Samples the diffuse lobe with probability `p_d` (`u_lobe < p_d`), else a GGX visible
    /// normal and then reflection or refraction about it (reusing the rescaled `u_lobe`).
    pub fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let inc = self.incident(wi)?;
        let md = &self.distribution;
        let cos_i = wi.z;
        let (wo, pdf, kind, eta) = if u_lobe < inc.p_diffuse {
            let wo = square_to_cosine_hemisphere(u);
            if wo.z <= 0.0 {
                return None;
            }
            let (_, mf_pdf) = self.microfacet_eval_pdf(&inc, wi, wo);
            let pdf = inc.p_diffuse * wo.z.min(1.0) * FRAC_1_PI + (1.0 - inc.p_diffuse) * mf_pdf;
            (wo, pdf, LobeKind::Diffuse, 1.0)
        } else {
            let u_branch = (u_lobe - inc.p_diffuse) / (1.0 - inc.p_diffuse);
            let wi_up = if inc.outside { wi } else { -wi };
            let m = md.sample_visible(wi_up, u);
            let pdf_m = md.pdf_visible(wi_up, m);
            if !positive_finite(pdf_m) {
                return None;
            }
            let wi_m = wi.dot(m);
            let fr = fresnel_dielectric(wi_m, self.params.specular_ior);
            let (refl, trans) = self.facet_weights(&inc, wi_m, &fr);
            let p_r = Self::reflect_prob(refl, trans);
            let reflect = u_branch < p_r;
            let (wo, branch_pdf, eta) = if reflect {
                let wo = (2.0 * wi_m * m - wi).normalize_or_zero();
                (wo, p_r / (4.0 * wo.dot(m).abs()), 1.0)
            } else {
                let wo = ((wi_m * fr.eta_ti + fr.cos_t) * m - fr.eta_ti * wi).normalize_or_zero();
                let wo_m = wo.dot(m);
                let denom = wi_m + fr.eta_it * wo_m;
                (wo, (1.0 - p_r) * fr.eta_it * fr.eta_it * wo_m.abs() / (denom * denom), fr.eta_it)
            };
            // The scattered direction must leave on the expected side.
            if (wo.z * cos_i < 0.0) == reflect || wo.z == 0.0 || md.g1(wo, m) <= 0.0 {
                return None;
            }
            let mut pdf = (1.0 - inc.p_diffuse) * pdf_m * branch_pdf;
            if inc.outside && wo.z > 0.0 {
                pdf += inc.p_diffuse * wo.z.min(1.0) * FRAC_1_PI;
            }
            (wo, pdf, LobeKind::Glossy, eta)
        };
        if !positive_finite(pdf) {
            return None;
        }
        let mut value = self.microfacet_eval_pdf(&inc, wi, wo).0;
        if inc.outside && wo.z > 0.0 {
            value += self.diffuse_value(&inc, wo);
        }
        let weight = value / pdf;
        if !weight.is_finite() {
            return None;
        }
        let transmitted = wo.z * cos_i < 0.0;
        Some(BsdfSample {
            wo,
            weight: weight.max(Spectrum::ZERO),
            pdf,
            kind,
            transmitted,
            eta,
            alpha: if kind == LobeKind::Diffuse { 1.0 } else { lobe_alpha(md) },
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Directional albedo table of the dielectric GGX reflection lobe

/// Nodes in `√cos θ` (uniform on [0, 1], dense toward grazing where `E` changes fastest; the node
/// at 0 holds the value at cos θ = 1e-4).
const N_MU: usize = 32;
/// Nodes in `√r = α^¼` (uniform on [0, 1]: dense at low roughness, where `E` near grazing
/// drops steeply once `α` reaches `cos θ`; the node at 0 holds α = `MIN_ALPHA`).
const N_ROUGH: usize = 21;
/// Nodes in `z = sign(q) √(|q|/0.6)` with `q = (η − 1)/(η + 1)`, uniform on [−1, 1]
/// (`q(MIN_IOR) = −0.6`, `q(MAX_IOR) = 0.6`; η = 1 is the middle node). `q` is the
/// normal-incidence amplitude reflectance, so away from grazing `E` is nearly linear in `q² ∝ z⁴`;
/// the square root puts nodes densely near η = 1, where the grazing peak of `E` narrows.
const N_ETA: usize = 41;
/// Visible-normal quadrature per table entry: midpoint rule on (u_φ ∈ [0, ½), u_z ∈ [0, 1)).
#[cfg(test)]
const Q_PHI: usize = 16;
#[cfg(test)]
const Q_Z: usize = 32;

struct AlbedoTable {
    /// `E[(i_rough · N_ETA + i_eta) · N_MU + i_mu]`.
    e: Vec<f32>,
    /// `2∫ E μ dμ` of the piecewise-linear interpolant in μ, per (rough, eta) node.
    avg: Vec<f32>,
}

static ALBEDO_TABLE: OnceLock<AlbedoTable> = OnceLock::new();

/// The table's entries as [`entries`] computes them, little-endian `f32` in the order of
/// [`AlbedoTable::e`]: computing them took 40 ms of every process that renders a
/// `standard_surface` (on two cores), a sixth of a small render; reading them takes
/// microseconds. The test `embedded_albedo_table_is_what_the_quadrature_gives` recomputes them.
const EMBEDDED_ENTRIES: &[u8] = include_bytes!("albedo_table.bin");

fn table() -> &'static AlbedoTable {
    ALBEDO_TABLE.get_or_init(|| {
        let e: Vec<f32> =
            EMBEDDED_ENTRIES.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        assert_eq!(e.len(), N_ROUGH * N_ETA * N_MU, "albedo_table.bin does not match the table's size");
        AlbedoTable { avg: averages(&e), e }
    })
}

/// Largest `|q|`, `q = (η − 1)/(η + 1)`, of the table (η = 4 or ¼).
const Q_MAX: f32 = 0.6;

/// The table coordinate `z ∈ [−1, 1]` of an IOR.
#[inline]
fn eta_to_z(eta: f32) -> f32 {
    let q = (eta - 1.0) / (eta + 1.0);
    (q.abs() / Q_MAX).min(1.0).sqrt().copysign(q)
}

#[cfg(test)]
fn eta_node(i: usize) -> f32 {
    if i == (N_ETA - 1) / 2 {
        return 1.0; // exactly index-matched in the middle (the range is symmetric)
    }
    let z = -1.0 + 2.0 * i as f32 / (N_ETA - 1) as f32;
    let q = Q_MAX * z * z.abs();
    (1.0 + q) / (1.0 - q)
}

/// `E(μ)` of GGX reflection with Fresnel at IOR `eta_k` for every `k`, by midpoint quadrature
/// of `E_m~D_wi[F(wi·m) G1(wo, m)]` over the visible-normal parametrisation (mirror-symmetric in
/// φ, so half the azimuths suffice).
#[cfg(test)]
fn directional_albedo(md: &Microfacet, mu: f32, etas: &[f32], out: &mut [f64]) {
    let wi = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    out.iter_mut().for_each(|o| *o = 0.0);
    for a in 0..Q_PHI {
        for b in 0..Q_Z {
            let u = Vec2::new(0.5 * (a as f32 + 0.5) / Q_PHI as f32, (b as f32 + 0.5) / Q_Z as f32);
            let m = md.sample_visible(wi, u);
            let wi_m = wi.dot(m);
            if m.z <= 0.0 || wi_m <= 0.0 {
                continue;
            }
            let wo = (2.0 * wi_m * m - wi).normalize_or_zero();
            if wo.z <= 0.0 {
                continue;
            }
            let g1 = md.g1(wo, m) as f64;
            if g1 <= 0.0 {
                continue;
            }
            for (o, &eta) in out.iter_mut().zip(etas) {
                *o += fresnel_dielectric(wi_m, eta).r as f64 * g1;
            }
        }
    }
    let n = (Q_PHI * Q_Z) as f64;
    out.iter_mut().for_each(|o| *o /= n);
}

/// The table's entries by quadrature, its roughness rows spread over the machine's cores (each
/// entry is computed alone, so the table is the same whatever the thread count). Embedded in
/// the binary ([`EMBEDDED_ENTRIES`]); run again by the tests.
#[cfg(test)]
fn entries() -> Vec<f32> {
    let etas: Vec<f32> = (0..N_ETA).map(eta_node).collect();
    let mut e = vec![0.0f32; N_ROUGH * N_ETA * N_MU];
    let row = |ir: usize, out: &mut [f32]| {
        let mut col = vec![0.0f64; N_ETA];
        let y = ir as f32 / (N_ROUGH - 1) as f32;
        let alpha = (y * y) * (y * y);
        let md = Microfacet::new(MicrofacetKind::Ggx, alpha, alpha);
        for imu in 0..N_MU {
            let x = imu as f32 / (N_MU - 1) as f32;
            let mu = (x * x).max(1e-4);
            directional_albedo(&md, mu, &etas, &mut col);
            for ie in 0..N_ETA {
                out[ie * N_MU + imu] = col[ie] as f32;
            }
        }
    };
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).clamp(1, N_ROUGH);
    let rows: Vec<(usize, &mut [f32])> = e.chunks_mut(N_ETA * N_MU).enumerate().collect();
    let mut parts: Vec<Vec<(usize, &mut [f32])>> = (0..threads).map(|_| Vec::new()).collect();
    for (k, r) in rows.into_iter().enumerate() {
        parts[k % threads].push(r);
    }
    std::thread::scope(|scope| {
        for part in parts {
            let row = &row;
            scope.spawn(move || {
                for (ir, out) in part {
                    row(ir, out);
                }
            });
        }
    });
    e
}

/// `E_avg` of every (roughness, IOR) row of entries `e`.
fn averages(e: &[f32]) -> Vec<f32> {
    // 2∫ μ L dμ of the interpolant L, linear in x = √μ between nodes: with μ = x²,
    // ∫ 2μ L dμ = ∫ 4x³ L(x) dx, and on [a, b] with L = y_a + (y_b − y_a)(x − a)/h,
    // = y_a (b⁴ − a⁴) + (y_b − y_a)/h · [⅘ (b⁵ − a⁵) − a (b⁴ − a⁴)].
    let h = 1.0 / (N_MU - 1) as f64;
    e.chunks(N_MU)
        .map(|row| {
            let mut s = 0.0f64;
            for i in 0..N_MU - 1 {
                let (a, b) = (i as f64 * h, (i + 1) as f64 * h);
                let (ya, yb) = (row[i] as f64, row[i + 1] as f64);
                let d4 = b.powi(4) - a.powi(4);
                s += ya * d4 + (yb - ya) / h * (0.8 * (b.powi(5) - a.powi(5)) - a * d4);
            }
            s as f32
        })
        .collect()
}

/// The bilinear (roughness, ln η) position of one material in the table, and its `E_avg`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct AlbedoLookup {
    i_rough: u16,
    i_eta: u16,
    w_rough: f32,
    w_eta: f32,
    avg: f32,
}

/// Cell index and fraction of `x ∈ [0, 1]` on `n` uniform nodes.
#[inline]
fn cell(x: f32, n: usize) -> (usize, f32) {
    let t = x.clamp(0.0, 1.0) * (n - 1) as f32;
    let i = (t as usize).min(n - 2);
    (i, (t - i as f32).clamp(0.0, 1.0))
}

impl AlbedoLookup {
    fn new(roughness: f32, eta: f32) -> Self {
        let t = table();
        let (i_rough, w_rough) = cell(roughness.max(0.0).sqrt(), N_ROUGH);
        let (i_eta, w_eta) = cell(0.5 * (eta_to_z(eta.clamp(MIN_IOR, MAX_IOR)) + 1.0), N_ETA);
        let at = |ir: usize, ie: usize| t.avg[ir * N_ETA + ie];
        let avg = (1.0 - w_rough) * ((1.0 - w_eta) * at(i_rough, i_eta) + w_eta * at(i_rough, i_eta + 1))
            + w_rough * ((1.0 - w_eta) * at(i_rough + 1, i_eta) + w_eta * at(i_rough + 1, i_eta + 1));
        AlbedoLookup { i_rough: i_rough as u16, i_eta: i_eta as u16, w_rough, w_eta, avg }
    }

    /// Trilinear `E(μ)` (linear in `√μ`).
    #[inline]
    fn e(&self, mu: f32) -> f32 {
        let t = &table().e;
        let (im, wm) = cell(mu.max(0.0).sqrt(), N_MU);
        let row = |ir: usize, ie: usize| {
            let base = (ir * N_ETA + ie) * N_MU + im;
            t[base] + wm * (t[base + 1] - t[base])
        };
        let (ir, ie) = (self.i_rough as usize, self.i_eta as usize);
        let (wr, we) = (self.w_rough, self.w_eta);
        (1.0 - wr) * ((1.0 - we) * row(ir, ie) + we * row(ir, ie + 1))
            + wr * ((1.0 - we) * row(ir + 1, ie) + we * row(ir + 1, ie + 1))
    }
}

/// Reads the embedded albedo table and reports its size (entries).
pub fn albedo_table_stats() -> usize {
    table().e.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The embedded entries are the quadrature's, bit for bit where the machine's maths library
    /// agrees with the one that wrote them, and within 1e-6 anywhere.
    #[test]
    fn embedded_albedo_table_is_what_the_quadrature_gives() {
        let fresh = entries();
        let embedded = &table().e;
        assert_eq!(fresh.len(), embedded.len());
        let worst = fresh.iter().zip(embedded).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        let same = fresh.iter().zip(embedded).filter(|(a, b)| a.to_bits() == b.to_bits()).count();
        println!("albedo table: {same} of {} entries bit-identical, worst difference {worst:e}", fresh.len());
        assert!(worst <= 1e-6, "albedo_table.bin is stale (worst difference {worst:e}): run regenerate_albedo_table");
    }

    /// Rewrites `albedo_table.bin` after a change to the quadrature or the table's nodes:
    /// `cargo test --release -p render --lib regenerate_albedo_table -- --ignored`.
    #[test]
    #[ignore]
    fn regenerate_albedo_table() {
        let bytes: Vec<u8> = entries().iter().flat_map(|v| v.to_le_bytes()).collect();
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/bsdf/albedo_table.bin");
        std::fs::write(&path, bytes).unwrap();
    }

    #[test]
    fn bsdf_standard_surface_artistic_ior() {
        // Normal incidence reproduces the reflectivity; a white edge colour keeps F high at all
        // angles, a black one lets it dip toward grazing like a dielectric-ish metal.
        for &(r, g) in &[(0.9f32, 1.0f32), (0.5, 0.2), (0.04, 0.0), (0.95, 0.6), (0.0, 0.5)] {
            let (n, k) = artistic_ior(Spectrum::splat(r), Spectrum::splat(g));
            let f0 = fresnel_conductor(1.0, n, k).x;
            assert!((f0 - r.min(0.99)).abs() < 2e-4, "r {r} g {g}: F(1) = {f0}, n {n} k {k}");
            assert!(n.is_finite() && k.is_finite() && k.min_element() >= 0.0);
        }
        let (n1, k1) = artistic_ior(Spectrum::splat(0.5), Spectrum::ONE);
        let (n0, k0) = artistic_ior(Spectrum::splat(0.5), Spectrum::ZERO);
        let grazing = 0.2;
        assert!(fresnel_conductor(grazing, n1, k1).x > fresnel_conductor(grazing, n0, k0).x);
        // Edge colour 0 gives a real IOR (k = 0): a dielectric with F0 = r.
        assert!(k0.max_element() < 1e-2, "{k0}");
    }

    #[test]
    fn bsdf_standard_surface_albedo_table_against_quadrature() {
        // Table interpolation against a direct, 16× finer quadrature at off-node points. Above
        // η = 1 the table is accurate to a few 1e-3 everywhere; below, E has a sharp edge at the
        // critical angle that the table blurs (there E only matters for opaque materials that are
        // optically thinner than air).
        let (mut worst, mut worst_under, mut worst_below_1) = (0.0f64, 0.0f64, 0.0f64);
        for &r in &[0.03f32, 0.2, 0.45, 0.71, 0.97] {
            for &eta in &[1.05f32, 1.33, 1.5, 2.4, 3.7, 0.8, 0.4] {
                let ss = StandardSurface::new(&StandardSurfaceParams {
                    specular_roughness: r,
                    specular_ior: eta,
                    ..StandardSurfaceParams::DEFAULT
                });
                let md = Microfacet::new(MicrofacetKind::Ggx, r * r, r * r);
                for &mu in &[0.02f32, 0.11, 0.37, 0.5, 0.83, 0.99] {
                    let want = direct_albedo(&md, mu, eta);
                    let got = ss.specular_albedo(mu) as f64;
                    if eta < 1.0 {
                        worst_below_1 = worst_below_1.max((got - want).abs());
                    } else {
                        worst = worst.max((got - want).abs());
                        worst_under = worst_under.max(want - got);
                    }
                }
            }
        }
        println!("albedo table, η > 1: worst |error| {worst:.2e}, worst underestimate {worst_under:.2e}; η < 1: {worst_below_1:.2e}");
        assert!(worst < 4e-3, "table error {worst}");
        assert!(worst_under < 3e-3, "table underestimates E by {worst_under}");
        assert!(worst_below_1 < 2.5e-2, "table error below η = 1: {worst_below_1}");
    }

    /// E(μ) by the midpoint rule on a 64 × 256 grid over the visible-normal parametrisation.
    fn direct_albedo(md: &Microfacet, mu: f32, eta: f32) -> f64 {
        let wi = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
        let (nx, ny) = (64, 256);
        let mut s = 0.0;
        for a in 0..nx {
            for b in 0..ny {
                let u = Vec2::new(0.5 * (a as f32 + 0.5) / nx as f32, (b as f32 + 0.5) / ny as f32);
                let m = md.sample_visible(wi, u);
                let wi_m = wi.dot(m);
                if m.z <= 0.0 || wi_m <= 0.0 {
                    continue;
                }
                let wo = (2.0 * wi_m * m - wi).normalize_or_zero();
                if wo.z <= 0.0 {
                    continue;
                }
                s += fresnel_dielectric(wi_m, eta).r as f64 * md.g1(wo, m) as f64;
            }
        }
        s / (nx * ny) as f64
    }

    #[test]
    fn bsdf_standard_surface_albedo_average_is_consistent() {
        // E_avg equals 2∫E μ dμ of the interpolant (fine midpoint rule), at off-node parameters.
        for &(r, eta) in &[(0.33f32, 1.47f32), (0.05, 2.9), (0.9, 0.7)] {
            let ss = StandardSurface::new(&StandardSurfaceParams {
                specular_roughness: r,
                specular_ior: eta,
                ..StandardSurfaceParams::DEFAULT
            });
            let n = 20_000;
            let s: f64 = (0..n)
                .map(|i| {
                    let mu = (i as f64 + 0.5) / n as f64;
                    2.0 * mu * ss.specular_albedo(mu as f32) as f64
                })
                .sum::<f64>()
                / n as f64;
            assert!((s - ss.specular_albedo_average() as f64).abs() < 1e-5, "{s} vs {}", ss.specular_albedo_average());
        }
    }
}
