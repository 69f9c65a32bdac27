//! The profile: what a short profiling render saw of each node's requests, as compact
//! statistics (schema [`PROFILE_SCHEMA`], documented in `docs/selective-caching.md`).
//!
//! A profile is written by `tessera profile` (or by any renderer that follows the schema) and
//! read by the model. It holds, per *stream* — one material's evaluation of one graph, i.e. the
//! set of nodes the renderer asks for together at every shading point — the requests per level
//! and the tiles their trilinear lookups would read, with touch counts; per node, its inputs and
//! its measured cost per evaluation by level; and the machine's cost of a cache lookup and of
//! filling a texel.
//!
//! Levels: `-1` stands for footprints finer than level 0 (evaluated directly, never cached);
//! `0..=max_level` for `⌊lod⌋` of the footprint, where lod is the cache's level function
//! (`½ log2 λ_max(Σ_uv) + log2 texels_per_uv`).

use serde::{Deserialize, Serialize};

use crate::error::{PlanError, Result};

/// The schema name and version every profile carries.
pub const PROFILE_SCHEMA: &str = "tessera.profile/1";

/// The level that stands for footprints finer than level 0.
pub const FINER_THAN_LEVEL0: i32 = -1;

/// A profile (see the module documentation).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Profile {
    /// [`PROFILE_SCHEMA`].
    pub schema: String,
    /// The scene the profile was taken of.
    pub scene: SceneId,
    /// The profiling render.
    pub render: ProfileRender,
    /// The tile geometry of the cache the model predicts for.
    pub cache: CacheGeometry,
    /// Costs measured on the profiling machine.
    pub machine: MachineCosts,
    /// The graphs, one per document.
    pub graphs: Vec<ProfileGraph>,
    /// The request streams.
    pub streams: Vec<Stream>,
}

/// Identifies a scene: a name for people and a hash of its files for checks.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct SceneId {
    /// File name (or a description).
    pub name: String,
    /// Hash of the scene's contents (hex); plans and profiles of other contents are rejected.
    pub hash: String,
}

/// The profiling render.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ProfileRender {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per profiled pixel.
    pub spp: u32,
    /// Samples per pixel the scene asks for (the default target of `tessera plan`); 0 if unknown.
    #[serde(default)]
    pub scene_spp: u32,
    /// Fraction of the image's pixels that were traced.
    pub pixel_fraction: f64,
    /// Camera samples (paths) traced.
    pub samples: u64,
    /// Samples whose tile reads are recorded in the streams' `tiles` (one per profiled pixel
    /// when pixels take several samples, so that touch counts are not inflated by a pixel's
    /// samples reading the same tiles); 0 means all `samples`.
    #[serde(default)]
    pub tile_samples: u64,
    /// Worker threads.
    pub threads: u32,
    /// Wall-clock seconds of the profiling render.
    pub wall_s: f64,
    /// Thread-seconds the profiled samples spent outside graph evaluation, estimated from the
    /// samples after each pixel's first (a render with many samples per pixel runs with warm
    /// processor caches); 0 if unknown (then `wall_s × threads` less the texture and tap time
    /// stands for it).
    #[serde(default)]
    pub outside_thread_s: f64,
    /// Thread-seconds spent evaluating graphs (estimated from timed evaluations).
    pub texture_thread_s: f64,
    /// Thread-seconds spent recording the profile (estimated from timed records).
    pub tap_thread_s: f64,
}

/// The virtual textures' geometry (one per cached node, all alike).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CacheGeometry {
    /// Tile side `T` in texels; a tile stores `(T + 1)²` texels (one border row and column).
    pub tile_size: u32,
    /// Level 0's texels per uv unit.
    pub level0_texels_per_uv: f64,
    /// Coarsest level.
    pub max_level: u8,
    /// Bytes per channel of a texel.
    pub bytes_per_channel: u32,
    /// Bytes a tile costs beyond its texels.
    pub tile_overhead_bytes: u64,
}

impl CacheGeometry {
    /// Texels a tile stores, border included.
    pub fn texels_per_tile(&self) -> f64 {
        let side = f64::from(self.tile_size) + 1.0;
        side * side
    }

    /// Bytes of one tile with `channels` channels.
    pub fn tile_bytes(&self, channels: u8) -> f64 {
        self.texels_per_tile() * f64::from(channels) * f64::from(self.bytes_per_channel)
            + self.tile_overhead_bytes as f64
    }
}

/// Machine costs measured when profiling (nanoseconds).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct MachineCosts {
    /// One trilinear lookup that hits resident tiles.
    pub lookup_ns: f64,
    /// Filling one texel beyond evaluating the node (the tile machinery).
    pub fill_ns_per_texel: f64,
    /// Per node evaluation, beyond the node's own timed work (the evaluator's bookkeeping).
    pub node_overhead_ns: f64,
    /// What one timing (two clock reads) adds to a timed evaluation; subtracted from costs.
    pub timer_ns: f64,
}

/// One graph (a MaterialX document's nodes, in topological order).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ProfileGraph {
    /// Document name.
    pub name: String,
    /// Hash of the graph's structure (names, categories, connections).
    pub hash: String,
    /// Nodes; a node's inputs have smaller indices.
    pub nodes: Vec<ProfileNode>,
}

/// `true`, the default of [`ProfileNode::exact_when_cached`] (profiles written before it).
fn yes() -> bool {
    true
}

/// One node.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ProfileNode {
    /// Full name, `nodegraph/node`.
    pub name: String,
    /// MaterialX category.
    pub category: String,
    /// Channels of its value (1 to 3 for cacheable nodes).
    pub channels: u8,
    /// Whether the renderer can cache it in texture space (depends on uv alone, has at most 3
    /// channels, and is not a coordinate or a constant).
    pub cacheable: bool,
    /// Whether caching it keeps the images' textures: its tiles hold means only (no spread over
    /// the footprint, no gradient), and every graph output it reaches depends on its mean alone
    /// (through sums, channel moves, and products, mixes and remaps whose other inputs are
    /// constants). Where a nonlinear node (a `smoothstep` mask) reads it, a cached value sharpens
    /// what the filtered evaluation blurs: the planner does not choose such nodes (a plan file or
    /// `nodes:` still can). Absent: true.
    #[serde(default = "yes")]
    pub exact_when_cached: bool,
    /// Indices of the nodes it reads (each smaller than its own).
    pub inputs: Vec<u32>,
    /// Its own cost per evaluation by level (inputs not included).
    pub cost: Vec<LevelCost>,
}

/// Measured cost of a node's evaluations at one level.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct LevelCost {
    /// Level ([`FINER_THAN_LEVEL0`] or `0..=max_level`).
    pub level: i32,
    /// Mean nanoseconds per timed evaluation (the timer's cost included; see
    /// [`MachineCosts::timer_ns`]).
    pub ns: f64,
    /// Timed evaluations behind the mean.
    pub samples: u64,
}

/// One stream: a material's requests of one graph.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Stream {
    /// Material (for reports).
    pub material: String,
    /// Index into [`Profile::graphs`].
    pub graph: u32,
    /// The nodes whose values the material reads.
    pub outputs: Vec<u32>,
    /// Requests by level.
    pub requests: Vec<LevelCount>,
    /// By level: the tiles trilinear lookups of these requests read.
    pub tiles: Vec<LevelTiles>,
    /// `[u_min, v_min, u_max, v_max]`: the uv range of the surfaces that carry the material,
    /// where its requests can land (absent: unknown).
    #[serde(default)]
    pub uv_bounds: Option<[f64; 4]>,
}

impl Stream {
    /// Total requests.
    pub fn total_requests(&self) -> u64 {
        self.requests.iter().map(|r| r.requests).sum()
    }
}

/// Requests at one level.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct LevelCount {
    /// Level ([`FINER_THAN_LEVEL0`] or `0..=max_level`).
    pub level: i32,
    /// Requests whose footprint falls on that level.
    pub requests: u64,
    /// Of them, the requests a pixel's camera samples share (their first hits' textures,
    /// evaluated once per pixel and surface): they grow with the image's pixels, the others
    /// with its samples.
    #[serde(default)]
    pub per_pixel: u64,
}

/// Tiles read at one level, each `[x, y, lower, upper]`: tile coordinates and how many lookups
/// read it as their finer level (`⌊lod⌋`, "lower") or as the coarser one they blend in
/// (`⌊lod⌋ + 1`, "upper").
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct LevelTiles {
    /// Level.
    pub level: u8,
    /// `[x, y, lower touches, upper touches]`.
    pub tiles: Vec<[i64; 4]>,
    /// Of all the level's lower and upper touches, those of requests a pixel's samples share
    /// ([`LevelCount::per_pixel`]).
    #[serde(default)]
    pub per_pixel: [u64; 2],
}

fn bad(what: String) -> PlanError {
    PlanError::Profile(what)
}

fn finite_nonneg(x: f64, what: &str) -> Result<()> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        Err(bad(format!("{what} must be a finite non-negative number, got {x}")))
    }
}

impl Profile {
    /// Parses and validates a profile from JSON text.
    pub fn from_json(text: &str) -> Result<Profile> {
        let p: Profile = serde_json::from_str(text).map_err(|e| {
            if text.contains(PROFILE_SCHEMA) || !text.contains("\"schema\"") {
                bad(format!("line {} column {}: {e}", e.line(), e.column()))
            } else {
                bad(format!("not a {PROFILE_SCHEMA} document ({e})"))
            }
        })?;
        p.validate()?;
        Ok(p)
    }

    /// The profile as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a profile serialises")
    }

    /// Checks the invariants the model relies on.
    pub fn validate(&self) -> Result<()> {
        if self.schema != PROFILE_SCHEMA {
            return Err(bad(format!("schema is '{}', expected '{PROFILE_SCHEMA}'", self.schema)));
        }
        for (k, st) in self.streams.iter().enumerate() {
            if let Some(b) = st.uv_bounds {
                if !(b.iter().all(|x| x.is_finite()) && b[0] <= b[2] && b[1] <= b[3]) {
                    return Err(bad(format!(
                        "streams[{k}].uv_bounds must be finite [u_min, v_min, u_max, v_max], got {b:?}"
                    )));
                }
            }
        }
        let c = &self.cache;
        if !(c.tile_size.is_power_of_two() && (2..=1024).contains(&c.tile_size)) {
            return Err(bad(format!("cache.tile_size must be a power of two from 2 to 1024, got {}", c.tile_size)));
        }
        if !(c.level0_texels_per_uv.is_finite() && c.level0_texels_per_uv > 0.0) {
            return Err(bad(format!("cache.level0_texels_per_uv must be positive, got {}", c.level0_texels_per_uv)));
        }
        if c.max_level > 31 || !(1..=8).contains(&c.bytes_per_channel) {
            return Err(bad("cache.max_level must be at most 31 and bytes_per_channel 1 to 8".into()));
        }
        let r = &self.render;
        if r.samples == 0 {
            return Err(bad("render.samples is 0: the profile saw nothing".into()));
        }
        if r.threads == 0 {
            return Err(bad("render.threads must be at least 1".into()));
        }
        finite_nonneg(r.wall_s, "render.wall_s")?;
        finite_nonneg(r.texture_thread_s, "render.texture_thread_s")?;
        finite_nonneg(r.outside_thread_s, "render.outside_thread_s")?;
        finite_nonneg(r.tap_thread_s, "render.tap_thread_s")?;
        let m = &self.machine;
        finite_nonneg(m.lookup_ns, "machine.lookup_ns")?;
        finite_nonneg(m.fill_ns_per_texel, "machine.fill_ns_per_texel")?;
        finite_nonneg(m.node_overhead_ns, "machine.node_overhead_ns")?;
        finite_nonneg(m.timer_ns, "machine.timer_ns")?;
        let max = i32::from(c.max_level);
        for (gi, g) in self.graphs.iter().enumerate() {
            for (ni, n) in g.nodes.iter().enumerate() {
                let at = || format!("graphs[{gi}] ({}) node {ni} ({})", g.name, n.name);
                if let Some(&i) = n.inputs.iter().find(|&&i| i as usize >= ni) {
                    return Err(bad(format!(
                        "{}: input {i} is not an earlier node (nodes must be in topological order)",
                        at()
                    )));
                }
                if n.cacheable && !(1..=3).contains(&n.channels) {
                    return Err(bad(format!("{}: a cacheable node has 1 to 3 channels, not {}", at(), n.channels)));
                }
                for lc in &n.cost {
                    if !(FINER_THAN_LEVEL0..=max).contains(&lc.level) {
                        return Err(bad(format!("{}: cost at level {} beyond -1..={max}", at(), lc.level)));
                    }
                    finite_nonneg(lc.ns, &format!("{}: cost.ns", at()))?;
                }
            }
        }
        for (si, s) in self.streams.iter().enumerate() {
            let Some(g) = self.graphs.get(s.graph as usize) else {
                return Err(bad(format!("streams[{si}]: graph {} does not exist", s.graph)));
            };
            if let Some(&o) = s.outputs.iter().find(|&&o| o as usize >= g.nodes.len()) {
                return Err(bad(format!("streams[{si}]: output node {o} does not exist in graph '{}'", g.name)));
            }
            if let Some(r) = s.requests.iter().find(|r| !(FINER_THAN_LEVEL0..=max).contains(&r.level)) {
                return Err(bad(format!("streams[{si}]: requests at level {} beyond -1..={max}", r.level)));
            }
            if let Some(t) = s.tiles.iter().find(|t| i32::from(t.level) > max) {
                return Err(bad(format!("streams[{si}]: tiles at level {} beyond max_level {max}", t.level)));
            }
            // The model adds a level's touch counts (and the requests) as integers.
            if s.requests.iter().try_fold(0u64, |n, r| n.checked_add(r.requests)).is_none() {
                return Err(bad(format!("streams[{si}]: the requests add up to more than 2^64")));
            }
            if let Some(r) = s.requests.iter().find(|r| r.per_pixel > r.requests) {
                return Err(bad(format!(
                    "streams[{si}]: {} per-pixel requests at level {} of only {} requests",
                    r.per_pixel, r.level, r.requests
                )));
            }
            let mut touches = vec![0u64; usize::from(c.max_level) + 1];
            for lt in &s.tiles {
                if let Some(t) = lt.tiles.iter().find(|t| t[2] < 0 || t[3] < 0) {
                    return Err(bad(format!(
                        "streams[{si}]: a tile at level {} has a negative touch count ({}, {})",
                        lt.level, t[2], t[3]
                    )));
                }
                let sum = &mut touches[usize::from(lt.level)];
                *sum = lt
                    .tiles
                    .iter()
                    .try_fold(*sum, |n, t| n.checked_add(t[2] as u64)?.checked_add(t[3] as u64))
                    .ok_or_else(|| {
                        bad(format!("streams[{si}]: the touch counts at level {} add up to more than 2^64", lt.level))
                    })?;
                let lower: u64 = lt.tiles.iter().map(|t| t[2] as u64).sum();
                let upper: u64 = lt.tiles.iter().map(|t| t[3] as u64).sum();
                if lt.per_pixel[0] > lower || lt.per_pixel[1] > upper {
                    return Err(bad(format!(
                        "streams[{si}]: per-pixel touches {:?} at level {} exceed the level's ({lower}, {upper})",
                        lt.per_pixel, lt.level
                    )));
                }
            }
        }
        Ok(())
    }
}
