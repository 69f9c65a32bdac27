//! The profiling render: a short render that taps every graph request and writes a
//! [`plan::Profile`] for the selective-caching model.
//!
//! Each shading point's evaluation of a material's graph is one request of that material's
//! stream. The [`Profiler`], the graph source of a profiling render, records its level and the
//! tiles a trilinear lookup of a cached node would read there (the cache crate's
//! [`cache::trilinear_taps`], the same arithmetic the lookup uses, on the textures
//! [`crate::caching::node_texture`] lays out), with touch counts, then evaluates it [`Direct`]ly;
//! the evaluator records each node's own cost per level from timed evaluations. Nothing is
//! cached while profiling, so every node of a request's plan is evaluated and timed. The
//! profile renders through the integrator's own bucket driver and pixel loop.
//!
//! The profile traces a deterministic subset of the image's pixels (`pixel_fraction`) at the
//! final render's footprints: fewer samples, the same distribution of requests per sample.

use std::collections::HashMap;
use std::time::Instant;

use cache::{CacheConfig, Filter, TexelFormat, TexelRequest, TextureDesc, TileCache, TileRef};
use graph::{EvalScratch, Filtered, Footprint, Graph, NodeId, Source};
use plan::profile::{
    CacheGeometry, LevelCost, LevelCount, LevelTiles, MachineCosts, Profile, ProfileGraph, ProfileNode, ProfileRender,
    SceneId, Stream, FINER_THAN_LEVEL0, PROFILE_SCHEMA,
};

use crate::caching::{
    channels, material_uv_bounds, means_suffice, node_texture, worth_caching, LEVEL0_TEXELS_PER_UV, MAX_LEVEL,
};
use crate::integrator::{for_each_bucket, render_pixel_with, NoObserver, RenderCounts, RenderSettings};
use crate::material::MaterialGraph;
use crate::scene::Scene;
use crate::shading::{Direct, GraphSource, TextureEvaluator};

/// Level bins: finer than level 0, then levels `0..=MAX_LEVEL`.
const BINS: usize = MAX_LEVEL as usize + 2;
/// While profiling, one evaluation in this many of each node is timed.
const PROFILE_TIMING_PERIOD: u64 = 4;
/// One request in this many is timed as a whole (evaluation and tap separately). Every one: a
/// request's cost varies 5-fold with its level, and the evaluator's per-node overhead is what
/// these timings leave after the nodes' own, so one in 16 of a profile's thousand-odd requests
/// moved it between 90 and 190 ns from run to run; three clock reads are under 1 % of a request.
const CALL_TIMING_PERIOD: u64 = 1;

/// What to profile.
#[derive(Clone, Debug)]
pub struct ProfileOptions {
    /// Render settings (spp is the profile's samples per traced pixel).
    pub settings: RenderSettings,
    /// Fraction of the pixels traced, in (0, 1].
    pub pixel_fraction: f64,
    /// Fraction of the traced pixels that take one more sample, timed but not recorded as tile
    /// reads (the warm-sample estimate of time outside textures when `spp` is 1).
    pub warm_fraction: f64,
    /// The scene's name and content hash (recorded for checks).
    pub scene: SceneId,
}

/// One stream's records on one thread.
#[derive(Clone, Debug, Default)]
struct StreamTap {
    requests: [u64; BINS],
    tiles: HashMap<TileRef, (u64, u64)>,
    /// Of `requests`, those a pixel's samples share; and of the touches per level, theirs.
    per_pixel: [u64; BINS],
    per_pixel_touches: [(u64, u64); MAX_LEVEL as usize + 1],
}

/// The graph source of a profiling render (one per image bucket): it records each request's
/// footprint level and the tiles a cached node's lookup would read, and times its direct
/// evaluation.
#[derive(Debug)]
pub struct Profiler {
    inner: Direct,
    desc: TextureDesc,
    tile_size: u32,
    streams: Vec<StreamTap>,
    /// The request under way is one a pixel's samples share.
    shared: bool,
    calls: u64,
    eval_ns: u64,
    /// The longest timed evaluation (left out of the mean when an outlier: [`graph::robust_mean`]).
    eval_max_ns: u64,
    tap_ns: u64,
    timed_calls: u64,
    /// Time every call (not one in [`CALL_TIMING_PERIOD`]) and add it to `exact_eval_ns`: set
    /// for a pixel's samples after its first.
    exact: bool,
    exact_eval_ns: u64,
    /// The warm sample under way: when it started and `exact_eval_ns` then.
    warm_start: Option<(Instant, u64)>,
    warm: Warm,
}

impl Profiler {
    fn new(streams: usize) -> Profiler {
        Profiler {
            inner: Direct,
            desc: node_texture(1),
            tile_size: CacheConfig::default().tile_size,
            streams: vec![StreamTap::default(); streams],
            shared: false,
            calls: 0,
            eval_ns: 0,
            eval_max_ns: 0,
            tap_ns: 0,
            timed_calls: 0,
            exact: false,
            exact_eval_ns: 0,
            warm_start: None,
            warm: Warm::default(),
        }
    }
}

impl GraphSource for Profiler {
    /// Records one request of `request`'s stream and evaluates it.
    fn evaluate(
        &mut self,
        g: &Graph,
        request: &MaterialGraph,
        fp: &Footprint,
        scratch: &mut EvalScratch,
        out: &mut [Filtered],
    ) {
        let timed = self.calls.is_multiple_of(CALL_TIMING_PERIOD);
        self.calls += 1;
        let t_all = self.exact.then(Instant::now);
        let t0 = timed.then(Instant::now);
        let taps = cache::trilinear_taps(&self.desc, self.tile_size, fp.uv, fp.cov);
        let b = if taps.level < 0.0 { 0 } else { (taps.lod as usize + 1).min(BINS - 1) };
        let st = &mut self.streams[request.stream as usize];
        st.requests[b] += 1;
        st.per_pixel[b] += u64::from(self.shared);
        if b > 0 && !self.exact {
            st.tiles.entry(taps.lower).or_default().0 += 1;
            if let Some(u) = taps.upper {
                st.tiles.entry(u).or_default().1 += 1;
            }
            if self.shared {
                st.per_pixel_touches[usize::from(taps.lower.level)].0 += 1;
                if let Some(u) = taps.upper {
                    st.per_pixel_touches[usize::from(u.level)].1 += 1;
                }
            }
        }
        scratch.set_bin(b);
        let t1 = timed.then(Instant::now);
        self.inner.evaluate(g, request, fp, scratch, out);
        if let (Some(t0), Some(t1)) = (t0, t1) {
            self.tap_ns += (t1 - t0).as_nanos() as u64;
            let ns = t1.elapsed().as_nanos() as u64;
            self.eval_ns += ns;
            self.eval_max_ns = self.eval_max_ns.max(ns);
            self.timed_calls += 1;
        }
        if let Some(t) = t_all {
            self.exact_eval_ns += t.elapsed().as_nanos() as u64;
        }
    }

    fn shared(&mut self, on: bool) {
        self.shared = on;
    }

    /// A pixel's samples after its first are timed whole (warm samples), their requests timed
    /// one by one and not recorded as tile reads.
    fn begin_sample(&mut self, index: u32) {
        self.exact = index > 0;
        self.warm_start = self.exact.then(|| (Instant::now(), self.exact_eval_ns));
    }

    fn end_sample(&mut self) {
        if let Some((t, before)) = self.warm_start.take() {
            let ns = t.elapsed().as_nanos() as u64;
            self.warm.outside_ns.push(ns.saturating_sub(self.exact_eval_ns - before));
        }
    }
}

impl Profiler {
    fn merge(&mut self, o: &Profiler) {
        for (a, b) in self.streams.iter_mut().zip(&o.streams) {
            for (x, y) in a.requests.iter_mut().zip(&b.requests) {
                *x += y;
            }
            for (x, y) in a.per_pixel.iter_mut().zip(&b.per_pixel) {
                *x += y;
            }
            for (x, y) in a.per_pixel_touches.iter_mut().zip(&b.per_pixel_touches) {
                *x = (x.0 + y.0, x.1 + y.1);
            }
            for (k, v) in &b.tiles {
                let e = a.tiles.entry(*k).or_default();
                e.0 += v.0;
                e.1 += v.1;
            }
        }
        self.calls += o.calls;
        self.eval_ns += o.eval_ns;
        self.eval_max_ns = self.eval_max_ns.max(o.eval_max_ns);
        self.tap_ns += o.tap_ns;
        self.timed_calls += o.timed_calls;
        self.warm.outside_ns.extend_from_slice(&o.warm.outside_ns);
    }
}

/// Whether pixel `(x, y)` is traced at `fraction` (a hash of the pixel, so the subset is spread
/// evenly and the same at any thread count).
fn traced(x: u32, y: u32, fraction: f64) -> bool {
    let mut h = (u64::from(y) << 32 | u64::from(x)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    h ^= h >> 29;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 32;
    (h >> 11) as f64 / (1u64 << 53) as f64 <= fraction
}

/// Per image bucket: its profiler, counters and the evaluator's binned timings and statistics.
type BucketProfile = (Profiler, RenderCounts, Vec<graph::BinnedTimings>, Vec<graph::EvalStats>);

/// Per sample after a pixel's first: nanoseconds outside graph evaluation. A render's samples of
/// one pixel share warm processor caches, so these, not first samples, tell the per-sample cost
/// of a render with many samples per pixel.
#[derive(Clone, Debug, Default)]
struct Warm {
    outside_ns: Vec<u64>,
}

impl Warm {
    /// Mean nanoseconds per sample, leaving out samples above 50 × the median: one-time costs
    /// (the first use of a lazily built table, a page fault) that a profile's few thousand
    /// samples would otherwise extrapolate to the whole render (seen: one 61 ms sample among
    /// 5000 of about 1 µs).
    fn robust_mean(&mut self) -> Option<f64> {
        if self.outside_ns.is_empty() {
            return None;
        }
        self.outside_ns.sort_unstable();
        let median = self.outside_ns[self.outside_ns.len() / 2];
        let kept: Vec<u64> =
            self.outside_ns.iter().copied().filter(|&t| t <= median.saturating_mul(50).max(1)).collect();
        Some(kept.iter().sum::<u64>() as f64 / kept.len().max(1) as f64)
    }
}

/// Runs the profiling render on the current rayon pool and returns the profile.
pub fn profile(scene: &Scene, opts: &ProfileOptions) -> crate::error::Result<Profile> {
    if !(opts.pixel_fraction > 0.0 && opts.pixel_fraction <= 1.0) {
        return Err(crate::error::Error::plain(format!(
            "the profiled pixel fraction must be in (0, 1], got {}",
            opts.pixel_fraction
        )));
    }
    // Calibrate first: it also brings the cores out of idle, whose slow clocks would otherwise
    // inflate the first tens of milliseconds of the profile.
    let (lookup_ns, fill_ns_per_texel, timer_ns) = calibrate();
    warm_up(scene);
    let mut t = trace(scene, opts);
    if t.samples == 0 {
        return Err(crate::error::Error::plain("the profiling render traced no samples; raise the pixel fraction"));
    }
    // Per sample outside textures, from warm samples when there are (profiles of 2+ spp).
    let outside_thread_s = t.profiler.warm.robust_mean().map_or(0.0, |ns| ns * t.samples as f64 * 1e-9);
    let tap = &t.profiler;
    let eval_ns = graph::robust_mean(tap.eval_ns, tap.timed_calls, tap.eval_max_ns).map_or(0.0, |m| m.0);
    let texture_thread_s = eval_ns * tap.calls as f64 * 1e-9;
    let tap_ns = if tap.timed_calls > 0 { tap.tap_ns as f64 / tap.timed_calls as f64 } else { 0.0 };
    let tap_thread_s = tap_ns * tap.calls as f64 * 1e-9;
    let node_overhead_ns = node_overhead_ns(&t.stats, &t.binned, texture_thread_s, timer_ns);
    let graphs = scene
        .graphs
        .iter()
        .enumerate()
        .map(|(gi, sg)| profile_graph(sg.file_name().to_string(), sg.graph(), t.binned.get(gi)))
        .collect();
    Ok(Profile {
        schema: PROFILE_SCHEMA.into(),
        scene: opts.scene.clone(),
        render: ProfileRender {
            width: scene.camera.width,
            height: scene.camera.height,
            spp: opts.settings.spp,
            scene_spp: scene.spp,
            pixel_fraction: opts.pixel_fraction,
            samples: t.samples,
            tile_samples: t.first_samples,
            threads: rayon::current_num_threads() as u32,
            wall_s: t.wall_s,
            outside_thread_s,
            texture_thread_s,
            tap_thread_s,
        },
        cache: cache_geometry()?,
        machine: MachineCosts { lookup_ns, fill_ns_per_texel, node_overhead_ns, timer_ns },
        graphs,
        streams: profile_streams(scene, tap),
    })
}

/// Evaluates every material's graphs once per level, untimed, on every thread of the pool: the
/// one-time work of a thread's first evaluations (a tiled pattern's memo, 1.7 ms on poster_wall)
/// is then done before the profile times anything, as it is before most of a final render's.
fn warm_up(scene: &Scene) {
    rayon::broadcast(|_| {
        for m in &scene.materials {
            for mg in &m.graphs {
                let g = scene.graphs[mg.graph as usize].graph();
                let mut scratch = EvalScratch::new(g);
                let mut out = vec![Filtered::zero(graph::ValueType::Float); mg.order.outputs().len()];
                let uv = glam::Vec2::new(0.375, 0.625);
                g.eval(&mg.order, &Footprint::point(uv), &mut scratch, &graph::NoOverride, &mut out);
                for level in FINER_THAN_LEVEL0..=i32::from(MAX_LEVEL) {
                    let sigma = (level as f32).exp2() / LEVEL0_TEXELS_PER_UV;
                    g.eval(&mg.order, &Footprint::isotropic(uv, sigma), &mut scratch, &graph::NoOverride, &mut out);
                }
            }
        }
    });
}

/// What the profiling render's buckets recorded, merged.
struct Traced {
    /// The merged recorder (requests, tiles, timings, warm samples).
    profiler: Profiler,
    /// Camera samples traced.
    samples: u64,
    /// Of them, each traced pixel's first (the ones recorded as tile reads).
    first_samples: u64,
    /// Per graph: the evaluator's timings per node and level bin.
    binned: Vec<graph::BinnedTimings>,
    /// Per graph: evaluation statistics.
    stats: Vec<graph::EvalStats>,
    /// Wall time of the render.
    wall_s: f64,
}

/// Renders the profile's pixels through the integrator's bucket driver with a [`Profiler`] per
/// bucket, and merges the buckets in their (fixed) order.
fn trace(scene: &Scene, opts: &ProfileOptions) -> Traced {
    let streams: usize = scene.materials.iter().map(|m| m.graphs.len()).sum();
    let (w, h) = (scene.camera.width, scene.camera.height);
    let settings = opts.settings;
    let start = Instant::now();
    let results: Vec<BucketProfile> = for_each_bucket(crate::integrator::Bucket::full(w, h), &|b| {
        let mut textures = TextureEvaluator::new(&scene.graphs, &scene.materials, Profiler::new(streams));
        for s in textures.eval_scratches_mut() {
            s.enable_binned_timing(BINS, PROFILE_TIMING_PERIOD);
        }
        let mut counts = RenderCounts::default();
        for (x, y) in b.pixels() {
            if traced(x, y, opts.pixel_fraction) {
                // A second hash (of the transposed pixel) picks the warm-timed pixels.
                let extra = u32::from(settings.spp == 1 && traced(y, x, opts.warm_fraction));
                let n = settings.spp + extra;
                render_pixel_with(scene, settings, x, y, 0..n, &mut counts, &mut textures, &mut NoObserver);
            }
        }
        let binned = textures.eval_scratches_mut().iter().map(|s| s.binned_timings().clone()).collect();
        let mut stats = Vec::new();
        textures.merge_stats_into(&mut stats);
        (textures.source, counts, binned, stats)
    })
    .into_iter()
    .map(|(_, r)| r)
    .collect();
    let wall_s = start.elapsed().as_secs_f64();
    let mut t = Traced {
        profiler: Profiler::new(streams),
        samples: 0,
        first_samples: 0,
        binned: Vec::new(),
        stats: vec![graph::EvalStats::default(); scene.graphs.len()],
        wall_s,
    };
    for (p, c, b, s) in &results {
        t.profiler.merge(p);
        t.samples += c.samples;
        t.first_samples += c.samples - p.warm.outside_ns.len() as u64;
        t.binned.resize(b.len(), graph::BinnedTimings::default());
        for (x, y) in t.binned.iter_mut().zip(b) {
            x.merge(y);
        }
        for (x, y) in t.stats.iter_mut().zip(s) {
            x.merge(y);
        }
    }
    t
}

/// The evaluator's bookkeeping per node evaluation: graph time (`texture_thread_s`) not inside
/// any node's own timed work, less the clocks' share.
fn node_overhead_ns(
    stats: &[graph::EvalStats],
    binned: &[graph::BinnedTimings],
    texture_thread_s: f64,
    timer_ns: f64,
) -> f64 {
    let (mut evaluations, mut own_s) = (0u64, 0.0);
    for (st, b) in stats.iter().zip(binned) {
        for (i, &e) in st.evaluations.iter().enumerate() {
            evaluations += e;
            // The node's mean over its bins, each bin's outlier left out as in its costs.
            let (mut ns, mut n) = (0.0, 0u64);
            for (mean, count) in (0..b.bins).filter_map(|k| b.mean_ns(i, k)) {
                ns += mean * count as f64;
                n += count;
            }
            if n > 0 {
                own_s += e as f64 * (ns / n as f64 - timer_ns).max(0.0) * 1e-9;
            }
        }
    }
    if evaluations > 0 {
        ((texture_thread_s - own_s) / evaluations as f64 * 1e9 - timer_ns / PROFILE_TIMING_PERIOD as f64).max(0.0)
    } else {
        0.0
    }
}

/// One profile stream per (material, graph) pair, in the scene's order, with the nodes its
/// outputs come from.
fn profile_streams(scene: &Scene, tap: &Profiler) -> Vec<Stream> {
    let mut out = Vec::new();
    let bounds = material_uv_bounds(scene);
    for (mi, m) in scene.materials.iter().enumerate() {
        for mg in &m.graphs {
            let g = scene.graphs[mg.graph as usize].graph();
            let outputs = mg
                .order
                .outputs()
                .iter()
                .filter_map(|&o| match g.output(o).source {
                    Source::Node { node, .. } => Some(node.0),
                    _ => None,
                })
                .collect();
            let mut st = stream_of(&tap.streams[mg.stream as usize], format!("material {mi}"), mg.graph, outputs);
            st.uv_bounds = bounds[mi].map(|(lo, hi)| [lo.x, lo.y, hi.x, hi.y].map(f64::from));
            out.push(st);
        }
    }
    out
}

/// The layout of the cache the profile's tile reads are counted in ([`node_texture`] in tiles
/// of the default size).
fn cache_geometry() -> crate::error::Result<CacheGeometry> {
    let probe = TileCache::new(CacheConfig::default()).map_err(|e| crate::error::Error::plain(e.to_string()))?;
    let tile_size = probe.config().tile_size;
    let texel_bytes = (tile_size as usize + 1).pow(2) * TexelFormat::F16.bytes();
    Ok(CacheGeometry {
        tile_size,
        level0_texels_per_uv: f64::from(LEVEL0_TEXELS_PER_UV),
        max_level: MAX_LEVEL,
        bytes_per_channel: TexelFormat::F16.bytes() as u32,
        tile_overhead_bytes: (cache::tile_bytes_for(&node_texture(1), tile_size) - texel_bytes) as u64,
    })
}

/// Level of bin `b`.
fn bin_level(b: usize) -> i32 {
    b as i32 + FINER_THAN_LEVEL0
}

fn stream_of(st: &StreamTap, material: String, graph: u32, outputs: Vec<u32>) -> Stream {
    let requests = (0..BINS)
        .filter(|&b| st.requests[b] > 0)
        .map(|b| LevelCount { level: bin_level(b), requests: st.requests[b], per_pixel: st.per_pixel[b] })
        .collect();
    let mut by_level: Vec<Vec<[i64; 4]>> = vec![Vec::new(); MAX_LEVEL as usize + 1];
    for (k, &(lo, up)) in &st.tiles {
        by_level[usize::from(k.level)].push([i64::from(k.x), i64::from(k.y), lo as i64, up as i64]);
    }
    let tiles = by_level
        .into_iter()
        .enumerate()
        .filter(|(_, t)| !t.is_empty())
        .map(|(l, mut tiles)| {
            tiles.sort_unstable();
            let (lower, upper) = st.per_pixel_touches[l];
            LevelTiles { level: l as u8, tiles, per_pixel: [lower, upper] }
        })
        .collect();
    Stream { material, graph, outputs, requests, tiles, uv_bounds: None }
}

/// A graph's nodes for the profile, with costs from the binned timings.
fn profile_graph(name: String, g: &Graph, binned: Option<&graph::BinnedTimings>) -> ProfileGraph {
    let exact = means_suffice(g);
    let nodes = g
        .node_ids()
        .map(|id| {
            let i = id.0 as usize;
            let cost = match binned {
                Some(b) if b.bins == BINS => (0..BINS)
                    .filter_map(|k| {
                        let (ns, samples) = b.mean_ns(i, k)?;
                        Some(LevelCost { level: bin_level(k), ns, samples })
                    })
                    .collect(),
                _ => Vec::new(),
            };
            let ch = channels(g.node_type(id));
            ProfileNode {
                name: g.node_name(id).to_string(),
                category: g.node_category(id).to_string(),
                channels: ch.unwrap_or(4),
                cacheable: ch.is_some() && worth_caching(g, id),
                exact_when_cached: exact[i],
                inputs: node_inputs(g, id),
                cost,
            }
        })
        .collect();
    ProfileGraph { name, hash: graph_hash(g), nodes }
}

/// The nodes `id` reads (each once).
fn node_inputs(g: &Graph, id: NodeId) -> Vec<u32> {
    let mut v: Vec<u32> = g
        .node_inputs(id)
        .into_iter()
        .filter_map(|(_, s)| match s {
            Source::Node { node, .. } => Some(node.0),
            _ => None,
        })
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}

/// A hash of a graph's structure: node names, categories, types and connections.
pub fn graph_hash(g: &Graph) -> String {
    let mut text = String::new();
    for id in g.node_ids() {
        text.push_str(&format!(
            "{}|{}|{:?}|{:?};",
            g.node_name(id),
            g.node_category(id),
            g.node_type(id),
            node_inputs(g, id)
        ));
    }
    plan::text_hash(&[text.as_bytes()])
}

/// Measures on this machine: a trilinear lookup that hits, the tile machinery's cost per texel
/// filled, and the cost of one timing (nanoseconds).
pub fn calibrate() -> (f64, f64, f64) {
    let config = CacheConfig { in_flight: cache::InFlight::Wait, ..CacheConfig::with_budget(256 << 20) };
    let tile_size = config.tile_size;
    let mut cache = TileCache::new(config).expect("a valid cache");
    let desc = node_texture(3);
    let tex = cache.add_texture(desc).expect("a valid texture");
    let fill = |r: TexelRequest| [r.uv.x, r.uv.y, 0.5];
    // Fills: one lookup per tile of level 0 along a row, each filling one new tile.
    let d = f64::from(LEVEL0_TEXELS_PER_UV);
    // 32 tiles (about 3·10⁴ texels), 4000 lookups and 4000 clock pairs time each to within a
    // few per cent, under the host's own drift, in about 1.3 ms: 100 tiles, 10⁴ lookups and
    // 2·10⁴ clock pairs took 5 ms, as long as the rest of a small render's profile, on one
    // thread while the others waited. (The clock pairs are measured once per process.)
    let tiles = 32;
    let texel = Filter::TRILINEAR;
    let t = Instant::now();
    for k in 0..tiles {
        let uv = glam::Vec2::new((((k * tile_size as usize) as f64 + 4.5) / d) as f32, (4.5 / d) as f32);
        cache.lookup_level(tex, uv, 0.0, &fill);
    }
    let fill_s = t.elapsed().as_secs_f64();
    let texels = tiles as f64 * f64::from(tile_size + 1).powi(2);
    let fill_ns_per_texel = fill_s * 1e9 / texels;
    // Hits: lookups at random footprints over the filled row (levels 0 to 3).
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    let n = 4_000;
    let span = (tiles * tile_size as usize) as f32 / LEVEL0_TEXELS_PER_UV;
    let queries: Vec<(glam::Vec2, glam::Mat2)> = (0..n)
        .map(|_| {
            let uv = glam::Vec2::new(next() * span * 0.9, next() * 8.0 / LEVEL0_TEXELS_PER_UV);
            let sigma = (next() * 3.0).exp2() / LEVEL0_TEXELS_PER_UV;
            (uv, glam::Mat2::from_diagonal(glam::Vec2::splat(sigma * sigma)))
        })
        .collect();
    // Through a reader, as a render's lookups go.
    let reader = cache.reader();
    for &(uv, cov) in queries.iter().take(n / 4) {
        reader.lookup(tex, uv, cov, texel, &fill); // warm every level
    }
    let t = Instant::now();
    let mut acc = 0.0f32;
    for &(uv, cov) in &queries {
        acc += reader.lookup(tex, uv, cov, texel, &fill)[0];
    }
    let lookup_ns = t.elapsed().as_secs_f64() * 1e9 / n as f64;
    std::hint::black_box(acc);
    // One timing: two clock reads and the subtraction.
    let timer_ns = graph::clock_pair_ns();
    (lookup_ns, fill_ns_per_texel, timer_ns)
}
