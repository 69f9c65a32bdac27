//! Ray queries alone, on each backend: closest-hit and occlusion queries of every camera ray of
//! each reference scene (256 × 256 rays per iteration), and of as many incoherent rays leaving
//! points along those (`bounce_*`, as secondary and shadow rays do), reported as rays per second;
//! `bvh` is the built-in BVH, `embree` Embree 3 where its library loads
//! (`scripts/install-embree.sh`). Queries alone answer what whole renders on this host cannot
//! tell apart from its drift: a change of a few per cent in how rays are traced.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::Vec2;
use render::accel::{build_intersector, Backend};
use render::geometry::Intersector;
use std::path::PathBuf;

fn bvh(c: &mut Criterion) {
    let refs = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/refs/scenes");
    let mut group = c.benchmark_group("bvh");
    group.sample_size(20);
    let mut backends = vec![("bvh", Backend::Bvh), ("exhaustive", Backend::Exhaustive)];
    match render::embree::available() {
        Ok(_) => backends.push(("embree", Backend::Embree)),
        Err(e) => eprintln!("embree: not measured: {e}"),
    }
    for name in ["cbox", "textured_mesh", "dielectrics", "roughconductors"] {
        let scene = render::loader::load_file(&refs.join(format!("{name}.xml")), &[]).expect("scene loads");
        let (w, h) = (scene.camera.width, scene.camera.height);
        let rays: Vec<_> = (0..h)
            .flat_map(|y| (0..w).map(move |x| Vec2::new(x as f32 + 0.5, y as f32 + 0.5)))
            .map(|p| scene.camera.generate_ray(p).ray)
            .collect();
        // Secondary-like rays: from each camera ray's first hit (or a point along it) in a
        // scrambled direction.
        let bounce: Vec<_> = rays
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let o = r.o + r.d * (1.0 + (k % 7) as f32 * 0.3);
                let a = k as f32 * 2.399_963;
                let z = 1.0 - 2.0 * ((k * 37 % 1000) as f32 + 0.5) / 1000.0;
                let s = (1.0 - z * z).sqrt();
                render::geometry::Ray::new(o, glam::Vec3::new(s * a.cos(), s * a.sin(), z))
            })
            .collect();
        group.throughput(Throughput::Elements(rays.len() as u64));
        for (label, backend) in &backends {
            // Testing every primitive of a large mesh says nothing: small scenes only.
            let (_, primitives) = render::exhaustive::counts(&scene.shapes);
            if *backend == Backend::Exhaustive && primitives > 2 * render::exhaustive::SMALL_SCENE {
                continue;
            }
            let accel = build_intersector(&scene.shapes, *backend).expect("backend builds");
            group.bench_function(format!("{name}/{label}/closest"), |b| {
                b.iter(|| rays.iter().filter(|r| accel.intersect(&scene.shapes, r).is_some()).count())
            });
            group.bench_function(format!("{name}/{label}/occluded"), |b| {
                b.iter(|| rays.iter().filter(|r| accel.occluded(&scene.shapes, r)).count())
            });
            group.bench_function(format!("{name}/{label}/bounce_closest"), |b| {
                b.iter(|| bounce.iter().filter(|r| accel.intersect(&scene.shapes, r).is_some()).count())
            });
            group.bench_function(format!("{name}/{label}/bounce_occluded"), |b| {
                b.iter(|| bounce.iter().filter(|r| accel.occluded(&scene.shapes, r)).count())
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bvh);
criterion_main!(benches);
