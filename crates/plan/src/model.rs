//! The statistical model: from a [`Profile`], predict what a final render with a given set of
//! cached nodes will cost — per node evaluations, cache lookups, tiles filled, bytes and time.
//!
//! The model follows the evaluator's semantics exactly (see `docs/selective-caching.md`):
//!
//! - **Renderer requests.** Each stream's requests (scaled from the profile's samples to the
//!   target's) walk the graph from the stream's outputs. A node that is cached and serves the
//!   request's level answers with one lookup and cuts off its inputs; any other node is
//!   evaluated once and its inputs are visited. Requests finer than level 0, or finer than a
//!   node's `min_level`, are not served by the cache.
//! - **Tiles.** The tiles a cached node's lookups read at level ℓ are the profile's recorded
//!   taps (the finer taps of requests on level ℓ, the coarser taps of requests on ℓ − 1),
//!   extrapolated to the target's number of draws by [`crate::richness::extrapolate`].
//! - **Fills and nesting.** Filling a tile at level ℓ evaluates the node at its `(T + 1)²`
//!   texels, each a request to the node's inputs at exactly level ℓ. Those requests walk the
//!   graph like the renderer's; a cached input reads, for the tiles `(x, y)` of its consumer, the
//!   tiles `(x, y)`, `(x + 1, y)`, `(x, y + 1)`, `(x + 1, y + 1)` of the same level (the border
//!   texels fall in the neighbours), so its tile set is the consumer's dilated by one tile.
//!   Cached nodes are processed from the outputs upstream, so every consumer's tiles are known
//!   before its inputs'.
//! - **Co-filling.** Cached nodes that a stream looks up together (on its frontier: reached
//!   from its outputs through uncached nodes) and of which none feeds another are filled
//!   together, as the renderer does: the fill of the one looked up first (the highest id)
//!   evaluates, at its texels of level ℓ, every such sibling whose finest cached level is at
//!   most ℓ, walking their inputs once, and makes their tiles there as it ends. A sibling's
//!   tiles are then its own or the co-filling node's, whichever are more, and its own fills
//!   request its inputs only for the tiles beyond.
//! - **Time.** Thread-seconds are the profile's per-sample time outside textures, plus each
//!   evaluation at the node's measured cost for its level, plus lookups and filled texels at the
//!   machine's measured costs; wall time divides by the threads.
//! - **Memory.** The bytes of every tile filled: the working set, which a budget must hold for
//!   the prediction (no evictions, no refills) to apply.
//!
//! A tile set is kept symbolically, per level, as one dilation depth and tap variant per
//! stream; unions across streams are counted exactly on the observed tiles (memoised), and each
//! stream adds its extrapolated unseen tiles scaled by the dilation's growth.

use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};

use crate::error::{PlanError, Result};
use crate::profile::{Profile, FINER_THAN_LEVEL0};
use crate::richness;

/// The final render a prediction is for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    /// Camera samples (pixels × samples per pixel).
    pub samples: u64,
    /// Worker threads.
    pub threads: u32,
}

/// Which nodes are cached: per graph, per node, `Some(min_level)` when the node is cached for
/// requests on level `min_level` or coarser (finer requests evaluate it directly).
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PlanSpec {
    /// Per graph, per node.
    pub cached: Vec<Vec<Option<u8>>>,
}

impl PlanSpec {
    /// Nothing cached.
    pub fn none(profile: &Profile) -> PlanSpec {
        PlanSpec { cached: profile.graphs.iter().map(|g| vec![None; g.nodes.len()]).collect() }
    }

    /// Every cacheable node, at every level.
    pub fn all(profile: &Profile) -> PlanSpec {
        let cached =
            profile.graphs.iter().map(|g| g.nodes.iter().map(|n| n.cacheable.then_some(0)).collect()).collect();
        PlanSpec { cached }
    }

    /// The cacheable nodes the materials read.
    pub fn outputs(profile: &Profile) -> PlanSpec {
        let mut p = PlanSpec::none(profile);
        for s in &profile.streams {
            for &o in &s.outputs {
                if profile.graphs[s.graph as usize].nodes[o as usize].cacheable {
                    p.cached[s.graph as usize][o as usize] = Some(0);
                }
            }
        }
        p
    }

    /// The cacheable outputs the materials read that the planner may choose (`exact_when_cached`:
    /// not an output a nonlinear node also reads), each cached from `level`.
    pub fn outputs_from(profile: &Profile, level: u8) -> PlanSpec {
        let mut p = PlanSpec::outputs(profile);
        for (g, nodes) in p.cached.iter_mut().enumerate() {
            for (n, c) in nodes.iter_mut().enumerate().filter(|(_, c)| c.is_some()) {
                *c = profile.graphs[g].nodes[n].exact_when_cached.then_some(level);
            }
        }
        p
    }

    /// Number of cached nodes.
    pub fn count(&self) -> usize {
        self.cached.iter().flatten().filter(|c| c.is_some()).count()
    }
}

/// What the model predicts for one node.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NodePrediction {
    /// Evaluations (tile fills' texels included).
    pub evaluations: f64,
    /// Cache lookups of the node's texture.
    pub lookups: f64,
    /// Tiles filled (distinct tiles: no evictions).
    pub tiles: f64,
    /// Bytes of those tiles.
    pub bytes: f64,
    /// Thread-seconds in the node's evaluations.
    pub thread_s: f64,
    /// Requests to the node by level (index 0: finer than level 0, index ℓ + 1: level ℓ), from
    /// the renderer and from other nodes' tile fills, whether the cache or an evaluation answers
    /// them (its own tile fills are not requests).
    pub requests_by_level: Vec<f64>,
}

/// What the model predicts for a plan.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Prediction {
    /// Node evaluations, all nodes.
    pub evaluations: f64,
    /// Cache lookups, all cached nodes.
    pub lookups: f64,
    /// Tiles filled.
    pub tiles_filled: f64,
    /// Texels filled.
    pub texels_filled: f64,
    /// Bytes of all filled tiles (the cache's peak when the budget holds them).
    pub peak_bytes: f64,
    /// Thread-seconds spent on textures (evaluations, lookups, fills).
    pub texture_thread_s: f64,
    /// Thread-seconds outside textures.
    pub base_thread_s: f64,
    /// Wall-clock seconds of the render.
    pub render_s: f64,
    /// Per graph, per node.
    pub nodes: Vec<Vec<NodePrediction>>,
}

/// One stream's tile taps at one level.
#[derive(Debug, Default)]
struct LevelTaps {
    /// `(x, y, lower touches, upper touches)`.
    tiles: Vec<(i32, i32, u64, u64)>,
    /// Of the touches, the lower and upper ones of per-pixel requests.
    per_pixel: (u64, u64),
    /// Observed and extrapolated distinct tiles per variant (index 1 lower, 2 upper, 3 both).
    observed: [f64; 4],
    predicted: [f64; 4],
    /// Of `predicted`, the tiles [`reachable`] adds beyond Chao1's extrapolation.
    reached: [f64; 4],
}

struct StreamData {
    graph: usize,
    outputs: Vec<u32>,
    /// Scaled requests per bin.
    requests: Vec<f64>,
    /// Per level `0..=max_level`.
    levels: Vec<LevelTaps>,
}

/// A component of a tile set: the taps of one stream at one level, of one variant, dilated.
type Component = (u32, u8, u8, u8); // (stream, level, variant, depth)

/// Per level, per stream: (variant bits, dilation depth).
type TileSet = BTreeMap<u8, BTreeMap<u32, (u8, u8)>>;

/// The model for one profile and one target render (see the module documentation).
pub struct Model<'p> {
    profile: &'p Profile,
    target: Target,
    bins: usize,
    streams: Vec<StreamData>,
    /// Per graph, per node, per bin: nanoseconds per evaluation (overhead included).
    cost: Vec<Vec<Vec<f64>>>,
    base_thread_s: f64,
    memo: RefCell<HashMap<Vec<Component>, f64>>,
    /// Per graph, per node: the nodes upstream of it (itself included).
    upstream: Vec<Vec<Vec<bool>>>,
}

/// Bin of a level: `level + 1` (bin 0: finer than level 0).
#[inline]
fn bin(level: i32) -> usize {
    (level - FINER_THAN_LEVEL0) as usize
}

impl<'p> Model<'p> {
    /// Prepares the model: scales the profile's requests to `target`, extrapolates its tile
    /// counts and fixes each node's cost per level.
    pub fn new(profile: &'p Profile, target: Target) -> Result<Model<'p>> {
        profile.validate()?;
        if target.samples == 0 || target.threads == 0 {
            return Err(PlanError::Settings("the target render needs at least one sample and one thread".into()));
        }
        let scale = target.samples as f64 / profile.render.samples as f64;
        let tile_samples = match profile.render.tile_samples {
            0 => profile.render.samples,
            t => t,
        };
        let tile_scale = target.samples as f64 / tile_samples as f64;
        // Requests a pixel's samples share grow with the pixels: the target renders the
        // profile's image, whose traced pixels each recorded one sample's tile reads.
        let pixel_scale = f64::from(profile.render.width) * f64::from(profile.render.height) / tile_samples as f64;
        let max = profile.cache.max_level;
        let bins = usize::from(max) + 2;
        let streams = profile
            .streams
            .iter()
            .map(|s| {
                let mut requests = vec![0.0; bins];
                for r in &s.requests {
                    let shared = r.per_pixel as f64;
                    requests[bin(r.level)] += (r.requests as f64 - shared) * scale + shared * pixel_scale;
                }
                let mut levels: Vec<LevelTaps> = (0..=max).map(|_| LevelTaps::default()).collect();
                for lt in &s.tiles {
                    let l = &mut levels[usize::from(lt.level)];
                    l.tiles.extend(lt.tiles.iter().map(|t| (t[0] as i32, t[1] as i32, t[2] as u64, t[3] as u64)));
                    l.per_pixel = (l.per_pixel.0 + lt.per_pixel[0], l.per_pixel.1 + lt.per_pixel[1]);
                }
                for (li, l) in levels.iter_mut().enumerate() {
                    for v in 1..4u8 {
                        let counts = l.tiles.iter().map(|t| pick(v, t.2, t.3));
                        let n: u64 = counts.clone().sum();
                        l.observed[usize::from(v)] = counts.clone().filter(|&c| c > 0).count() as f64;
                        let shared = pick(v, l.per_pixel.0, l.per_pixel.1).min(n);
                        let more = (n - shared) as f64 * (tile_scale - 1.0) + shared as f64 * (pixel_scale - 1.0);
                        let chao = richness::extrapolate(counts, more.max(0.0));
                        let reach = match s.uv_bounds {
                            Some(b) if n > 0 => reachable(b, &profile.cache, li, n as f64 + more.max(0.0)),
                            _ => None,
                        };
                        l.predicted[usize::from(v)] = reach.map_or(chao, |r| chao.max(r));
                        l.reached[usize::from(v)] = l.predicted[usize::from(v)] - chao;
                    }
                }
                StreamData { graph: s.graph as usize, outputs: s.outputs.clone(), requests, levels }
            })
            .collect();
        let m = &profile.machine;
        let cost = profile
            .graphs
            .iter()
            .map(|g| {
                g.nodes
                    .iter()
                    .map(|n| {
                        let mut per_bin: Vec<Option<f64>> = vec![None; bins];
                        for c in n.cost.iter().filter(|c| c.samples > 0) {
                            per_bin[bin(c.level)] = Some((c.ns - m.timer_ns).max(0.0));
                        }
                        nearest_fill(&per_bin).into_iter().map(|c| c + m.node_overhead_ns).collect()
                    })
                    .collect()
            })
            .collect();
        let r = &profile.render;
        let outside = if r.outside_thread_s > 0.0 {
            r.outside_thread_s
        } else {
            (r.wall_s * f64::from(r.threads) - r.texture_thread_s - r.tap_thread_s).max(0.0)
        };
        let base_thread_s = outside / r.samples as f64 * target.samples as f64;
        let upstream = profile
            .graphs
            .iter()
            .map(|g| {
                (0..g.nodes.len())
                    .map(|n| {
                        let mut seen = vec![false; g.nodes.len()];
                        let mut stack = vec![n as u32];
                        while let Some(u) = stack.pop() {
                            if !std::mem::replace(&mut seen[u as usize], true) {
                                stack.extend(g.nodes[u as usize].inputs.iter().copied());
                            }
                        }
                        seen
                    })
                    .collect()
            })
            .collect();
        Ok(Model { profile, target, bins, streams, cost, base_thread_s, memo: RefCell::new(HashMap::new()), upstream })
    }

    /// The profile.
    pub fn profile(&self) -> &Profile {
        self.profile
    }

    /// The target render.
    pub fn target(&self) -> Target {
        self.target
    }

    /// Visits the nodes one request reaches from `roots` at `bin`: `answer(node)` for nodes the
    /// cache serves (their inputs are not visited), `evaluate(node)` for the others.
    fn walk(
        &self,
        graph: usize,
        roots: &[u32],
        bin: usize,
        plan: &PlanSpec,
        seen: &mut Vec<bool>,
        mut visit: impl FnMut(u32, bool),
    ) {
        let nodes = &self.profile.graphs[graph].nodes;
        seen.clear();
        seen.resize(nodes.len(), false);
        let mut stack: Vec<u32> = roots.to_vec();
        while let Some(n) = stack.pop() {
            if std::mem::replace(&mut seen[n as usize], true) {
                continue;
            }
            let served = bin > 0 && plan.cached[graph][n as usize].is_some_and(|min| bin > usize::from(min));
            visit(n, served);
            if !served {
                stack.extend(nodes[n as usize].inputs.iter().copied());
            }
        }
    }

    /// Per graph, per cached node: the cached nodes its tile fills compute too, as the renderer
    /// co-fills them: those some stream looks up together with it (both on the stream's
    /// frontier, reached from its outputs through uncached nodes) that neither feed it nor read
    /// it.
    fn siblings(&self, plan: &PlanSpec) -> Vec<Vec<Vec<u32>>> {
        let graphs = &self.profile.graphs;
        let mut sib: Vec<Vec<Vec<u32>>> = graphs.iter().map(|g| vec![Vec::new(); g.nodes.len()]).collect();
        for s in &self.streams {
            let (g, nodes) = (s.graph, &graphs[s.graph].nodes);
            let mut seen = vec![false; nodes.len()];
            let mut frontier = Vec::new();
            let mut stack = s.outputs.clone();
            while let Some(n) = stack.pop() {
                if std::mem::replace(&mut seen[n as usize], true) {
                    continue;
                }
                if plan.cached[g][n as usize].is_some() {
                    frontier.push(n);
                } else {
                    stack.extend(nodes[n as usize].inputs.iter().copied());
                }
            }
            let up = &self.upstream[g];
            for &a in &frontier {
                for &b in &frontier {
                    let related = up[a as usize][b as usize] || up[b as usize][a as usize];
                    if !related && !sib[g][a as usize].contains(&b) {
                        sib[g][a as usize].push(b);
                    }
                }
            }
        }
        sib
    }

    /// Predicts the final render's cost under `plan`.
    pub fn predict(&self, plan: &PlanSpec) -> Prediction {
        let p = self.profile;
        let geo = &p.cache;
        let mut evals: Vec<Vec<Vec<f64>>> =
            p.graphs.iter().map(|g| vec![vec![0.0; self.bins]; g.nodes.len()]).collect();
        let mut lookups: Vec<Vec<f64>> = p.graphs.iter().map(|g| vec![0.0; g.nodes.len()]).collect();
        let mut requests: Vec<Vec<Vec<f64>>> =
            p.graphs.iter().map(|g| vec![vec![0.0; self.bins]; g.nodes.len()]).collect();
        let mut sets: Vec<Vec<TileSet>> = p.graphs.iter().map(|g| vec![TileSet::new(); g.nodes.len()]).collect();
        let mut seen = Vec::new();
        for (si, s) in self.streams.iter().enumerate() {
            for (b, &r) in s.requests.iter().enumerate() {
                if r <= 0.0 {
                    continue;
                }
                let g = s.graph;
                self.walk(g, &s.outputs, b, plan, &mut seen, |n, served| {
                    requests[g][n as usize][b] += r;
                    if served {
                        lookups[g][n as usize] += r;
                        let level = (b - 1) as u8;
                        merge(&mut sets[g][n as usize], level, si as u32, 1, 0);
                        if level < geo.max_level {
                            merge(&mut sets[g][n as usize], level + 1, si as u32, 2, 0);
                        }
                    } else {
                        evals[g][n as usize][b] += r;
                    }
                });
            }
        }
        let mut nodes: Vec<Vec<NodePrediction>> =
            p.graphs.iter().map(|g| vec![NodePrediction::default(); g.nodes.len()]).collect();
        let texels_per_tile = geo.texels_per_tile();
        let siblings = self.siblings(plan);
        // Tiles of a node at a level that a sibling's fills computed with theirs (co-filled).
        let mut covered: HashMap<(usize, u32, u8), f64> = HashMap::new();
        let mut roots = Vec::new();
        for (g, graph) in p.graphs.iter().enumerate() {
            for n in (0..graph.nodes.len()).rev() {
                if plan.cached[g][n].is_none() {
                    continue;
                }
                let set = std::mem::take(&mut sets[g][n]);
                for (&level, comps) in &set {
                    let tiles = self.count(level, comps);
                    // The node is evaluated at its own tiles' texels, or at the tiles of the
                    // sibling whose fills computed it (which make them its tiles), whichever are
                    // more; its inputs are requested by its own fills only beyond what a
                    // sibling's computed.
                    let done = covered.get(&(g, n as u32, level)).copied().unwrap_or(0.0);
                    nodes[g][n].tiles += tiles.max(done);
                    nodes[g][n].bytes += tiles.max(done) * geo.tile_bytes(graph.nodes[n].channels);
                    let b = bin(i32::from(level));
                    evals[g][n][b] += tiles.max(done) * texels_per_tile;
                    let texels = (tiles - done).max(0.0) * texels_per_tile;
                    roots.clear();
                    roots.extend_from_slice(&graph.nodes[n].inputs);
                    if done == 0.0 {
                        // Fills of this node, looked up first (highest id), compute the siblings
                        // read at this level (finest cached level at most this one) with it: one
                        // walk over all their inputs.
                        for &s in &siblings[g][n] {
                            let key = (g, s, level);
                            if (s as usize) < n
                                && plan.cached[g][s as usize].is_some_and(|m| m <= level)
                                && !covered.contains_key(&key)
                            {
                                covered.insert(key, tiles);
                                roots.extend_from_slice(&graph.nodes[s as usize].inputs);
                            }
                        }
                    }
                    if texels == 0.0 {
                        continue;
                    }
                    self.walk(g, &roots, b, plan, &mut seen, |u, served| {
                        requests[g][u as usize][b] += texels;
                        if served {
                            lookups[g][u as usize] += texels;
                            for (&s, &(v, d)) in comps {
                                merge(&mut sets[g][u as usize], level, s, v, d.saturating_add(1));
                            }
                        } else {
                            evals[g][u as usize][b] += texels;
                        }
                    });
                }
            }
        }
        let m = &p.machine;
        let mut out = Prediction { base_thread_s: self.base_thread_s, ..Prediction::default() };
        for (g, graph) in p.graphs.iter().enumerate() {
            for n in 0..graph.nodes.len() {
                let np = &mut nodes[g][n];
                np.lookups = lookups[g][n];
                np.requests_by_level = std::mem::take(&mut requests[g][n]);
                np.evaluations = evals[g][n].iter().sum();
                np.thread_s = evals[g][n].iter().zip(&self.cost[g][n]).map(|(e, c)| e * c).sum::<f64>() * 1e-9;
                out.evaluations += np.evaluations;
                out.lookups += np.lookups;
                out.tiles_filled += np.tiles;
                out.peak_bytes += np.bytes;
                out.texture_thread_s += np.thread_s;
            }
        }
        out.texels_filled = out.tiles_filled * texels_per_tile;
        out.texture_thread_s += (out.lookups * m.lookup_ns + out.texels_filled * m.fill_ns_per_texel) * 1e-9;
        out.render_s = (out.base_thread_s + out.texture_thread_s) / f64::from(self.target.threads);
        out.nodes = nodes;
        out
    }

    /// Predicted distinct tiles of a tile set at `level` (memoised).
    fn count(&self, level: u8, comps: &BTreeMap<u32, (u8, u8)>) -> f64 {
        let key: Vec<Component> = comps.iter().map(|(&s, &(v, d))| (s, level, v, d)).collect();
        if let Some(&c) = self.memo.borrow().get(&key) {
            return c;
        }
        // Tiles as packed (x, y) keys, counted by sorting: hashing them was half of planning.
        let pack = |x: i32, y: i32| (u64::from(x as u32) << 32) | u64::from(y as u32);
        let (mut union, mut own): (Vec<u64>, Vec<u64>) = (Vec::new(), Vec::new());
        let mut unseen = 0.0;
        for &(s, level, v, d) in &key {
            let taps = &self.streams[s as usize].levels[usize::from(level)];
            own.clear();
            for &(x, y, lo, up) in &taps.tiles {
                if pick(v, lo, up) == 0 {
                    continue;
                }
                for dy in 0..=i32::from(d) {
                    for dx in 0..=i32::from(d) {
                        own.push(pack(x + dx, y + dy));
                    }
                }
            }
            own.sort_unstable();
            own.dedup();
            let observed = taps.observed[usize::from(v)];
            if observed > 0.0 {
                // Chao1's unseen tiles dilate as the seen ones do; the reachable ones already
                // cover the surfaces' whole range and count once.
                let growth = own.len() as f64 / observed;
                let reached = taps.reached[usize::from(v)];
                unseen += (taps.predicted[usize::from(v)] - reached - observed) * growth + reached;
            }
            union.extend_from_slice(&own);
        }
        if key.len() > 1 {
            union.sort_unstable();
            union.dedup();
        }
        let c = union.len() as f64 + unseen;
        self.memo.borrow_mut().insert(key, c);
        c
    }
}

/// Most tiles a level's lookups can read over the surfaces' uv range for [`reachable`] to apply.
const FEW_TILES: f64 = 4.0;

/// Distinct tiles of `level` that `draws` lookups are expected to read when they land anywhere
/// on the surfaces' uv range `b` (`[u_min, v_min, u_max, v_max]`) with uniform density: each
/// tile the range reaches, a lookup's lower tap reading tile `floor((u d − ½) / T)` per axis, is
/// read with probability `1 − (1 − a)^draws`, `a` its share of the range. `None` where the
/// range reaches more than [`FEW_TILES`] tiles: there lookups concentrate where the camera looks
/// and uniform density says little, while the profile sees those levels well enough for Chao1.
///
/// Why: at coarse levels a profile sees few distinct tiles (secondary bounces with wide
/// footprints, often a single tile), too few for Chao1 to extrapolate from, while a final render
/// with thirty times the lookups reads every tile of the range, including the thin ones a
/// lookup within half a texel of the range's edge reads. On marble at 64² and 16 spp the profile
/// saw one tile of level 10 where the render filled four (the four around uv 0, a floor's uv
/// starting there); outputs cached from level 10 were predicted 18 tiles each against 26 filled,
/// and each fill evaluates the node's upstream at all (T + 1)² texels of a tile.
fn reachable(b: [f64; 4], geo: &crate::profile::CacheGeometry, level: usize, draws: f64) -> Option<f64> {
    let d = geo.level0_texels_per_uv * (-(level as f64)).exp2();
    let t = f64::from(geo.tile_size);
    // Per axis: the tiles the range reaches and each one's share of it.
    let axis = |lo: f64, hi: f64| -> Option<Vec<f64>> {
        let tile = |u: f64| ((u * d - 0.5) / t).floor();
        let (first, last) = (tile(lo), tile(hi));
        if !(first.is_finite() && last.is_finite()) || last - first >= FEW_TILES {
            return None;
        }
        if hi <= lo {
            return Some(vec![1.0]);
        }
        let mut shares = Vec::new();
        let mut i = first;
        while i <= last {
            // Lookups at u in [(i T + ½)/d, ((i + 1) T + ½)/d) read tile i.
            let (a, z) = (((i * t + 0.5) / d).max(lo), (((i + 1.0) * t + 0.5) / d).min(hi));
            shares.push(((z - a) / (hi - lo)).max(0.0));
            i += 1.0;
        }
        Some(shares)
    };
    let (us, vs) = (axis(b[0], b[2])?, axis(b[1], b[3])?);
    if (us.len() * vs.len()) as f64 > FEW_TILES {
        return None;
    }
    Some(us.iter().flat_map(|a| vs.iter().map(move |c| 1.0 - (1.0 - a * c).powf(draws))).sum())
}

/// Touches of a tile counted by variant `v` (bit 1: lower taps, bit 2: upper taps).
#[inline]
fn pick(v: u8, lower: u64, upper: u64) -> u64 {
    (if v & 1 != 0 { lower } else { 0 }) + (if v & 2 != 0 { upper } else { 0 })
}

/// Adds stream `s`'s taps of variant `v` at dilation `d` to `set` at `level`: the union of two
/// components of one stream is bounded by their variants' union at the larger dilation.
fn merge(set: &mut TileSet, level: u8, s: u32, v: u8, d: u8) {
    let e = set.entry(level).or_default().entry(s).or_insert((0, 0));
    *e = (e.0 | v, e.1.max(d));
}

/// Fills missing entries with the nearest present one (ties: the finer level); all zero when
/// none is present.
fn nearest_fill(v: &[Option<f64>]) -> Vec<f64> {
    (0..v.len())
        .map(|i| {
            (0..v.len())
                .filter_map(|j| v[j].map(|c| (i.abs_diff(j), j, c)))
                .min_by_key(|&(d, j, _)| (d, j))
                .map_or(0.0, |(_, _, c)| c)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::CacheGeometry;

    /// `reachable` against a direct simulation: `draws` lookups at uniform uv over the range,
    /// each reading the tile of its lower tap, and the distinct tiles counted.
    #[test]
    fn reachable_tiles_match_simulated_lookups() {
        let geo = CacheGeometry {
            tile_size: 16,
            level0_texels_per_uv: 16384.0,
            max_level: 20,
            bytes_per_channel: 2,
            tile_overhead_bytes: 0,
        };
        // Additive recurrences (the plastic number's): uniform enough, and independent of the
        // tile grid, for the simulated lookups.
        let (mut k, a1, a2) = (0u64, 0.754_877_666_246_692_7, 0.569_840_290_998_053_3);
        let mut next2 = || {
            k += 1;
            (((k as f64) * a1).fract(), ((k as f64) * a2).fract())
        };
        let mut checked = 0;
        for (b, level, draws) in [
            ([0.0, 0.0, 1.0, 1.0], 10, 40.0),
            ([0.0, 0.0, 1.0, 1.0], 10, 1500.0),
            ([0.0, 0.0, 1.0, 1.0], 14, 300.0),
            ([-0.3, 0.2, 0.7, 0.9], 11, 200.0),
            ([0.0, 0.0, 1.0, 1.0], 9, 100.0),
        ] {
            let Some(r) = reachable(b, &geo, level, draws) else { continue };
            checked += 1;
            let d = geo.level0_texels_per_uv * (-(level as f64)).exp2();
            let tile = |u: f64| ((u * d - 0.5) / f64::from(geo.tile_size)).floor() as i64;
            let trials = 400;
            let mut total = 0usize;
            for _ in 0..trials {
                let mut seen = std::collections::HashSet::new();
                for _ in 0..draws as usize {
                    let (x, y) = next2();
                    let (u, v) = (b[0] + (b[2] - b[0]) * x, b[1] + (b[3] - b[1]) * y);
                    seen.insert((tile(u), tile(v)));
                }
                total += seen.len();
            }
            let mean = total as f64 / f64::from(trials);
            assert!(
                (mean - r).abs() < 0.05 * r.max(1.0),
                "{b:?} level {level}, {draws} draws: {r} predicted, {mean} simulated"
            );
        }
        // Level 9 reaches 9 tiles of [0, 1]² (more than the few it applies to).
        assert_eq!(checked, 4);
    }
}
