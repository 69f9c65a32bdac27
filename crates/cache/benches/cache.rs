//! Benchmarks of the tile cache. Throughputs are per lookup (`hit/*`, `tile_size/*`,
//! `eviction/*`, `in_flight/*`) or per texel filled (`fill/*`), so criterion's `thrpt` (or
//! `time / elements`) reads directly as the cost the report quotes.
//!
//! - `hit/{trilinear,anisotropic}/{coherent,random}/{micro64,micro64-f16,micro4,micro0,nocount}`:
//!   lookups on a warm cache (every tile resident), f32 texels unless named (renders store f16).
//!   `coherent`: a scanline walk (neighbouring lookups share tiles); `random`: uniform uv over
//!   64×64 level-0 tiles (the micro-cache rarely helps). Each variant also through a
//!   [`cache::Reader`] (`…-reader`), the per-thread handle renders use.
//! - `fill/*`: lookups that each fill one new tile with a trivial fill function, per texel:
//!   the cache's own cost of filling (requests, rounding, stores, allocation, eviction).
//! - `tile_size/T`: a render-like trace (camera scanlines plus scattered secondary lookups) with
//!   a fill of ~100 ns per texel, under a budget that forces eviction, for T = 8, 16, 32, 64.
//! - `eviction/{clock,fifo}`: the same trace under a tighter budget.
//! - `in_flight/{wait,evaluate}`: two threads interleaving that trace on a cold cache.
//!
//! `cargo bench -p cache` takes about a minute on two cores.

use std::hint::black_box;
use std::time::Duration;

use cache::{CacheConfig, Eviction, Filter, InFlight, TexelFormat, TexelRequest, TextureDesc, TextureId, TileCache};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::{Mat2, Vec2};

struct Rng(u64);

impl Rng {
    fn f32(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// One lookup: centre, covariance, filter.
type Query = (Vec2, Mat2, Filter);

const D0: f32 = 256.0;

fn desc(format: TexelFormat) -> TextureDesc {
    TextureDesc { channels: 3, format, texels_per_uv: D0, max_level: 10 }
}

fn cache(config: CacheConfig, format: TexelFormat) -> (TileCache, TextureId) {
    let mut c = TileCache::new(config).unwrap();
    let id = c.add_texture(desc(format)).unwrap();
    (c, id)
}

/// Footprint of σ = `texels` level-0 texels along the major axis, anisotropy `ratio`.
fn cov(texels: f32, ratio: f32, angle: f32) -> Mat2 {
    let s1 = texels / D0;
    let s2 = s1 / ratio;
    let r = Mat2::from_angle(angle);
    r * Mat2::from_diagonal(Vec2::new(s1 * s1, s2 * s2)) * r.transpose()
}

/// Cheap fill (not a constant, so nothing is hoisted).
fn cheap(r: TexelRequest) -> [f32; 3] {
    [r.uv.x, r.uv.y, r.texel_size]
}

/// A fill costing about 100 ns per texel: eight plane waves, like a small noise graph.
fn costly(r: TexelRequest) -> [f32; 3] {
    let mut v = 0.0f32;
    for k in 0..8 {
        let f = 1.7f32.powi(k) * 0.5;
        let a = k as f32 * 0.77;
        v += (f * (r.uv.x * a.cos() + r.uv.y * a.sin()) * std::f32::consts::TAU).sin()
            * (-f * f * r.texel_size * r.texel_size).exp();
    }
    [v, v * 0.5, 1.0]
}

fn hit_queries(coherent: bool, filter: Filter) -> Vec<Query> {
    let mut rng = Rng(0x5EED);
    (0..1024)
        .map(|k| {
            let uv = if coherent {
                Vec2::new(0.25 + (k % 64) as f32 * 0.6 / D0, 0.25 + (k / 64) as f32 * 0.6 / D0)
            } else {
                Vec2::new(rng.f32() * 4.0, rng.f32() * 4.0) // 64×64 level-0 tiles of 16
            };
            (uv, cov(1.0 + 2.0 * rng.f32(), 1.0 + 3.0 * rng.f32(), rng.f32() * 3.0), filter)
        })
        .collect()
}

fn run(c: &TileCache, id: TextureId, queries: &[Query], fill: &(impl Fn(TexelRequest) -> [f32; 3] + ?Sized)) -> f32 {
    queries.iter().map(|&(uv, cov, f)| c.lookup(id, uv, cov, f, fill)[0]).sum()
}

fn run_reader(
    r: &cache::Reader,
    id: TextureId,
    queries: &[Query],
    fill: &(impl Fn(TexelRequest) -> [f32; 3] + ?Sized),
) -> f32 {
    queries.iter().map(|&(uv, cov, f)| r.lookup(id, uv, cov, f, fill)[0]).sum()
}

fn hits(crit: &mut Criterion) {
    let mut g = crit.benchmark_group("hit");
    for (name, filter) in [("trilinear", Filter::TRILINEAR), ("anisotropic", Filter::anisotropic(8.0))] {
        for coherent in [true, false] {
            let q = hit_queries(coherent, filter);
            g.throughput(Throughput::Elements(q.len() as u64));
            for (variant, micro_cache, count_requests, format) in [
                ("micro64", 64, true, TexelFormat::F32),
                ("micro64-f16", 64, true, TexelFormat::F16),
                ("micro4", 4, true, TexelFormat::F32),
                ("micro0", 0, true, TexelFormat::F32),
                ("nocount", 64, false, TexelFormat::F32),
            ] {
                let config = CacheConfig { micro_cache, count_requests, ..CacheConfig::with_budget(1 << 30) };
                let (c, id) = cache(config, format);
                run(&c, id, &q, &cheap);
                let fills = c.stats().total().fills;
                let pattern = if coherent { "coherent" } else { "random" };
                g.bench_function(BenchmarkId::new(format!("{name}/{pattern}"), variant), |b| {
                    b.iter(|| black_box(run(&c, id, &q, &cheap)))
                });
                let reader = c.reader();
                g.bench_function(BenchmarkId::new(format!("{name}/{pattern}"), format!("{variant}-reader")), |b| {
                    b.iter(|| black_box(run_reader(&reader, id, &q, &cheap)))
                });
                drop(reader);
                assert_eq!(c.stats().total().fills, fills, "hit benchmark missed");
            }
        }
    }
    g.finish();
}

fn fills(crit: &mut Criterion) {
    let mut g = crit.benchmark_group("fill");
    for (t, format) in [
        (8, TexelFormat::F32),
        (16, TexelFormat::F32),
        (32, TexelFormat::F32),
        (64, TexelFormat::F32),
        (16, TexelFormat::F16),
    ] {
        let config = CacheConfig { tile_size: t, ..CacheConfig::with_budget(4 << 20) };
        let (c, id) = cache(config, format);
        let texels = u64::from((t + 1) * (t + 1));
        g.throughput(Throughput::Elements(texels));
        let mut x = 0u64;
        let point = Filter::TRILINEAR.levels(0, 0);
        g.bench_function(BenchmarkId::new(format!("{format:?}"), t), |b| {
            b.iter(|| {
                // A new tile every time: walk level 0's tiles in a long row (and wrap far away).
                x += 1;
                let uv = Vec2::new(((x % 1_000_000) * u64::from(t)) as f32 / D0, (x / 1_000_000) as f32);
                black_box(c.lookup(id, uv, Mat2::ZERO, point, &cheap))
            })
        });
        let s = c.stats().total();
        assert_eq!(s.fills, s.misses, "every fill benchmark lookup fills");
    }
    g.finish();
}

/// A render-like trace: a 192×192 camera image in scanlines (footprints growing with depth,
/// moderately anisotropic), and after every camera lookup a scattered secondary lookup at a
/// coarser level, as a glossy or diffuse bounce would make.
fn trace() -> Vec<Query> {
    let mut rng = Rng(0xC0FFEE);
    let n = 192;
    let mut q = Vec::with_capacity(2 * n * n);
    for y in 0..n {
        for x in 0..n {
            let depth = 1.0 + 3.0 * y as f32 / n as f32;
            let uv = Vec2::new((x as f32 / n as f32 - 0.5) * depth * 2.0 + 2.0, depth * 1.5);
            let px = 2.0 * depth / n as f32 * D0; // one pixel in level-0 texels
            q.push((uv, cov(0.5 * px * depth, depth, 1.57), Filter::anisotropic(8.0)));
            let uv2 = Vec2::new(rng.f32() * 4.0, rng.f32() * 4.0);
            q.push((uv2, cov((2.0 + 5.0 * rng.f32()).exp2(), 1.0, 0.0), Filter::TRILINEAR));
        }
    }
    q
}

fn trace_config(tile_size: u32, budget: usize) -> CacheConfig {
    CacheConfig { tile_size, ..CacheConfig::with_budget(budget) }
}

fn tile_sizes(crit: &mut Criterion) {
    let q = trace();
    let mut g = crit.benchmark_group("tile_size");
    g.throughput(Throughput::Elements(q.len() as u64));
    for t in [8, 16, 32, 64] {
        let (c, id) = cache(trace_config(t, 3 << 20), TexelFormat::F16);
        g.bench_function(BenchmarkId::from_parameter(t), |b| b.iter(|| black_box(run(&c, id, &q, &costly))));
        report(&format!("tile_size/{t}"), &c, q.len());
    }
    g.finish();
}

fn evictions(crit: &mut Criterion) {
    let q = trace();
    let mut g = crit.benchmark_group("eviction");
    g.throughput(Throughput::Elements(q.len() as u64));
    for (name, eviction) in [("clock", Eviction::Clock), ("fifo", Eviction::Fifo)] {
        let config = CacheConfig { eviction, ..trace_config(16, 1 << 20) };
        let (c, id) = cache(config, TexelFormat::F16);
        g.bench_function(name, |b| b.iter(|| black_box(run(&c, id, &q, &costly))));
        report(&format!("eviction/{name}"), &c, q.len());
    }
    g.finish();
}

fn in_flight(crit: &mut Criterion) {
    let q = trace();
    let mut g = crit.benchmark_group("in_flight");
    g.throughput(Throughput::Elements(q.len() as u64));
    for (name, in_flight) in [("wait", InFlight::Wait), ("evaluate", InFlight::Evaluate)] {
        let config = CacheConfig { in_flight, ..trace_config(16, 64 << 20) };
        let mut last = None;
        g.bench_function(name, |b| {
            b.iter(|| {
                let (c, id) = cache(config, TexelFormat::F16); // cold every time
                std::thread::scope(|s| {
                    for k in 0..2 {
                        let (c, q) = (&c, &q);
                        s.spawn(move || {
                            // Pixel k, k + 2, …: each thread takes every other camera lookup with
                            // its secondary, so both want the same tiles at the same time.
                            let mine: Vec<Query> = q.chunks(2).skip(k).step_by(2).flatten().copied().collect();
                            black_box(run(c, id, &mine, &costly))
                        });
                    }
                });
                last = Some(c.stats().total());
            })
        });
        if let Some(s) = last {
            eprintln!(
                "in_flight/{name}: fills {} waits {} direct {} texels filled {} direct {}",
                s.fills, s.waits, s.direct, s.texels_filled, s.texels_direct
            );
        }
    }
    g.finish();
}

/// Prints what a trace benchmark did, per pass.
fn report(name: &str, c: &TileCache, lookups: usize) {
    let s = c.stats();
    let t = s.total();
    let passes = s.textures[0].lookups as f64 / lookups as f64;
    eprintln!(
        "{name}: per pass: hit rate {:.3}, fills {:.0}, refills {:.0}, texels filled per lookup {:.2}, direct {:.0}; peak {} KiB",
        t.hits as f64 / t.requests as f64,
        t.fills as f64 / passes,
        t.refills as f64 / passes,
        t.texels_filled as f64 / passes / lookups as f64,
        t.direct as f64 / passes,
        s.peak_bytes >> 10
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_millis(1000));
    targets = hits, fills, tile_sizes, evictions, in_flight
}
criterion_main!(benches);
