//! Footprints along camera paths: the renderer's side of the `footprint` crate.
//!
//! [`PathFootprint`] is carried by every camera path. At the first hit it projects the pixel
//! filter (σ = ½ px) by the camera's ray differentials; at every later hit it advances by the
//! estimator the user chose ([`FootprintMode`]): Algorithm 1 of the supplemental (default), ray
//! cones, pbrt-v4-style differentials, or none (point sampling). The result at each vertex is a
//! [`footprint::VertexFootprint`]: the 2×2 tangent-plane covariance, the world 3×3 `T Σ Tᵀ` and the uv
//! covariance.

use crate::bsdf::{lobe_alpha, Bsdf, BsdfModel, BsdfSample, LobeKind};
use crate::camera::{Camera, CameraRay};
use footprint::{
    first_vertex_variance_with, half_vector_variance, FootprintTracker, LocalGeometry, PbrtDifferentials, PixelRay,
    RayCone, Scatter, Vertex,
};
use glam::{DMat2, DVec3, Vec3};
use std::str::FromStr;

/// Which footprint estimator paths carry (`--footprint`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FootprintMode {
    /// Algorithm 1: half-vector-space covariance propagation with roughness.
    #[default]
    Covariance,
    /// Ray cones (Akenine-Möller et al. 2021); roughness ignored.
    RayCone,
    /// pbrt-v4: ray differentials through specular bounces, camera approximation after others.
    Pbrt,
    /// No footprint: point sampling.
    None,
}

impl FromStr for FootprintMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s {
            "covariance" => FootprintMode::Covariance,
            "raycone" => FootprintMode::RayCone,
            "pbrt" => FootprintMode::Pbrt,
            "none" => FootprintMode::None,
            _ => return Err(format!("unknown footprint estimator '{s}' (expected covariance, raycone, pbrt or none)")),
        })
    }
}

/// The scattering event of a BSDF sample, as the footprint crate names it.
pub fn scatter_of(bs: &BsdfSample) -> Scatter {
    if bs.transmitted {
        Scatter::Refraction { eta: bs.eta as f64 }
    } else {
        Scatter::Reflection
    }
}

/// The scattering record a BSDF sample toward `wo` would carry, for the footprint a shadow ray
/// from this vertex carries onto the partly transparent surfaces it crosses (next-event
/// estimation picks `wo` by the light, so there is no sample): reflection or refraction by the
/// sides of `wi` and `wo`, the interface's IOR ratio on refraction, and the roughness of the
/// BSDF's roughest lobe (1 where it has a diffuse part). A texture seen through the shadow ray is
/// so filtered at least as widely as along any path the BSDF could sample toward the light.
pub fn shadow_scatter(bsdf: &Bsdf, wi: Vec3, wo: Vec3) -> BsdfSample {
    let transmitted = wi.z * wo.z < 0.0;
    let (alpha, eta) = match &bsdf.model {
        BsdfModel::Diffuse(_) => (1.0, 1.0),
        BsdfModel::RoughConductor(b) => (lobe_alpha(&b.distribution), 1.0),
        BsdfModel::RoughDielectric(b) => (lobe_alpha(&b.distribution), b.eta),
        BsdfModel::StandardSurface(b) => {
            let p = b.params();
            let diffuse = p.metalness < 1.0 && p.transmission < 1.0;
            (if diffuse { 1.0 } else { lobe_alpha(b.distribution()) }, p.specular_ior)
        }
        // Delta BSDFs: next-event estimation never traces shadow rays from them.
        BsdfModel::Conductor(_) => (0.0, 1.0),
        BsdfModel::Dielectric(b) => (0.0, b.eta),
    };
    let eta = match (transmitted, wi.z >= 0.0) {
        (false, _) => 1.0,
        (true, true) => eta,
        (true, false) => 1.0 / eta,
    };
    let kind = if alpha >= 1.0 {
        LobeKind::Diffuse
    } else if alpha > 0.0 {
        LobeKind::Glossy
    } else {
        LobeKind::Specular
    };
    BsdfSample { wo, weight: Vec3::ONE, pdf: 1.0, kind, transmitted, eta, alpha }
}

/// A footprint estimator's state along one camera path (no allocation; one lives on the stack
/// per path, so the variants' different sizes cost nothing worth a box).
#[derive(Clone, Copy, Debug)]
#[allow(clippy::large_enum_variant)]
pub enum PathFootprint {
    /// Algorithm 1.
    Covariance(FootprintTracker),
    /// Ray cone.
    RayCone(RayCone),
    /// pbrt-v4-style differentials.
    Pbrt(PbrtDifferentials),
    /// Point sampling.
    None,
}

impl PathFootprint {
    /// Starts at the first hit `x1` of camera ray `cam`, whose local geometry is `local` and
    /// geometric normal `normal`; returns the state and `var(Δx₁)`.
    pub fn start(
        mode: FootprintMode,
        camera: &Camera,
        cam: &CameraRay,
        x1: &Vertex,
        (local, normal): (&LocalGeometry, DVec3),
        spp: u32,
    ) -> (Self, DMat2) {
        let o = cam.ray.o.as_dvec3();
        let d = cam.d_unnormalised.as_dvec3();
        match mode {
            FootprintMode::Covariance => {
                let ray =
                    PixelRay { origin: o, dir: d, d_dir_dpx: cam.dd_dx.as_dvec3(), d_dir_dpy: cam.dd_dy.as_dvec3() };
                let var = first_vertex_variance_with(&ray, x1, normal);
                (PathFootprint::Covariance(FootprintTracker::start_path_with(o, x1, local, var)), var)
            }
            FootprintMode::RayCone => {
                let mut cone = RayCone::new(o, d, camera.pixel_spread_angle());
                let var = cone.advance(x1);
                (PathFootprint::RayCone(cone), var)
            }
            FootprintMode::Pbrt => {
                let scale = (1.0 / (spp.max(1) as f64).sqrt()).max(0.125);
                let mut p = PbrtDifferentials::new(
                    o,
                    d,
                    cam.dd_dx.as_dvec3(),
                    cam.dd_dy.as_dvec3(),
                    camera.pixel_spread_angle(),
                    scale,
                );
                let var = p.advance(x1);
                (PathFootprint::Pbrt(p), var)
            }
            FootprintMode::None => (PathFootprint::None, DMat2::ZERO),
        }
    }

    /// The uv Jacobian at `v`, the vertex this state reached last (the tracker keeps it).
    pub fn uv_jacobian(&self, v: &Vertex) -> DMat2 {
        match self {
            PathFootprint::Covariance(t) => t.current_local().uv_jacobian,
            _ => v.uv_jacobian(),
        }
    }

    /// Advances from the current vertex `cur` (where `bs` was sampled, leaving along `dir`) to
    /// the next hit `next`; returns `var(Δx)` at `next` in its tangent frame.
    pub fn advance(&mut self, cur: &Vertex, bs: &BsdfSample, dir: Vec3, next: &Vertex) -> DMat2 {
        match self {
            PathFootprint::Covariance(t) => {
                // Roughness of the lobe the path took: σ = α/√2 in slope space (α = 1 diffuse).
                t.advance(next, scatter_of(bs), half_vector_variance(bs.alpha as f64))
            }
            PathFootprint::RayCone(c) => {
                c.scatter(cur, dir.as_dvec3(), scatter_of(bs));
                c.advance(next)
            }
            PathFootprint::Pbrt(p) => {
                if bs.kind == LobeKind::Specular {
                    p.scatter_specular(cur, dir.as_dvec3(), scatter_of(bs));
                } else {
                    p.scatter_rough(cur, dir.as_dvec3());
                }
                p.advance(next)
            }
            PathFootprint::None => DMat2::ZERO,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::{Diffuse, Microfacet, MicrofacetKind, RoughDielectric};

    #[test]
    fn shadow_scatter_describes_the_light_direction_with_the_roughest_lobe() {
        let up = Vec3::new(0.3, 0.1, 0.9).normalize();
        let down = Vec3::new(-0.2, 0.4, -0.8).normalize();
        let diffuse = Bsdf::new(BsdfModel::Diffuse(Diffuse { reflectance: Vec3::splat(0.5) }));
        let s = shadow_scatter(&diffuse, up, up);
        assert_eq!((s.alpha, s.kind, s.transmitted, s.eta, s.wo), (1.0, LobeKind::Diffuse, false, 1.0, up));
        let glass = Bsdf::new(BsdfModel::RoughDielectric(RoughDielectric {
            distribution: Microfacet::new(MicrofacetKind::Beckmann, 0.2, 0.2),
            eta: 1.5,
            specular_reflectance: Vec3::ONE,
            specular_transmittance: Vec3::ONE,
        }));
        // Reflection keeps η = 1; refraction enters (η) or leaves (1/η) by the side of wi.
        let r = shadow_scatter(&glass, up, up);
        assert_eq!((r.kind, r.transmitted, r.eta), (LobeKind::Glossy, false, 1.0));
        assert!((r.alpha - 0.2).abs() < 1e-6, "{}", r.alpha);
        let t = shadow_scatter(&glass, up, down);
        assert_eq!((t.transmitted, t.eta), (true, 1.5));
        let t = shadow_scatter(&glass, down, up);
        assert_eq!((t.transmitted, t.eta), (true, 1.0 / 1.5));
    }
}
