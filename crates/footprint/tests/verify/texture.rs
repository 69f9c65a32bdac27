//! Texture-space and world-space covariances, the LOD, the first vertex, the GGX conversion,
//! and the comparison estimators, each against an independent computation.

use crate::common::*;
use footprint::*;
use glam::{DMat2, DMat3, DVec2, DVec3};

/// `J_uv` by central differences of the exact uv of points moved on the surface.
fn uv_jacobian_fd(s: &Surface, p: DVec3, f: &Frame) -> DMat2 {
    let eps = 1e-6;
    let uv = |dx: DVec2| s.uv(s.moved(p, f, dx).0);
    DMat2::from_cols(
        (uv(DVec2::new(eps, 0.0)) - uv(DVec2::new(-eps, 0.0))) / (2.0 * eps),
        (uv(DVec2::new(0.0, eps)) - uv(DVec2::new(0.0, -eps))) / (2.0 * eps),
    )
}

#[test]
fn uv_covariance_matches_exact_uv_mapping() {
    let mut rng = Rng::new(23);
    let tri = Surface::Triangle {
        q: [DVec3::new(-1.0, -0.5, 0.1), DVec3::new(1.2, -0.3, -0.2), DVec3::new(0.1, 1.0, 0.3)],
        m: [
            DVec3::new(0.2, 0.0, 1.0).normalize(),
            DVec3::new(-0.1, 0.3, 1.0).normalize(),
            DVec3::new(0.0, -0.2, 1.0).normalize(),
        ],
        uv: [DVec2::new(0.0, 0.0), DVec2::new(3.0, 0.5), DVec2::new(-0.5, 2.0)],
    };
    let sphere = Surface::Sphere { c: DVec3::new(0.3, -0.2, 0.5), r: 1.7, inward: false };
    let plane = Surface::plane(DVec3::new(1.0, 2.0, 3.0), DVec3::new(0.3, 0.4, 1.0));
    let points = [
        (tri, DVec3::new(0.05, 0.0, 0.0)),
        (sphere, DVec3::new(0.3, -0.2, 0.5) + DVec3::new(0.6, 0.5, 0.62).normalize() * 1.7),
        (plane, DVec3::new(1.0, 2.0, 3.0)),
    ];
    for (k, (s, p0)) in points.into_iter().enumerate() {
        // Put the point on the surface (triangle: project onto its plane).
        let p = match s {
            Surface::Triangle { q, .. } => {
                let n = (q[1] - q[0]).cross(q[2] - q[0]).normalize();
                p0 - n * n.dot(p0 - q[0])
            }
            _ => p0,
        };
        let f = Frame::around(s.normal(p), 0.9);
        let v = s.lib_vertex(p, &f);
        let cov = rng.spd(1e-4, 1e-2);
        let j = uv_jacobian_fd(&s, p, &f);
        let expect = j * cov * j.transpose();
        let got = uv_covariance(cov, &v);
        let e = rel_err(got, expect);
        assert!(e < 1e-6, "surface {k}: {e:e}\n{got:?}\n{expect:?}");
    }
}

#[test]
fn world_covariance_is_t_sigma_t_and_frame_independent() {
    let mut rng = Rng::new(29);
    let n = rng.unit_vector();
    let f1 = Frame::around(n, 0.0);
    let f2 = Frame::around(n, 1.1); // same plane, rotated tangent
    let v1 = Vertex { t: f1.t, b: f1.b, n, ..Vertex::on_plane(DVec3::ONE, n) };
    let v2 = Vertex { t: f2.t, b: f2.b, n, ..Vertex::on_plane(DVec3::ONE, n) };
    let cov1 = rng.spd(0.1, 2.0);
    // The same footprint expressed in frame 2: Σ₂ = R Σ₁ Rᵀ with R = [t₂ b₂]ᵀ [t₁ b₁].
    let r = DMat2::from_cols(f2.to_local(f1.t), f2.to_local(f1.b));
    let cov2 = r * cov1 * r.transpose();
    let w1 = world_covariance(cov1, &v1);
    let w2 = world_covariance(cov2, &v2);
    assert!((w1 - w2).abs_diff_eq(DMat3::ZERO, 1e-12));
    // Explicit T Σ Tᵀ, entry by entry.
    for i in 0..3 {
        for j in 0..3 {
            let ti = DVec2::new(f1.t[i], f1.b[i]);
            let tj = DVec2::new(f1.t[j], f1.b[j]);
            assert!((w1.col(j)[i] - ti.dot(cov1 * tj)).abs() < 1e-12);
        }
    }
    assert!((w1 * n).length() < 1e-12);
    assert!(rel_err(tangent_covariance(w1, &v1), cov1) < 1e-12);
}

#[test]
fn lod_is_log2_of_major_sigma_in_texels() {
    // Anisotropic: σ_major = 0.01 uv along a rotated axis, σ_minor = 0.001.
    let a: f64 = 0.6;
    let rot = DMat2::from_angle(a);
    let cov = rot * DMat2::from_diagonal(DVec2::new(1e-4, 1e-6)) * rot.transpose();
    let l = lod(cov, 2048.0);
    assert!((l as f64 - (0.01f64 * 2048.0).log2()).abs() < 1e-5);
    // Doubling the density moves one level up; doubling σ too.
    assert!((lod(cov, 4096.0) - l - 1.0).abs() < 1e-5);
    assert!((lod(cov * 4.0, 2048.0) - l - 1.0).abs() < 1e-5);
}

/// GGX and Beckmann lobes related by `ggx_to_beckmann_alpha` have the same median slope
/// magnitude, by numerical integration of the projected-area NDFs.
#[test]
fn ggx_conversion_matches_median_slopes() {
    use std::f64::consts::PI;
    let ag = 0.3;
    let ab = ggx_to_beckmann_alpha(ag as f32) as f64;
    // D(θ) cos θ sin θ dθ dφ integrated up to tan θ = r.
    let ggx = |t: f64| {
        let c2 = t.cos().powi(2);
        let tan2 = t.tan().powi(2);
        ag * ag / (PI * c2 * c2 * (ag * ag + tan2).powi(2))
    };
    let beck = |t: f64| {
        let c2 = t.cos().powi(2);
        (-t.tan().powi(2) / (ab * ab)).exp() / (PI * ab * ab * c2 * c2)
    };
    let mass = |d: &dyn Fn(f64) -> f64, r: f64| {
        let tmax = r.atan();
        let n = 20000;
        let h = tmax / n as f64;
        (0..n)
            .map(|i| {
                let t = (i as f64 + 0.5) * h;
                d(t) * t.cos() * t.sin() * h * 2.0 * PI
            })
            .sum::<f64>()
    };
    let median = |d: &dyn Fn(f64) -> f64| {
        let (mut lo, mut hi) = (0.0, 50.0);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if mass(d, mid) < 0.5 {
                lo = mid
            } else {
                hi = mid
            }
        }
        0.5 * (lo + hi)
    };
    let mg = median(&ggx);
    let mb = median(&beck);
    assert!((mg - ag).abs() < 1e-4, "GGX median {mg}");
    assert!((mb - mg).abs() < 1e-4, "Beckmann median {mb} vs GGX {mg}");
    // Half-vector variance is (α/√2)² I.
    let v = half_vector_variance(0.4);
    assert!((v - DMat2::IDENTITY * 0.08).abs_diff_eq(DMat2::ZERO, 1e-15));
}

#[test]
fn first_vertex_fronto_parallel_and_conventions() {
    // Fronto-parallel plane at distance 5: σ = ½ px · pixel angle · distance.
    let cam = DVec3::ZERO;
    let hit = Vertex::on_plane(DVec3::new(0.0, 0.0, 5.0), -DVec3::Z);
    let v = first_vertex_variance(cam, DVec3::Z, DVec3::X * 1e-3, DVec3::Y * 1e-3, &hit);
    let s = 0.5 * 1e-3 * 5.0;
    assert!(rel_err(v, DMat2::IDENTITY * (s * s)) < 1e-12);
    // Off-centre pixel on a sphere: unnormalised and normalised conventions agree, and both
    // agree with exactly traced offset rays.
    let path = crate::mirror::mirror_path();
    let c = &path.camera;
    let v1 = path.lib_vertices()[0];
    let fwd = c.forward * 1.7 + c.right * 30.0; // an unnormalised direction off the centre
    let hitp = path.surfaces[0].intersect(c.origin, fwd, path.points[0]);
    let f = Frame::around(path.surfaces[0].normal(hitp), 0.2);
    let vh = path.surfaces[0].lib_vertex(hitp, &f);
    let un = first_vertex_variance(c.origin, fwd, c.right, c.up, &vh);
    let len = fwd.length();
    let d = fwd / len;
    let nrm = |x: DVec3| (x - d * d.dot(x)) / len;
    let nn = first_vertex_variance(c.origin, d, nrm(c.right), nrm(c.up), &vh);
    assert!(rel_err(nn, un) < 1e-12);
    let eps = 1e-3;
    let tr = |px: DVec2| {
        let dir = fwd + c.right * px.x + c.up * px.y;
        f.to_local(path.surfaces[0].intersect(c.origin, dir, hitp) - hitp)
    };
    let j = DMat2::from_cols(
        (tr(DVec2::new(eps, 0.0)) - tr(DVec2::new(-eps, 0.0))) / (2.0 * eps),
        (tr(DVec2::new(0.0, eps)) - tr(DVec2::new(0.0, -eps))) / (2.0 * eps),
    );
    assert!(rel_err(un, j * j.transpose() * 0.25) < 1e-6);
    let _ = v1;
}

// ---------------------------------------------------------------------------------------------
// Comparison estimators

fn sorted_eigen(m: DMat2) -> (f64, f64) {
    let a = m.x_axis.x;
    let c = m.y_axis.y;
    let b = m.x_axis.y;
    let mean = 0.5 * (a + c);
    let d = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    (mean + d, mean - d)
}

#[test]
fn estimators_first_hit_on_planes() {
    let spread = 2e-3;
    let dist = 7.0;
    for tilt in [0.0f64, 0.5, 1.2] {
        let n = rotate(-DVec3::Z, DVec3::X, tilt);
        let hit = Vertex::on_plane(DVec3::new(0.0, 0.0, dist), n);
        let expect_minor = (0.5 * spread * dist).powi(2);
        let expect_major = expect_minor / tilt.cos().powi(2);
        // Ray cone.
        let mut cone = RayCone::new(DVec3::ZERO, DVec3::Z, spread);
        let (l1, l2) = sorted_eigen(cone.advance(&hit));
        assert!((l1 / expect_major - 1.0).abs() < 1e-9 && (l2 / expect_minor - 1.0).abs() < 1e-9);
        // pbrt after a rough bounce: the camera approximation gives the same footprint.
        let mut p = PbrtDifferentials::new(DVec3::ZERO, DVec3::Z, DVec3::X * spread, DVec3::Y * spread, spread, 1.0);
        let direct = p.advance(&hit);
        let (d1, d2) = sorted_eigen(direct);
        assert!((d1 / expect_major - 1.0).abs() < 1e-9 && (d2 / expect_minor - 1.0).abs() < 1e-9);
        let somewhere = Vertex::on_plane(DVec3::new(0.0, 3.0, 1.0), DVec3::Y);
        p.advance(&somewhere);
        p.scatter_rough(&somewhere, (hit.p - somewhere.p).normalize());
        assert!(!p.has_differentials());
        let approx = p.advance(&hit);
        assert!(rel_err(approx, direct) < 1e-9, "tilt {tilt}");
        // spp scale
        let mut q = PbrtDifferentials::new(DVec3::ZERO, DVec3::Z, DVec3::X * spread, DVec3::Y * spread, spread, 0.5);
        assert!(rel_err(q.advance(&hit), direct * 0.25) < 1e-9);
    }
}

/// At normal incidence on a sphere the isotropic ray cone is exact to first order, so it must
/// agree with the tracker (α = 0): reflection off convex and concave mirrors, and refraction
/// into a glass sphere.
#[test]
fn ray_cone_matches_tracker_at_normal_incidence() {
    let spread = 1e-3;
    // The optical axis avoids the poles of the sphere's (φ, θ) parameterisation.
    let ax = DVec3::new(0.6, 0.5, 0.3).normalize();
    let cam = -ax * 6.0;
    let dir = ax;
    for (r, inward, scatter, next_z) in [
        (1.5, false, Scatter::Reflection, -3.0), // convex mirror, reflect back
        (4.0, true, Scatter::Reflection, -2.0),  // concave mirror (seen from inside)
        (1.5, false, Scatter::Refraction { eta: 1.5 }, 1.0), // into glass
        (1.5, false, Scatter::Refraction { eta: 1.0 / 1.5 }, 1.0), // into a thinner medium
    ] {
        // Sphere whose hit point is at the origin with normal facing the camera.
        let c = if inward { -ax * r } else { ax * r };
        let s = Surface::Sphere { c, r, inward };
        let p = DVec3::ZERO;
        let f = Frame::around(s.normal(p), 0.3);
        let v1 = s.lib_vertex(p, &f);
        let v2 = Vertex::on_plane(ax * next_z, -ax);
        let right = perpendicular(ax);
        let up = ax.cross(right);
        let (dx, dy) = (right * spread, up * spread);
        let var1 = first_vertex_variance(cam, dir, dx, dy, &v1);
        let mut tr = FootprintTracker::start_path(cam, &v1, var1);
        let want = tr.advance(&v2, scatter, half_vector_variance(0.0));
        let mut cone = RayCone::new(cam, dir, spread);
        let c1 = cone.advance(&v1);
        assert!(rel_err(c1, var1) < 1e-12);
        cone.scatter(&v1, (v2.p - v1.p).normalize(), scatter);
        let got = cone.advance(&v2);
        let e = rel_err(got, want);
        assert!(e < 1e-9, "{scatter:?} inward {inward}: {e:e}\n{got:?}\n{want:?}");
    }
}

/// Away from normal incidence the ray cone is only an approximation; it ignores roughness.
#[test]
fn ray_cone_ignores_roughness() {
    let path = crate::mirror::mirror_path();
    let v = path.lib_vertices();
    let c = &path.camera;
    let mut cone = RayCone::new(c.origin, c.forward, 1e-3);
    let smooth: Vec<_> = (0..v.len())
        .map(|k| {
            let f = cone.advance(&v[k]);
            if k + 1 < v.len() {
                cone.scatter(&v[k], (v[k + 1].p - v[k].p).normalize(), Scatter::Reflection);
            }
            f
        })
        .collect();
    let tracker = crate::mirror::tracker_footprints(&path);
    // Same order of magnitude as the exact α = 0 footprint along the whole mirror chain.
    for k in 0..v.len() {
        let ratio = (smooth[k].x_axis.x + smooth[k].y_axis.y) / (tracker[k].x_axis.x + tracker[k].y_axis.y);
        assert!(ratio > 0.2 && ratio < 5.0, "vertex {}: ratio {ratio}", k + 1);
    }
}
