//! A_i, B_i, C_i against central finite differences of the half-vector slope, with vertices
//! moved exactly on planes, spheres and normal-interpolated triangles.

use crate::common::*;
use footprint::constraint_derivatives;
use glam::{DMat2, DVec2, DVec3};

/// A surface through `p` whose (geometric) normal is close to `nd`, of the given kind.
fn make_surface(kind: usize, p: DVec3, nd: DVec3, rng: &mut Rng) -> Surface {
    match kind {
        0 => Surface::plane(p, (nd + rng.unit_vector() * 0.2).normalize()),
        1 => {
            let r = rng.range(0.5, 3.0);
            let nout = (nd + rng.unit_vector() * 0.2).normalize();
            Surface::Sphere { c: p - nout * r, r, inward: rng.uniform() < 0.5 }
        }
        _ => {
            let ng = (nd + rng.unit_vector() * 0.2).normalize();
            let f = Frame::around(ng, rng.range(0.0, 6.0));
            let q = [
                p + f.t * rng.range(-1.5, -0.5) + f.b * rng.range(-1.0, -0.3),
                p + f.t * rng.range(0.5, 1.5) + f.b * rng.range(-0.8, 0.0),
                p + f.t * rng.range(-0.4, 0.4) + f.b * rng.range(0.6, 1.4),
            ];
            let bend = 0.35;
            let m = [
                (ng + rng.unit_vector() * bend).normalize(),
                (ng + rng.unit_vector() * bend).normalize(),
                (ng + rng.unit_vector() * bend).normalize(),
            ];
            let uv = [
                DVec2::new(0.0, 0.0),
                DVec2::new(rng.range(0.5, 1.5), rng.range(-0.3, 0.3)),
                DVec2::new(rng.range(-0.3, 0.3), rng.range(0.5, 1.5)),
            ];
            Surface::Triangle { q, m, uv }
        }
    }
}

struct Config {
    surf: [Surface; 3],
    p: [DVec3; 3],
    f: [Frame; 3],
    ev: Event,
}

fn fd_matrix(eps: f64, g: impl Fn(DVec2) -> DVec2) -> DMat2 {
    let c0 = (g(DVec2::new(eps, 0.0)) - g(DVec2::new(-eps, 0.0))) / (2.0 * eps);
    let c1 = (g(DVec2::new(0.0, eps)) - g(DVec2::new(0.0, -eps))) / (2.0 * eps);
    DMat2::from_cols(c0, c1)
}

fn check(cfg: &Config, label: &str) -> f64 {
    let eps = 1e-5;
    let [s0, s1, s2] = cfg.surf;
    let [p0, p1, p2] = cfg.p;
    let [f0, f1, f2] = cfg.f;
    let ev = cfg.ev;
    let fd_a = fd_matrix(eps, |dx| {
        let (q, _) = s0.moved(p0, &f0, dx);
        slope(q, p1, &f1, p2, ev)
    });
    let fd_b = fd_matrix(eps, |dx| {
        let (q, f) = s1.moved(p1, &f1, dx);
        slope(p0, q, &f, p2, ev)
    });
    let fd_c = fd_matrix(eps, |dx| {
        let (q, _) = s2.moved(p2, &f2, dx);
        slope(p0, p1, &f1, q, ev)
    });
    let v: Vec<_> = (0..3).map(|k| cfg.surf[k].lib_vertex(cfg.p[k], &cfg.f[k])).collect();
    let d = constraint_derivatives(&v[0], &v[1], &v[2], ev.lib());
    let mut worst: f64 = 0.0;
    for (name, lib, fd) in [("A", d.a, fd_a), ("B", d.b, fd_b), ("C", d.c, fd_c)] {
        let err = frob(lib - fd) / (1.0 + frob(fd));
        assert!(err < 1e-6, "{label}: {name} mismatch (err {err:e})\nlib {lib:?}\nfd  {fd:?}");
        worst = worst.max(err);
    }
    // The base slope itself also agrees with the library's.
    let s_lib = footprint::half_vector_slope(p0, &v[1], p2, ev.lib());
    let s_ind = slope(p0, p1, &f1, p2, ev);
    assert!((s_lib - s_ind).length() < 1e-9 * (1.0 + s_ind.length()), "{label}: slope");
    worst
}

fn random_config(rng: &mut Rng, kinds: [usize; 3], ev: Event) -> Config {
    // Keep configurations whose half vector is not grazing (|slope| < 3), as in real paths;
    // near-grazing ones are exercised by the robustness tests.
    loop {
        let cfg = random_config_any(rng, kinds, ev);
        let [p0, p1, p2] = cfg.p;
        if slope(p0, p1, &cfg.f[1], p2, ev).length() < 3.0 {
            return cfg;
        }
    }
}

fn random_config_any(rng: &mut Rng, kinds: [usize; 3], ev: Event) -> Config {
    // Current vertex at the origin with normal ~ +z.
    let n1 = (DVec3::Z + rng.unit_vector() * 0.3).normalize();
    let p1 = DVec3::new(rng.range(-0.2, 0.2), rng.range(-0.2, 0.2), 0.0);
    let up = |rng: &mut Rng| (DVec3::Z * 1.2 + rng.unit_vector()).normalize();
    let p0 = p1 + up(rng) * rng.range(1.0, 4.0);
    let dn = up(rng);
    let p2 = match ev {
        Event::Reflect => p1 + dn * rng.range(1.0, 4.0),
        _ => p1 - dn * rng.range(1.0, 4.0),
    };
    // Neighbour surfaces face the current vertex.
    let s0 = make_surface(kinds[0], p0, (p1 - p0).normalize(), rng);
    let s1 = make_surface(kinds[1], p1, n1, rng);
    let s2 = make_surface(kinds[2], p2, (p1 - p2).normalize(), rng);
    let surf = [s0, s1, s2];
    let p = [p0, p1, p2];
    let f = [
        Frame::around(s0.normal(p0), rng.range(0.0, 6.3)),
        Frame::around(s1.normal(p1), rng.range(0.0, 6.3)),
        Frame::around(s2.normal(p2), rng.range(0.0, 6.3)),
    ];
    Config { surf, p, f, ev }
}

#[test]
fn constraint_derivatives_match_finite_differences() {
    let mut rng = Rng::new(11);
    let mut worst: f64 = 0.0;
    let mut count = 0;
    for ev in [Event::Reflect, Event::Refract(1.5), Event::Refract(1.0 / 1.5)] {
        for k0 in 0..3 {
            for k1 in 0..3 {
                for k2 in 0..3 {
                    for rep in 0..4 {
                        let cfg = random_config(&mut rng, [k0, k1, k2], ev);
                        let label = format!("{ev:?} kinds {k0}{k1}{k2} rep {rep}");
                        worst = worst.max(check(&cfg, &label));
                        count += 1;
                    }
                }
            }
        }
    }
    eprintln!("{count} configurations, worst relative error {worst:e}");
}

/// The derivatives must be sensitive to what they claim to model: dropping the frame rotation
/// (shape operator) or the shading-normal offset of the tangent map changes B visibly, so the
/// finite-difference test above can fail.
#[test]
fn finite_differences_see_curvature_and_frame_rotation() {
    let mut rng = Rng::new(5);
    let cfg = random_config(&mut rng, [1, 1, 1], Event::Reflect);
    let mut v: Vec<_> = (0..3).map(|k| cfg.surf[k].lib_vertex(cfg.p[k], &cfg.f[k])).collect();
    let good = constraint_derivatives(&v[0], &v[1], &v[2], Event::Reflect.lib());
    v[1].dndu = DVec3::ZERO;
    v[1].dndv = DVec3::ZERO;
    let flat = constraint_derivatives(&v[0], &v[1], &v[2], Event::Reflect.lib());
    assert!(frob(good.b - flat.b) > 1e-2 * frob(good.b));
    assert_eq!(good.a, flat.a);
    assert_eq!(good.c, flat.c);
}
