//! ns per point of unfiltered 2D gradient noise: the graph crate's MaterialX Perlin noise (and
//! its 6-octave fractal) beside the `noise` crate's Perlin and its 6-octave fBm, over the same
//! 1024 pseudo-random points in [0, 64)², one thread. Both compute scalar f32/f64 noise per point;
//! neither is batched or vectorised here.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::Vec2;
use noise::{Fbm, MultiFractal, NoiseFn, Perlin};

fn points() -> Vec<[f64; 2]> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 64.0
    };
    (0..1024).map(|_| [next(), next()]).collect()
}

fn point_noise(c: &mut Criterion) {
    let pts = points();
    let mut group = c.benchmark_group("point_noise");
    group.sample_size(30).measurement_time(std::time::Duration::from_secs(2));
    group.throughput(Throughput::Elements(pts.len() as u64));
    group.bench_function("tessera perlin_float", |b| {
        b.iter(|| pts.iter().map(|p| graph::perlin_float(Vec2::new(p[0] as f32, p[1] as f32))).sum::<f32>())
    });
    let perlin = Perlin::new(7);
    group.bench_function("noise-rs Perlin", |b| b.iter(|| pts.iter().map(|p| perlin.get(*p)).sum::<f64>()));
    group.bench_function("tessera fractal_point 6 octaves", |b| {
        b.iter(|| pts.iter().map(|p| graph::fractal_point(Vec2::new(p[0] as f32, p[1] as f32), 6, 2.0, 0.5)).sum::<f32>())
    });
    let fbm = Fbm::<Perlin>::new(7).set_octaves(6).set_lacunarity(2.0).set_persistence(0.5);
    group.bench_function("noise-rs Fbm<Perlin> 6 octaves", |b| b.iter(|| pts.iter().map(|p| fbm.get(*p)).sum::<f64>()));
    group.finish();
}

criterion_group!(benches, point_noise);
criterion_main!(benches);
