//! Monte Carlo perturbation of real paths: perturb the screen offset and every half-vector
//! slope, re-trace exactly through the analytic scene, and compare the empirical covariance of
//! every vertex (in the base vertex's tangent plane, divided by s²) with the prediction.

use crate::common::*;
use crate::mirror::{glass_path, tracker_footprints};
use footprint::{constraint_derivatives, half_vector_variance, Vertex};
use glam::{DMat2, DVec2, DVec3};

const S: f64 = 1e-3;
const SAMPLES: usize = 200_000;
const TOLERANCE: f64 = 0.03;

fn glossy_path() -> Path {
    let cam = Camera::looking_at(DVec3::new(0.0, -4.0, 2.5), DVec3::new(0.2, 0.1, 0.0), 1e-3);
    let node = |place, event, alpha, slope: [f64; 2], angle| Node {
        place,
        event,
        alpha,
        base_slope: DVec2::from(slope),
        frame_angle: angle,
    };
    Path::build(
        cam,
        vec![
            node(Place::Plane { dist: 4.8, tilt: 0.15 }, Event::Reflect, 0.2, [0.05, -0.03], 0.3),
            node(
                Place::SphereOutside { dist: 3.0, r: 1.0, beta: 0.5, inward: false },
                Event::Reflect,
                0.1,
                [-0.02, 0.04],
                1.2,
            ),
            node(
                Place::Triangle { dist: 2.5, tilt: 0.4, bend: 0.3 },
                Event::Reflect,
                1.0, // diffuse
                [0.3, -0.2],
                2.0,
            ),
            node(
                Place::SphereInside { dist: 1.5, r: 2.0, beta: 0.2, inward: true },
                Event::Reflect,
                0.15,
                [0.01, 0.02],
                0.7,
            ),
            node(Place::Plane { dist: 2.0, tilt: 0.6 }, Event::End, 0.0, [0.0, 0.0], 0.0),
        ],
    )
}

/// Empirical covariances of `Δx_k / s` for every vertex.
fn monte_carlo(path: &Path, seed: u64) -> Vec<DMat2> {
    let k = path.points.len();
    let mut rng = Rng::new(seed);
    let mut sum = vec![DVec2::ZERO; k];
    let mut sum2 = vec![DMat2::ZERO; k];
    let mut dh = vec![DVec2::ZERO; k];
    for _ in 0..SAMPLES {
        let px = rng.normal2() * (S * 0.5);
        for (i, node) in path.nodes.iter().enumerate() {
            dh[i] = rng.normal2() * (S * node.alpha / 2f64.sqrt());
        }
        let pts = path.trace(px, &dh);
        for i in 0..k {
            let d = path.frames[i].to_local(pts[i] - path.points[i]) / S;
            sum[i] += d;
            sum2[i] += DMat2::from_cols(d * d.x, d * d.y);
        }
    }
    let n = SAMPLES as f64;
    (0..k)
        .map(|i| {
            let m = sum[i] / n;
            (sum2[i] - DMat2::from_cols(m * m.x, m * m.y) * n) / (n - 1.0)
        })
        .collect()
}

fn check(path: &Path, name: &str, seed: u64) -> Vec<DMat2> {
    let pred = tracker_footprints(path);
    let mc = monte_carlo(path, seed);
    for i in 0..pred.len() {
        let e = rel_err(mc[i], pred[i]);
        eprintln!("{name} vertex {}: relative Frobenius error {e:.4}", i + 1);
        assert!(e < TOLERANCE, "{name} vertex {}: {e}\nmc   {:?}\npred {:?}", i + 1, mc[i], pred[i]);
    }
    mc
}

#[test]
fn monte_carlo_glossy_chain() {
    let path = glossy_path();
    let mc = check(&path, "glossy", 1);
    // Sensitivity: a model that drops the cross-covariance cov(Δx_i, Δx_{i−1}) of eq. (14)
    // is visibly wrong on the same samples, so this test can fail.
    let naive = no_cross_covariance(&path);
    let worst = (0..naive.len()).map(|i| rel_err(mc[i], naive[i])).fold(0.0, f64::max);
    eprintln!("glossy without cross-covariance: worst error {worst:.3}");
    assert!(worst > 3.0 * TOLERANCE);
}

#[test]
fn monte_carlo_rough_glass_sphere() {
    check(&glass_path(0.05), "rough glass", 2);
}

#[test]
fn monte_carlo_smooth_glass_sphere() {
    check(&glass_path(0.0), "smooth glass", 3);
}

/// Algorithm 1 without the cross terms (a plausible mistake).
fn no_cross_covariance(path: &Path) -> Vec<DMat2> {
    let v = path.lib_vertices();
    let cam = &path.camera;
    let cam_v = Vertex::point(cam.origin);
    let var1 = footprint::first_vertex_variance(cam.origin, cam.forward, cam.right, cam.up, &v[0]);
    let mut out = vec![var1];
    let mut var_pp = DMat2::ZERO;
    let mut var_p = var1;
    for i in 0..v.len() - 1 {
        let prev = if i == 0 { &cam_v } else { &v[i - 1] };
        let d = constraint_derivatives(prev, &v[i], &v[i + 1], path.nodes[i].event.lib());
        let ci = d.c.inverse();
        let g = d.a * var_pp * d.a.transpose() + d.b * var_p * d.b.transpose();
        let next = ci * (half_vector_variance(path.nodes[i].alpha) + g) * ci.transpose();
        var_pp = var_p;
        var_p = next;
        out.push(next);
    }
    out
}
