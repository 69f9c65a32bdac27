//! Robustness: every documented clamp is driven, and nothing returns NaN or infinity.

use footprint::*;
use glam::{DMat2, DVec2, DVec3};

use crate::common::rotate;

fn finite_psd_bounded(m: DMat2) -> bool {
    let sym = (m.x_axis.y - m.y_axis.x).abs() <= 1e-9 * (1.0 + m.x_axis.x.abs() + m.y_axis.y.abs());
    m.is_finite()
        && sym
        && m.x_axis.x >= 0.0
        && m.y_axis.y >= 0.0
        && m.determinant() >= -1e-9 * (m.x_axis.x * m.y_axis.y).max(1e-300)
        && major(m) <= MAX_VARIANCE * (1.0 + 1e-12)
}

fn major(m: DMat2) -> f64 {
    let a = m.x_axis.x;
    let c = m.y_axis.y;
    let b = 0.5 * (m.x_axis.y + m.y_axis.x);
    0.5 * (a + c) + (0.25 * (a - c) * (a - c) + b * b).sqrt()
}

/// A glossy reflection at the origin (plane z = 0) seen from `(0, −1, 1)`, towards a plane at
/// distance 2 along the mirror direction whose normal makes `cos = c` with the ray.
fn grazing_setup(c: f64) -> (Vertex, Vertex, Vertex) {
    let prev = Vertex::point(DVec3::new(0.0, -1.0, 1.0));
    let cur = Vertex::on_plane(DVec3::ZERO, DVec3::Z);
    let wo = DVec3::new(0.0, 1.0, 1.0).normalize();
    let u = DVec3::X; // perpendicular to wo
    let n_next = -wo * c + u * (1.0 - c * c).max(0.0).sqrt();
    let next = Vertex::on_plane(wo * 2.0, n_next);
    (prev, cur, next)
}

#[test]
fn grazing_next_vertex_is_clamped() {
    let var1 = DMat2::IDENTITY * 1e-6;
    let run = |c: f64| {
        let (prev, cur, next) = grazing_setup(c);
        let mut tr = FootprintTracker::start_path(prev.p, &cur, var1);
        let v = tr.advance(&next, Scatter::Reflection, half_vector_variance(0.3));
        assert!(finite_psd_bounded(v), "cos {c}: {v:?}");
        major(v)
    };
    let l1 = run(1e-1);
    let l2 = run(1e-2);
    let l3 = run(1e-3);
    // Genuine grazing elongation: variance ∝ 1/cos².
    assert!((l2 / l1 / 100.0 - 1.0).abs() < 0.1, "{l1} {l2}");
    assert!((l3 / l2 / 100.0 - 1.0).abs() < 0.1, "{l2} {l3}");
    // Beyond the clamp the footprint stops growing.
    let l_clamp = run(C_CONDITION_LIMIT);
    for c in [1e-6, 1e-9, 1e-14, 0.0] {
        let l = run(c);
        eprintln!("grazing cos {c:e}: major {l:e} (clamp-level {l_clamp:e}, cos 1e-3: {l3:e})");
        assert!(l <= 4.0 * l_clamp, "cos {c}: {l} vs {l_clamp}");
    }
}

#[test]
fn singular_and_non_finite_matrices_in_matrix_mode() {
    let var1 = DMat2::IDENTITY * 1e-4;
    let d = |c: DMat2| ConstraintDerivatives {
        a: DMat2::IDENTITY,
        b: DMat2::from_cols(DVec2::new(2.0, 0.1), DVec2::new(-0.3, 1.0)),
        c,
    };
    let vh = half_vector_variance(0.5);
    // C = 0: the absolute floor MIN_C_SINGULAR_VALUE gives a maximal, finite footprint.
    let mut tr = FootprintTracker::start(var1);
    let v = tr.step(&d(DMat2::ZERO), vh);
    assert!(finite_psd_bounded(v));
    assert!(major(v) > 0.99 * MAX_VARIANCE);
    // The clamp resets the correlation; the next step is still fine.
    assert_eq!(tr.cov_current_previous(), DMat2::ZERO);
    let v = tr.step(&d(DMat2::IDENTITY), vh);
    assert!(finite_psd_bounded(v));
    // Rank-one C.
    let mut tr = FootprintTracker::start(var1);
    let rank1 = DMat2::from_cols(DVec2::new(1.0, 2.0), DVec2::new(0.5, 1.0));
    let v = tr.step(&d(rank1), vh);
    assert!(finite_psd_bounded(v));
    // Elongation capped at 1/C_CONDITION_LIMIT in standard deviation (times B's conditioning).
    let v2 = tr.step(&d(DMat2::IDENTITY), vh);
    assert!(finite_psd_bounded(v2));
    // Non-finite inputs: the tracker is lost → maximal isotropic footprint, and recovers.
    for bad in [f64::NAN, f64::INFINITY] {
        let mut tr = FootprintTracker::start(var1);
        let mut dd = d(DMat2::IDENTITY);
        dd.a.x_axis.x = bad;
        let v = tr.step(&dd, vh);
        assert_eq!(v, DMat2::IDENTITY * MAX_VARIANCE);
        let v = tr.step(&d(DMat2::IDENTITY), vh);
        assert!(finite_psd_bounded(v));
        let mut tr = FootprintTracker::start(var1);
        let v = tr.step(&d(DMat2::IDENTITY), DMat2::IDENTITY * bad);
        assert_eq!(v, DMat2::IDENTITY * MAX_VARIANCE);
    }
    // Non-finite start.
    let tr = FootprintTracker::start(DMat2::IDENTITY * f64::NAN);
    assert!(finite_psd_bounded(tr.var_current()));
    // Overflowing products (finite but huge B) are caught too.
    let mut tr = FootprintTracker::start(var1);
    let mut dd = d(DMat2::IDENTITY * 1e-300);
    dd.b = DMat2::IDENTITY * 1e300;
    let v = tr.step(&dd, vh);
    assert!(finite_psd_bounded(v));
}

#[test]
fn non_finite_vertex_loses_track_then_recovers() {
    let cam = DVec3::new(0.0, -1.0, 1.0);
    let cur = Vertex::on_plane(DVec3::ZERO, DVec3::Z);
    let mut bad = Vertex::on_plane(DVec3::new(0.0, 1.0, 1.0), -DVec3::Y);
    bad.dndu = DVec3::NAN;
    let mut tr = FootprintTracker::start_path(cam, &cur, DMat2::IDENTITY * 1e-6);
    let v = tr.advance(&bad, Scatter::Reflection, half_vector_variance(0.1));
    assert!(finite_psd_bounded(v));
    // The bad vertex's own derivatives enter only through the next constraint.
    let next = Vertex::on_plane(DVec3::new(0.0, 0.0, 2.0), -DVec3::Z);
    let v = tr.advance(&next, Scatter::Reflection, half_vector_variance(0.1));
    assert_eq!(v, DMat2::IDENTITY * MAX_VARIANCE);
    let next2 = Vertex::on_plane(DVec3::new(0.0, 2.0, 2.0), -DVec3::Y);
    let v = tr.advance(&next2, Scatter::Reflection, half_vector_variance(0.1));
    assert!(finite_psd_bounded(v));
}

#[test]
fn alpha_zero_chain_with_zero_start_stays_zero() {
    let cam = DVec3::new(0.0, -1.0, 1.0);
    let a = Vertex::on_plane(DVec3::ZERO, DVec3::Z);
    let b = Vertex::on_plane(DVec3::new(0.0, 1.0, 1.0), DVec3::new(0.0, -1.0, -0.2));
    let c = Vertex::on_plane(DVec3::new(0.0, -0.5, 2.0), DVec3::new(0.1, 0.3, -1.0));
    let mut tr = FootprintTracker::start_path(cam, &a, DMat2::ZERO);
    for v in [&b, &c] {
        let cov = tr.advance(v, Scatter::Reflection, half_vector_variance(0.0));
        assert_eq!(cov, DMat2::ZERO);
        let f = VertexFootprint::new(cov, v);
        assert_eq!(f.world, glam::DMat3::ZERO);
        assert_eq!(f.uv, DMat2::ZERO);
        assert_eq!(f.lod(1024.0), LOD_MIN);
    }
}

#[test]
fn enormous_inputs_are_clamped() {
    let cam = DVec3::new(0.0, -1.0, 1.0);
    let a = Vertex::on_plane(DVec3::ZERO, DVec3::Z);
    let far = Vertex::on_plane(DVec3::new(0.0, 1.0, 1.0) * 1e20, DVec3::new(0.0, -1.0, -1.0));
    let mut tr = FootprintTracker::start_path(cam, &a, DMat2::IDENTITY * 1e-6);
    let v = tr.advance(&far, Scatter::Reflection, half_vector_variance(1e30));
    assert!(finite_psd_bounded(v));
    assert!(major(v) > 0.99 * MAX_VARIANCE);
    let f = VertexFootprint::new(v, &far);
    assert!(f.world.is_finite());
    assert_eq!(f.lod(1e6), LOD_MAX);
    // Roughness inputs.
    assert_eq!(half_vector_variance(f64::INFINITY), half_vector_variance(MAX_ALPHA));
    assert_eq!(half_vector_variance(f64::NAN), half_vector_variance(MAX_ALPHA));
    assert_eq!(half_vector_variance(-1.0), DMat2::ZERO);
    assert_eq!(ggx_to_beckmann_alpha(f32::NAN), MAX_ALPHA as f32);
    assert_eq!(ggx_to_beckmann_alpha(f32::INFINITY), MAX_ALPHA as f32);
    assert_eq!(ggx_to_beckmann_alpha(-0.5), 0.0);
    assert!(half_vector_variance_aniso(DVec2::new(f64::NAN, 0.1)).is_finite());
}

/// An index-matched refraction (eta = 1) has no half vector; with the clamp it behaves as
/// straight propagation (roughness barely deflects the path), matching the footprint of the
/// same ray transferred directly.
#[test]
fn index_matched_refraction_is_straight_propagation() {
    let cam = DVec3::new(0.0, -4.0, 3.0);
    let dir = (DVec3::ZERO - cam).normalize();
    let right = DVec3::X * 1e-3;
    let up = dir.cross(DVec3::X) * 1e-3;
    let first = Vertex::on_plane(DVec3::ZERO, DVec3::new(0.2, -0.1, 1.0));
    let second = Vertex::on_plane(dir * 2.0, DVec3::new(-0.3, 0.2, 1.0));
    let var1 = first_vertex_variance(cam, dir, right, up, &first);
    let direct = first_vertex_variance(cam, dir, right, up, &second);
    for eta in [1.0, 1.0 + 1e-7, 1.0 - 1e-7] {
        let mut tr = FootprintTracker::start_path(cam, &first, var1);
        let v = tr.advance(&second, Scatter::Refraction { eta }, half_vector_variance(0.5));
        assert!(finite_psd_bounded(v));
        let e = crate::common::rel_err(v, direct);
        eprintln!("index-matched eta {eta}: relative error to straight transfer {e:e}");
        assert!(e < 1e-2, "eta {eta}: {e}");
    }
    assert_eq!(effective_eta(1.0), 1.0 + MIN_ETA_OFFSET);
    assert_eq!(effective_eta(f64::NAN), 1.0 + MIN_ETA_OFFSET);
    assert_eq!(effective_eta(1.5), 1.5);
}

#[test]
fn vanishing_half_vector_and_coincident_vertices() {
    let a = Vertex::on_plane(DVec3::ZERO, DVec3::Z);
    // Reflection with the next vertex straight behind: ω_o = −ω_i, h = 0.
    let prev = Vertex::point(DVec3::new(0.0, -1.0, 1.0));
    let next = Vertex::on_plane(DVec3::new(0.0, 1.0, -1.0), DVec3::Y);
    let d = constraint_derivatives(&prev, &a, &next, Scatter::Reflection);
    assert!(d.is_finite());
    let mut tr = FootprintTracker::start_path(prev.p, &a, DMat2::IDENTITY * 1e-6);
    assert!(finite_psd_bounded(tr.advance(&next, Scatter::Reflection, half_vector_variance(0.2))));
    // Half vector in the tangent plane (h·n = 0).
    let prev = Vertex::point(DVec3::new(-1.0, 0.0, 0.0));
    let next = Vertex::on_plane(DVec3::new(0.0, 1.0, 0.0), -DVec3::Y);
    let d = constraint_derivatives(&prev, &a, &next, Scatter::Reflection);
    assert!(d.is_finite());
    let s = half_vector_slope(prev.p, &a, next.p, Scatter::Reflection);
    assert!(s.is_finite() && s.length() <= 1.5 / MIN_COSINE);
    // Coincident vertices.
    let same = Vertex::point(DVec3::ZERO);
    let d = constraint_derivatives(&same, &a, &a, Scatter::Refraction { eta: 1.5 });
    assert!(d.is_finite());
    let mut tr = FootprintTracker::start_path(DVec3::ZERO, &a, DMat2::IDENTITY);
    assert!(finite_psd_bounded(tr.advance(&a, Scatter::Reflection, half_vector_variance(1.0))));
}

#[test]
fn degenerate_uv_mappings() {
    let n = DVec3::Z;
    let (t, b) = orthonormal_basis(n);
    let base = Vertex::on_plane(DVec3::ZERO, n);
    let cov = DMat2::from_cols(DVec2::new(2e-4, 5e-5), DVec2::new(5e-5, 1e-4));
    let cases = [
        ("pole: dpdu = 0", DVec3::ZERO, b * 0.5),
        ("parallel", t, t * 2.0),
        ("both zero", DVec3::ZERO, DVec3::ZERO),
        ("nearly parallel", t, t * 2.0 + b * 1e-12),
        ("sliver", t, b * 1e-9),
    ];
    for (name, dpdu, dpdv) in cases {
        let v = Vertex { dpdu, dpdv, dndu: dpdu * 0.3, dndv: dpdv * 0.3, ..base };
        let l = v.local();
        assert!(l.shape.is_finite() && l.uv_jacobian.is_finite(), "{name}");
        // Tangent-plane components of the tangent map stay the identity.
        assert!((l.tangent_map[0] - t).length() < 1e-12, "{name}");
        assert!((l.tangent_map[1] - b).length() < 1e-12, "{name}");
        let uv = uv_covariance(cov, &v);
        assert!(finite_psd_bounded(uv), "{name}: {uv:?}");
        let lod = lod(uv, 512.0);
        assert!(lod.is_finite() && (LOD_MIN..=LOD_MAX).contains(&lod), "{name}");
        if dpdu == DVec3::ZERO && dpdv == DVec3::ZERO {
            assert_eq!(uv, DMat2::ZERO);
            assert_eq!(l.shape, DMat2::ZERO);
        } else {
            // The clamp caps the uv Jacobian at 1/UV_CONDITION_LIMIT times the best direction.
            let best = dpdu.length().max(dpdv.length());
            assert!(major(uv) <= major(cov) / (UV_CONDITION_LIMIT * best).powi(2) * 1.0001);
            // Continuity: the degenerate direction is large, not dropped.
            assert!(major(uv) > 1e6 * major(cov), "{name}: {uv:?}");
        }
    }
}

#[test]
fn grazing_camera_rays_are_clamped() {
    let hit = Vertex::on_plane(DVec3::ZERO, DVec3::Z);
    let cam = DVec3::new(0.0, -5.0, 0.0);
    let d_px = DVec3::X * 1e-3;
    let d_py = DVec3::Z * 1e-3;
    for tilt in [0.0, 1e-9, 1e-6, 1e-3] {
        let dir = rotate(DVec3::Y, DVec3::X, -tilt);
        let v = first_vertex_variance(cam, dir, d_px, d_py, &hit);
        assert!(finite_psd_bounded(v), "tilt {tilt}");
        // along-ray stretch ≤ distance · pixel angle / MIN_COSINE (σ = ½ px)
        let bound = (5.0 * 1e-3 / MIN_COSINE * 0.5).powi(2) * 1.01;
        assert!(major(v) <= bound, "tilt {tilt}: {} > {bound}", major(v));
    }
    // Degenerate direction.
    let v = first_vertex_variance(cam, DVec3::ZERO, d_px, d_py, &hit);
    assert!(finite_psd_bounded(v));
    let j = first_vertex_jacobian(cam, DVec3::NAN, d_px, d_py, &hit);
    assert!(j.is_finite());
}

#[test]
fn lod_clamps() {
    let iso = |s: f64| DMat2::IDENTITY * (s * s);
    assert!((lod(iso(1.0 / 256.0), 1024.0) - 2.0).abs() < 1e-6);
    assert_eq!(lod(DMat2::ZERO, 1024.0), LOD_MIN);
    assert_eq!(lod(iso(1e-30), 1.0), LOD_MIN);
    assert_eq!(lod(iso(1e30), 1.0), LOD_MAX);
    assert_eq!(lod(DMat2::IDENTITY * f64::INFINITY, 1.0), LOD_MAX);
    assert_eq!(lod(DMat2::IDENTITY * f64::NAN, 1.0), LOD_MAX);
    assert_eq!(lod(iso(0.1), f64::NAN), LOD_MAX);
    assert_eq!(lod(iso(0.1), 0.0), LOD_MIN);
    assert_eq!(lod(iso(0.1), -5.0), LOD_MIN);
    assert_eq!(lod(iso(0.1), f64::INFINITY), LOD_MAX);
    assert_eq!(lod(DMat2::ZERO, f64::INFINITY), LOD_MAX);
    // Negative (non-PSD) input counts as zero.
    assert_eq!(lod(DMat2::IDENTITY * -1.0, 64.0), LOD_MIN);
}

#[test]
fn estimators_stay_finite() {
    let hit = Vertex::on_plane(DVec3::ZERO, DVec3::Z);
    let cam = DVec3::new(0.0, -5.0, 1e-12);
    let dir = (hit.p - cam).normalize();
    let mut cone = RayCone::new(cam, dir, 1e-3);
    let v = cone.advance(&hit);
    assert!(finite_psd_bounded(v));
    cone.scatter(&hit, DVec3::new(0.0, 1.0, 1e-12).normalize(), Scatter::Refraction { eta: f64::NAN });
    assert!(cone.width.is_finite() && cone.spread.is_finite());
    let mut p = PbrtDifferentials::new(cam, dir, DVec3::X * 1e-3, DVec3::Z * 1e-3, 1e-3, 1.0);
    assert!(finite_psd_bounded(p.advance(&hit)));
    // Grazing refraction into a denser medium and total internal reflection drop nothing
    // unexpectedly and never produce NaN.
    p.scatter_specular(&hit, DVec3::Y, Scatter::Refraction { eta: 1.0 / 1.5 });
    assert!(!p.has_differentials());
    let next = Vertex::on_plane(DVec3::new(0.0, 3.0, 0.0), -DVec3::Y);
    assert!(finite_psd_bounded(p.advance(&next)));
    // Huge differentials are dropped as in pbrt-v4.
    let mut p = PbrtDifferentials::new(cam, dir, DVec3::X * 1e9, DVec3::Z, 1e-3, 1.0);
    assert!(!p.has_differentials());
    assert!(finite_psd_bounded(p.advance(&hit)));
}
