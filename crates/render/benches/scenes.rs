//! Throughput on the reference scenes: one 256×256 frame at 1 spp per iteration, reported as
//! samples per second. Compare with Mitsuba's ms per spp in `../shared/refs/README.md`
//! (ms per spp = 65 536 / samples-per-second × 1000).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use render::integrator::{render, RenderSettings};
use std::path::PathBuf;

fn scenes(c: &mut Criterion) {
    let refs = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/refs/scenes");
    let mut group = c.benchmark_group("render_1spp");
    group.sample_size(10);
    for name in ["cbox", "roughconductors", "dielectrics", "textured_mesh"] {
        let scene = render::loader::load_file(&refs.join(format!("{name}.xml")), &[]).expect("scene loads");
        let pixels = scene.camera.width as u64 * scene.camera.height as u64;
        group.throughput(Throughput::Elements(pixels));
        let mut seed = 0;
        group.bench_function(name, |b| {
            b.iter(|| {
                seed += 1;
                render(&scene, RenderSettings::new(1, seed), &|_| {})
            })
        });
    }
    group.finish();
}

criterion_group!(benches, scenes);
criterion_main!(benches);
