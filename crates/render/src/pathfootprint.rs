//! Footprints along camera paths: the renderer's side of the `footprint` crate.
//!
//! [`PathFootprint`] is carried by every camera path. At the first hit it projects the pixel
//! filter (σ = ½ px) by the camera's ray differentials; at every later hit it advances by the
//! estimator the user chose ([`FootprintMode`]): Algorithm 1 of the supplemental (default), ray
//! cones, pbrt-v4-style differentials, or none (point sampling). The result at each vertex is a
//! [`footprint::Footprint`]: the 2×2 tangent-plane covariance, the world 3×3 `T Σ Tᵀ` and the uv
//! covariance.

use crate::bsdf::{BsdfSample, LobeKind};
use crate::camera::{Camera, CameraRay};
use crate::geometry::SurfaceInteraction;
use footprint::{
    first_vertex_variance, half_vector_variance, FootprintTracker, PbrtDifferentials, RayCone, Scatter, Vertex,
};
use glam::{DMat2, DVec2, Vec3};
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

/// The footprint crate's view of a surface hit.
pub fn vertex_of(si: &SurfaceInteraction) -> Vertex {
    Vertex {
        p: si.p.as_dvec3(),
        n: si.sh.n.as_dvec3(),
        t: si.sh.s.as_dvec3(),
        b: si.sh.t.as_dvec3(),
        dpdu: si.dpdu.as_dvec3(),
        dpdv: si.dpdv.as_dvec3(),
        dndu: si.dndu.as_dvec3(),
        dndv: si.dndv.as_dvec3(),
        uv: DVec2::new(si.uv.x as f64, si.uv.y as f64),
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
    /// Starts at the first hit `x1` of camera ray `cam`; returns the state and `var(Δx₁)`.
    pub fn start(mode: FootprintMode, camera: &Camera, cam: &CameraRay, x1: &Vertex, spp: u32) -> (Self, DMat2) {
        let o = cam.ray.o.as_dvec3();
        let d = cam.d_unnormalised.as_dvec3();
        match mode {
            FootprintMode::Covariance => {
                let var = first_vertex_variance(o, d, cam.dd_dx.as_dvec3(), cam.dd_dy.as_dvec3(), x1);
                (PathFootprint::Covariance(FootprintTracker::start_path(o, x1, var)), var)
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
