//! Micro-benchmarks of the per-bounce footprint updates.
//!
//! The vertex sequence is a real path: rays traced (in this file, analytically) through a closed
//! box of six planes with skewed uv parameterisations and three spheres with spherical uv
//! (curved: `dndu, dndv ≠ 0`), reflecting about half vectors a little off the normal (glossy
//! bounces). Every path has [`BOUNCES`] bounces after its first hit; path-shaped benchmarks
//! report a throughput of `BOUNCES` elements per iteration, so criterion's `time / BOUNCES` (or
//! `1 / thrpt`) is the cost of one bounce, the path's start included (see `start_path` for that).
//!
//! `cargo bench -p footprint --bench tracker` takes well under a minute (2 s per benchmark).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use footprint::{
    constraint_derivatives, first_vertex_variance, half_vector_variance, lod, ConstraintDerivatives, FootprintTracker,
    PbrtDifferentials, RayCone, Scatter, Vertex, VertexFootprint,
};
use glam::{DMat2, DVec2, DVec3};
use std::f64::consts::PI;
use std::hint::black_box;
use std::time::Duration;

/// Bounces per benchmarked path (vertices x₁ … x_{BOUNCES+1}).
const BOUNCES: usize = 8;

#[derive(Clone, Copy)]
enum Surface {
    /// Inward-facing wall of the box `|x|, |y|, |z| ≤ 5`: axis and sign of its inward normal.
    Wall {
        axis: usize,
        sign: f64,
    },
    Sphere {
        c: DVec3,
        r: f64,
    },
}

const SURFACES: [Surface; 9] = [
    Surface::Wall { axis: 0, sign: 1.0 },
    Surface::Wall { axis: 0, sign: -1.0 },
    Surface::Wall { axis: 1, sign: 1.0 },
    Surface::Wall { axis: 1, sign: -1.0 },
    Surface::Wall { axis: 2, sign: 1.0 },
    Surface::Wall { axis: 2, sign: -1.0 },
    Surface::Sphere { c: DVec3::new(-1.5, -3.0, 0.5), r: 2.0 },
    Surface::Sphere { c: DVec3::new(2.5, 1.0, -2.0), r: 1.2 },
    Surface::Sphere { c: DVec3::new(0.5, 2.5, 2.5), r: 1.5 },
];

fn intersect(s: &Surface, o: DVec3, d: DVec3) -> Option<f64> {
    match *s {
        Surface::Wall { axis, sign } => {
            // The wall sits at coordinate −5·sign (its normal points inwards, along +sign).
            let t = (-5.0 * sign - o[axis]) / d[axis];
            (t > 1e-9).then_some(t)
        }
        Surface::Sphere { c, r } => {
            let oc = o - c;
            let b = oc.dot(d);
            let disc = b * b - (oc.length_squared() - r * r);
            if disc < 0.0 {
                return None;
            }
            let t = -b - disc.sqrt();
            (t > 1e-9).then_some(t)
        }
    }
}

/// The vertex the renderer would describe at `p` on `s`.
fn vertex_on(s: &Surface, p: DVec3) -> Vertex {
    match *s {
        Surface::Wall { axis, sign } => {
            let mut n = DVec3::ZERO;
            n[axis] = sign;
            let (t, b) = footprint::orthonormal_basis(n);
            // A skewed, anisotropic uv mapping (as on a stretched texture).
            let dpdu = t * 2.0 + b * 0.3;
            let dpdv = b * 1.5;
            let uv = DVec2::new(p.dot(t) * 0.5, p.dot(b) / 1.5);
            Vertex { p, n, t, b, dpdu, dpdv, dndu: DVec3::ZERO, dndv: DVec3::ZERO, uv }
        }
        Surface::Sphere { c, r } => {
            let n = (p - c) / r;
            let theta = n.z.clamp(-1.0, 1.0).acos();
            let phi = n.y.atan2(n.x);
            let (sp, cp) = phi.sin_cos();
            let (st, ct) = theta.sin_cos();
            let dpdu = DVec3::new(-st * sp, st * cp, 0.0) * (2.0 * PI * r);
            let dpdv = DVec3::new(ct * cp, ct * sp, -st) * (PI * r);
            let t = dpdu.normalize();
            let b = n.cross(t);
            let uv = DVec2::new(phi / (2.0 * PI), theta / PI);
            Vertex { p, n, t, b, dpdu, dpdv, dndu: dpdu / r, dndv: dpdv / r, uv }
        }
    }
}

/// A traced path: camera, vertices, and per bounce the event and `var(Δh)`.
struct PathData {
    camera: DVec3,
    dir: DVec3,
    ddx: DVec3,
    ddy: DVec3,
    vertices: Vec<Vertex>,
    var_h: Vec<DMat2>,
    dirs: Vec<DVec3>,
    derivs: Vec<ConstraintDerivatives>,
}

/// Traces one path from the camera with a deterministic glossy jitter per bounce.
fn trace(seed: usize) -> PathData {
    let camera = DVec3::new(0.3, -0.2, 4.5);
    let k = seed as f64;
    let dir = DVec3::new(0.15 * (k * 1.3).sin(), 0.2 * (k * 0.7).cos(), -1.0);
    // Camera differentials of the unnormalised direction: about 1 mrad per pixel.
    let (ddx, ddy) = (DVec3::X * 1e-3, DVec3::Y * 1e-3);
    let alphas = [0.1, 0.3, 1.0, 0.05, 0.2, 0.6, 0.15, 0.4];
    let (mut o, mut d) = (camera, dir.normalize());
    let mut vertices = Vec::new();
    let mut dirs = Vec::new();
    while vertices.len() < BOUNCES + 1 {
        let (t, s) = SURFACES
            .iter()
            .filter_map(|s| intersect(s, o, d).map(|t| (t, s)))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .expect("the box is closed");
        let p = o + d * t;
        let v = vertex_on(s, p);
        // Reflect about a half vector a little off the normal (towards the inside).
        let i = vertices.len() as f64 + k;
        let n = if v.n.dot(d) > 0.0 { -v.n } else { v.n };
        let h = (n + v.t * (0.2 * (i * 2.1).sin()) + v.b * (0.2 * (i * 1.7).cos())).normalize();
        let mut nd = d - h * (2.0 * d.dot(h));
        if nd.dot(n) < 0.2 {
            // Keep away from grazing: lift the direction off the surface.
            nd = (nd + n * (0.3 - nd.dot(n))).normalize();
        }
        vertices.push(v);
        dirs.push(nd);
        o = p;
        d = nd;
    }
    let var_h: Vec<DMat2> = (0..BOUNCES).map(|i| half_vector_variance(alphas[i % alphas.len()])).collect();
    let cam_v = Vertex::point(camera);
    let derivs = (0..BOUNCES)
        .map(|i| {
            let prev = if i == 0 { &cam_v } else { &vertices[i - 1] };
            constraint_derivatives(prev, &vertices[i], &vertices[i + 1], Scatter::Reflection)
        })
        .collect();
    PathData { camera, dir, ddx, ddy, vertices, var_h, dirs, derivs }
}

fn config() -> Criterion {
    Criterion::default()
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(50)
}

fn benches(c: &mut Criterion) {
    let paths: Vec<PathData> = (0..16).map(trace).collect();
    let var1: Vec<DMat2> =
        paths.iter().map(|p| first_vertex_variance(p.camera, p.dir, p.ddx, p.ddy, &p.vertices[0])).collect();
    // The path's footprints (for the boundary benchmark) and a sanity check: no path is lost or
    // clamped (footprints do get large: diffuse bounces followed by convex mirrors).
    let mut footprints = Vec::new();
    for (p, v1) in paths.iter().zip(&var1) {
        let mut t = FootprintTracker::start_path(p.camera, &p.vertices[0], *v1);
        for i in 0..BOUNCES {
            let v = t.advance(&p.vertices[i + 1], Scatter::Reflection, p.var_h[i]);
            let big = v.x_axis.x.max(v.y_axis.y);
            assert!(v.is_finite() && v.determinant() > 0.0 && big < 1e12, "bounce {i}: {v:?}");
            footprints.push((v, p.vertices[i + 1]));
        }
    }

    let mut g = c.benchmark_group("per_bounce");
    g.throughput(Throughput::Elements(BOUNCES as u64));
    let mut which = 0usize;
    g.bench_function("tracker_advance", |b| {
        b.iter(|| {
            which = (which + 1) % paths.len();
            let p = &paths[which];
            let mut t = FootprintTracker::start_path(p.camera, &p.vertices[0], var1[which]);
            for i in 0..BOUNCES {
                black_box(t.advance(black_box(&p.vertices[i + 1]), Scatter::Reflection, p.var_h[i]));
            }
            t
        })
    });
    g.bench_function("tracker_step", |b| {
        b.iter(|| {
            which = (which + 1) % paths.len();
            let p = &paths[which];
            let mut t = FootprintTracker::start(var1[which]);
            for i in 0..BOUNCES {
                black_box(t.step(black_box(&p.derivs[i]), p.var_h[i]));
            }
            t
        })
    });
    g.bench_function("constraint_derivatives", |b| {
        b.iter(|| {
            which = (which + 1) % paths.len();
            let p = &paths[which];
            let mut acc = DMat2::ZERO;
            for i in 0..BOUNCES {
                let prev = if i == 0 { Vertex::point(p.camera) } else { p.vertices[i - 1] };
                let d = constraint_derivatives(
                    &prev,
                    black_box(&p.vertices[i]),
                    black_box(&p.vertices[i + 1]),
                    Scatter::Reflection,
                );
                acc += d.c;
            }
            acc
        })
    });
    g.bench_function("raycone", |b| {
        b.iter(|| {
            which = (which + 1) % paths.len();
            let p = &paths[which];
            let mut cone = RayCone::new(p.camera, p.dir, 1e-3);
            black_box(cone.advance(&p.vertices[0]));
            for i in 0..BOUNCES {
                cone.scatter(black_box(&p.vertices[i]), p.dirs[i], Scatter::Reflection);
                black_box(cone.advance(black_box(&p.vertices[i + 1])));
            }
            cone
        })
    });
    g.bench_function("pbrt_specular", |b| {
        b.iter(|| {
            which = (which + 1) % paths.len();
            let p = &paths[which];
            let mut d = PbrtDifferentials::new(p.camera, p.dir, p.ddx, p.ddy, 1e-3, 1.0);
            black_box(d.advance(&p.vertices[0]));
            for i in 0..BOUNCES {
                d.scatter_specular(black_box(&p.vertices[i]), p.dirs[i], Scatter::Reflection);
                black_box(d.advance(black_box(&p.vertices[i + 1])));
            }
            d
        })
    });
    g.bench_function("pbrt_rough", |b| {
        b.iter(|| {
            which = (which + 1) % paths.len();
            let p = &paths[which];
            let mut d = PbrtDifferentials::new(p.camera, p.dir, p.ddx, p.ddy, 1e-3, 1.0);
            black_box(d.advance(&p.vertices[0]));
            for i in 0..BOUNCES {
                d.scatter_rough(black_box(&p.vertices[i]), p.dirs[i]);
                black_box(d.advance(black_box(&p.vertices[i + 1])));
            }
            d
        })
    });
    g.finish();

    let mut g = c.benchmark_group("per_call");
    g.bench_function("start_path", |b| {
        b.iter(|| {
            which = (which + 1) % paths.len();
            let p = &paths[which];
            FootprintTracker::start_path(black_box(p.camera), black_box(&p.vertices[0]), var1[which])
        })
    });
    g.bench_function("first_vertex_variance", |b| {
        b.iter(|| {
            which = (which + 1) % paths.len();
            let p = &paths[which];
            first_vertex_variance(black_box(p.camera), black_box(p.dir), p.ddx, p.ddy, black_box(&p.vertices[0]))
        })
    });
    g.bench_function("vertex_local", |b| {
        b.iter(|| {
            which = (which + 1) % footprints.len();
            black_box(&footprints[which].1).local()
        })
    });
    g.bench_function("footprint_new_lod", |b| {
        b.iter(|| {
            which = (which + 1) % footprints.len();
            let (cov, v) = &footprints[which];
            let fp = VertexFootprint::new(black_box(*cov), black_box(v));
            fp.lod(black_box(1024.0))
        })
    });
    g.bench_function("lod", |b| {
        b.iter(|| {
            which = (which + 1) % footprints.len();
            lod(black_box(footprints[which].0), black_box(1024.0))
        })
    });
    // One advance with the tracker state restored each time (copying it costs a little).
    g.bench_function("tracker_advance_single", |b| {
        let p = &paths[3];
        let mut t = FootprintTracker::start_path(p.camera, &p.vertices[0], var1[3]);
        t.advance(&p.vertices[1], Scatter::Reflection, p.var_h[0]);
        b.iter_batched(
            || t,
            |mut t| t.advance(black_box(&p.vertices[2]), Scatter::Reflection, p.var_h[1]),
            BatchSize::SmallInput,
        )
    });
    g.finish();
}

criterion_group! {
    name = tracker;
    config = config();
    targets = benches
}
criterion_main!(tracker);
