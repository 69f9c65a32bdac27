//! α = 0 chains: the tracker against classic ray-differential propagation (Igehy 1999),
//! implemented here independently, and against finite differences of exactly traced rays.

use crate::common::*;
use footprint::{first_vertex_variance, half_vector_variance, FootprintTracker, PbrtDifferentials};
use glam::{DMat2, DVec2, DVec3};

pub fn mirror_path() -> Path {
    let cam = Camera::looking_at(DVec3::new(0.0, -4.0, 2.5), DVec3::new(0.2, 0.1, 0.0), 1e-3);
    let node = |place, event| Node { place, event, alpha: 0.0, base_slope: DVec2::ZERO, frame_angle: 0.4 };
    Path::build(
        cam,
        vec![
            node(Place::SphereOutside { dist: 4.5, r: 1.5, beta: 0.4, inward: false }, Event::Reflect),
            node(Place::Plane { dist: 3.0, tilt: 0.5 }, Event::Reflect),
            node(Place::SphereInside { dist: 2.5, r: 3.0, beta: 0.3, inward: true }, Event::Reflect),
            node(Place::SphereOutside { dist: 2.0, r: 0.8, beta: 0.6, inward: false }, Event::Reflect),
            node(Place::SphereInside { dist: 1.5, r: 2.0, beta: 0.2, inward: false }, Event::Reflect),
            node(Place::Plane { dist: 2.0, tilt: -0.3 }, Event::End),
        ],
    )
}

pub fn glass_path(alpha: f64) -> Path {
    let cam = Camera::looking_at(DVec3::new(0.3, -5.0, 1.0), DVec3::new(0.0, 0.0, 0.4), 1e-3);
    // A smooth path is exactly specular; a rough base path has non-zero half-vector slopes.
    let rough = if alpha > 0.0 { 1.0 } else { 0.0 };
    let node = |place, event, slope| Node { place, event, alpha, base_slope: slope, frame_angle: 1.1 };
    Path::build(
        cam,
        vec![
            node(
                Place::SphereOutside { dist: 4.0, r: 1.0, beta: 0.35, inward: false },
                Event::Refract(1.5),
                DVec2::new(0.02, -0.03) * rough,
            ),
            node(Place::SameSphere, Event::Refract(1.0 / 1.5), DVec2::new(-0.01, 0.02) * rough),
            node(Place::Plane { dist: 3.0, tilt: 0.3 }, Event::End, DVec2::ZERO),
        ],
    )
}

/// Footprints predicted by the tracker, one per vertex.
pub fn tracker_footprints(path: &Path) -> Vec<DMat2> {
    let v = path.lib_vertices();
    let cam = &path.camera;
    let var1 = first_vertex_variance(cam.origin, cam.forward, cam.right, cam.up, &v[0]);
    let mut tr = FootprintTracker::start_path(cam.origin, &v[0], var1);
    let mut out = vec![var1];
    for k in 1..v.len() {
        let node = &path.nodes[k - 1];
        out.push(tr.advance(&v[k], node.event.lib(), half_vector_variance(node.alpha)));
    }
    out
}

/// Igehy's ray differentials along a mirror path (plane and sphere mirrors), returning
/// `J_k = ∂Δx_k/∂(pixel)` for every vertex.
fn igehy_mirror(path: &Path) -> Vec<DMat2> {
    let cam = &path.camera;
    let len = cam.forward.length();
    let mut d = cam.forward / len;
    let perp = |v: DVec3, d: DVec3| (v - d * d.dot(v)) / len;
    let mut dd = [perp(cam.right, d), perp(cam.up, d)];
    let mut o = cam.origin;
    let mut dorig = [DVec3::ZERO; 2];
    let mut out = Vec::new();
    for k in 0..path.points.len() {
        let p = path.points[k];
        let surf = path.surfaces[k];
        let n = surf.normal(p);
        let t = (p - o).dot(d);
        let mut dp = [DVec3::ZERO; 2];
        for j in 0..2 {
            // transfer (Igehy eqs. 10, 12)
            let v = dorig[j] + dd[j] * t;
            dp[j] = v - d * (v.dot(n) / d.dot(n));
        }
        let f = &path.frames[k];
        out.push(DMat2::from_cols(f.to_local(dp[0]), f.to_local(dp[1])));
        if path.nodes[k].event == Event::End {
            break;
        }
        assert_eq!(path.nodes[k].event, Event::Reflect);
        for j in 0..2 {
            let dn = match surf {
                Surface::Sphere { r, inward, .. } => {
                    let s = if inward { -1.0 / r } else { 1.0 / r };
                    (dp[j] - n * n.dot(dp[j])) * s
                }
                Surface::Plane { .. } => DVec3::ZERO,
                Surface::Triangle { .. } => panic!("not a plane or sphere mirror"),
            };
            // reflection (Igehy eq. 16–17): r = d − 2(d·n)n
            dd[j] = dd[j] - (dn * d.dot(n) + n * (dd[j].dot(n) + d.dot(dn))) * 2.0;
            dorig[j] = dp[j];
        }
        d = d - n * (2.0 * d.dot(n));
        o = p;
    }
    out
}

/// `J_k` by central differences of exactly re-traced rays (any α = 0 path, refraction too).
fn traced_jacobians(path: &Path) -> Vec<DMat2> {
    let eps = 1e-3;
    let plus_x = path.trace(DVec2::new(eps, 0.0), &[]);
    let minus_x = path.trace(DVec2::new(-eps, 0.0), &[]);
    let plus_y = path.trace(DVec2::new(0.0, eps), &[]);
    let minus_y = path.trace(DVec2::new(0.0, -eps), &[]);
    (0..path.points.len())
        .map(|k| {
            let f = &path.frames[k];
            DMat2::from_cols(
                f.to_local((plus_x[k] - minus_x[k]) / (2.0 * eps)),
                f.to_local((plus_y[k] - minus_y[k]) / (2.0 * eps)),
            )
        })
        .collect()
}

fn quarter_jjt(j: DMat2) -> DMat2 {
    j * j.transpose() * 0.25
}

#[test]
fn mirror_chain_matches_igehy_ray_differentials() {
    let path = mirror_path();
    let pred = tracker_footprints(&path);
    let ig = igehy_mirror(&path);
    let fd = traced_jacobians(&path);
    assert_eq!(pred.len(), 6);
    for k in 0..pred.len() {
        let e = rel_err(pred[k], quarter_jjt(ig[k]));
        let e_fd = rel_err(quarter_jjt(fd[k]), quarter_jjt(ig[k]));
        eprintln!("mirror vertex {}: tracker vs Igehy {e:e}, traced vs Igehy {e_fd:e}", k + 1);
        assert!(e < 1e-9, "vertex {}: {e:e}", k + 1);
        assert!(e_fd < 1e-5, "test-side Igehy vs traced rays at vertex {}: {e_fd:e}", k + 1);
    }
    // The chain is not trivial: the footprint's shape changes along it.
    let ratio = |m: DMat2| m.determinant().sqrt() / (m.x_axis.x + m.y_axis.y);
    assert!((ratio(pred[5]) - ratio(pred[0])).abs() > 0.05);
}

#[test]
fn smooth_glass_matches_traced_ray_differentials() {
    let path = glass_path(0.0);
    let pred = tracker_footprints(&path);
    let fd = traced_jacobians(&path);
    for k in 0..pred.len() {
        let e = rel_err(pred[k], quarter_jjt(fd[k]));
        eprintln!("glass vertex {}: tracker vs traced {e:e}", k + 1);
        assert!(e < 1e-5, "vertex {}: {e:e}", k + 1);
    }
}

/// The pbrt-style estimator carries true ray differentials through specular chains, so with
/// α = 0 it must agree with the tracker (an independent derivation: Igehy's reflection and
/// refraction of differentials versus the half-vector constraint).
#[test]
fn pbrt_estimator_agrees_on_specular_chains() {
    for (path, events) in [(mirror_path(), "mirror"), (glass_path(0.0), "glass")] {
        let pred = tracker_footprints(&path);
        let v = path.lib_vertices();
        let cam = &path.camera;
        let mut pbrt = PbrtDifferentials::new(cam.origin, cam.forward, cam.right, cam.up, 1e-3, 1.0);
        for k in 0..v.len() {
            let cov = pbrt.advance(&v[k]);
            let e = rel_err(cov, pred[k]);
            assert!(e < 1e-9, "{events} vertex {}: {e:e}", k + 1);
            if k + 1 < v.len() {
                let next_dir = (path.points[k + 1] - path.points[k]).normalize();
                pbrt.scatter_specular(&v[k], next_dir, path.nodes[k].event.lib());
                assert!(pbrt.has_differentials());
            }
        }
    }
}
