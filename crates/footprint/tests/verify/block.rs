//! Algorithm 1 against a direct solve of the block system of eq. (2).

use crate::common::*;
use footprint::{constraint_derivatives, ConstraintDerivatives, FootprintTracker};
use glam::DMat2;

/// Solves eq. (2) densely: with `M = [M₁ | M₂]` (first block column and the rest),
/// `(Δx₂ … Δx_k) = M₂⁻¹ (Δh − M₁ Δx₁)`, a linear map `L` of `(Δx₁, Δh₁ … Δh_{k−1})`; the joint
/// covariance of all vertices is `L' D L'ᵀ` with `L' = [I 0; L]` and `D` block-diagonal.
/// Returns the full (2k × 2k) covariance of `(Δx₁ … Δx_k)`.
fn direct(rows: &[ConstraintDerivatives], var_x1: DMat2, var_h: &[DMat2]) -> Vec<Vec<f64>> {
    let m = rows.len(); // constraints; k = m + 1 vertices
    let n = 2 * m;
    let mut m1 = vec![vec![0.0; 2]; n];
    let mut m2 = vec![vec![0.0; n]; n];
    for (i, r) in rows.iter().enumerate() {
        // Row i (0-based) is constraint i+1, relating x_i, x_{i+1}, x_{i+2} (1-based vertices);
        // x₀ (the camera) is fixed, x₁ goes to M₁, x_j (j ≥ 2) to block column j − 2 of M₂.
        for (x, mat) in [(i, r.a), (i + 1, r.b), (i + 2, r.c)] {
            match x {
                0 => {}
                1 => {
                    for rr in 0..2 {
                        for cc in 0..2 {
                            m1[2 * i + rr][cc] = mat.col(cc)[rr];
                        }
                    }
                }
                _ => put_block(&mut m2, i, x - 2, mat),
            }
        }
    }
    let m2inv = dense_inverse(&m2);
    // L = [−M₂⁻¹ M₁ | M₂⁻¹] maps (Δx₁, Δh) to (Δx₂ … Δx_k); prepend the identity for Δx₁.
    let neg = matmul(&m2inv, &m1);
    let total = 2 + n;
    let mut l = vec![vec![0.0; total]; total];
    l[0][0] = 1.0;
    l[1][1] = 1.0;
    for r in 0..n {
        for c in 0..2 {
            l[2 + r][c] = -neg[r][c];
        }
        for c in 0..n {
            l[2 + r][2 + c] = m2inv[r][c];
        }
    }
    let mut d = vec![vec![0.0; total]; total];
    put_block(&mut d, 0, 0, var_x1);
    for (i, v) in var_h.iter().enumerate() {
        put_block(&mut d, i + 1, i + 1, *v);
    }
    matmul(&matmul(&l, &d), &transpose(&l))
}

fn compare(rows: &[ConstraintDerivatives], var_x1: DMat2, var_h: &[DMat2], label: &str) -> f64 {
    let full = direct(rows, var_x1, var_h);
    let mut tr = FootprintTracker::start(var_x1);
    let mut worst: f64 = 0.0;
    for (i, r) in rows.iter().enumerate() {
        let v = tr.step(r, var_h[i]);
        let expect = get_block(&full, i + 1, i + 1);
        let e = rel_err(v, expect);
        let expect_cov = get_block(&full, i + 1, i);
        let ec = frob(tr.cov_current_previous() - expect_cov) / frob(expect).max(1e-300);
        assert!(e < 1e-9 && ec < 1e-9, "{label}: vertex {} var err {e:e} cov err {ec:e}", i + 2);
        assert!(rel_err(tr.var_previous(), get_block(&full, i, i)) < 1e-9);
        worst = worst.max(e).max(ec);
    }
    worst
}

#[test]
fn tracker_matches_direct_block_solve_random_matrices() {
    let mut rng = Rng::new(3);
    let mut worst: f64 = 0.0;
    for k in 2..=8 {
        for rep in 0..25 {
            let rows: Vec<_> = (0..k - 1)
                .map(|_| ConstraintDerivatives {
                    a: rng.mat2(1.0),
                    b: rng.mat2(1.0),
                    // well-conditioned C (the solve is exact; conditioning only affects rounding)
                    c: rng.mat2(0.5) + DMat2::from_diagonal(glam::DVec2::new(1.5, -1.2)),
                })
                .collect();
            let var_x1 = rng.spd(0.01, 1.0);
            let var_h: Vec<_> =
                (0..k - 1).map(|i| if (i + rep) % 4 == 3 { DMat2::ZERO } else { rng.spd(0.0, 0.5) }).collect();
            worst = worst.max(compare(&rows, var_x1, &var_h, &format!("k {k} rep {rep}")));
        }
    }
    eprintln!("block solve: worst relative error {worst:e}");
}

/// The same with A/B/C of real geometric paths (as the library forms them).
#[test]
fn tracker_matches_direct_block_solve_geometric_paths() {
    let mut rng = Rng::new(17);
    for rep in 0..10 {
        let cam = Camera::looking_at(
            glam::DVec3::new(0.0, -4.0, 2.5),
            glam::DVec3::new(rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), 0.0),
            1e-3,
        );
        let mut nodes = Vec::new();
        for i in 0..7 {
            let place = match (i + rep) % 3 {
                0 => Place::Plane { dist: rng.range(1.0, 3.0), tilt: rng.range(-0.6, 0.6) },
                1 => Place::SphereOutside {
                    dist: rng.range(1.0, 3.0),
                    r: rng.range(0.5, 2.0),
                    beta: rng.range(0.0, 0.8),
                    inward: false,
                },
                _ => Place::Triangle { dist: rng.range(1.0, 3.0), tilt: rng.range(-0.6, 0.6), bend: 0.3 },
            };
            let place = if i == 0 { Place::Plane { dist: 4.0, tilt: 0.3 } } else { place };
            nodes.push(Node {
                place,
                event: if i == 6 { Event::End } else { Event::Reflect },
                alpha: 0.0,
                base_slope: rng.normal2() * 0.1,
                frame_angle: rng.range(0.0, 6.0),
            });
        }
        let path = Path::build(cam, nodes);
        let v = path.lib_vertices();
        let cam_v = footprint::Vertex::point(path.camera.origin);
        let rows: Vec<_> = (0..v.len() - 1)
            .map(|i| {
                let prev = if i == 0 { &cam_v } else { &v[i - 1] };
                constraint_derivatives(prev, &v[i], &v[i + 1], footprint::Scatter::Reflection)
            })
            .collect();
        let var_x1 = rng.spd(1e-6, 1e-5);
        let var_h: Vec<_> = rows.iter().map(|_| rng.spd(0.0, 0.3)).collect();
        compare(&rows, var_x1, &var_h, &format!("geometric rep {rep}"));
    }
}
