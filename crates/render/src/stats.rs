//! `tessera.stats/1`: what a render measured, as `tessera render --stats-json` writes it and
//! `tessera bench` and `tessera analyze` read it. One type for writer and readers, so a field
//! cannot be written under one name and looked for under another.
//!
//! Timings are in seconds (`_s`), memory in bytes; counts are whole numbers. Readers need only
//! `phases.render_s` and `counts.samples` (and, in a plan's `predicted`, every quantity): any
//! other field reads as zero (or empty) when a file lacks it, as files written before it was
//! added do.

use crate::caching::NodeCache;
use crate::integrator::RenderCounts;
use crate::material::SceneGraph;
use serde::{Deserialize, Serialize};

/// The schema name.
pub const STATS_SCHEMA: &str = "tessera.stats/1";

/// A render's statistics.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RenderStats {
    /// [`STATS_SCHEMA`].
    #[serde(default)]
    pub schema: String,
    /// The scene file (or `<embedded default scene>`).
    #[serde(default)]
    pub scene: String,
    /// The images written.
    #[serde(default)]
    pub images: Vec<String>,
    /// The AOV files written.
    #[serde(default)]
    pub aovs: Vec<String>,
    /// The footprint estimator (`covariance`, `raycone`, `pbrt`, `none`).
    #[serde(default)]
    pub footprint: String,
    /// What traced the rays (`--accel`): "Embree 3.13.5 (N triangles)" or "built-in BVH (N
    /// primitives)".
    #[serde(default)]
    pub accel: String,
    /// Image width in pixels.
    #[serde(default)]
    pub width: u32,
    /// Image height in pixels.
    #[serde(default)]
    pub height: u32,
    /// Samples per pixel.
    #[serde(default)]
    pub spp: u32,
    /// Seed of the random streams.
    #[serde(default)]
    pub seed: u64,
    /// Worker threads.
    #[serde(default)]
    pub threads: u32,
    /// Wall time per phase.
    pub phases: Phases,
    /// Camera samples and rays.
    pub counts: Counts,
    /// Values that were not finite.
    #[serde(default)]
    pub nonfinite: NonFiniteStats,
    /// Rates over the render phase.
    #[serde(default)]
    pub throughput: Throughput,
    /// Per scene graph: per-node evaluations and work.
    #[serde(default)]
    pub graphs: Vec<GraphStats>,
    /// With `--strategy auto`: the profile and the plan.
    #[serde(default)]
    pub plan: Option<PlanStats>,
    /// With a caching strategy: the tile cache's counters.
    #[serde(default)]
    pub cache: Option<CacheReport>,
}

impl RenderStats {
    /// Node evaluations over all graphs.
    pub fn node_evaluations(&self) -> u64 {
        self.graphs.iter().flat_map(|g| &g.nodes).map(|n| n.evaluations).sum()
    }
}

/// Wall time per phase, in seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Phases {
    /// Loading the scene.
    #[serde(default)]
    pub load_s: f64,
    /// Building the cache (and baking, for `bake:RES`).
    #[serde(default)]
    pub cache_setup_s: f64,
    /// Rendering.
    pub render_s: f64,
    /// Writing the images.
    #[serde(default)]
    pub write_s: f64,
}

/// Camera samples and rays traced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    /// Camera samples.
    pub samples: u64,
    /// Rays traced for closest hits.
    #[serde(default)]
    pub rays: u64,
    /// Shadow rays.
    #[serde(default)]
    pub shadow_rays: u64,
    /// Samples left out of their pixels because their radiance was not finite.
    #[serde(default)]
    pub nonfinite_samples: u64,
    /// Samples with a channel beyond the pixel sum's limit (`render::film::SAMPLE_LIMIT`),
    /// clamped to it.
    #[serde(default)]
    pub clamped_samples: u64,
    /// Texture evaluations at pixel centres (first hits and hits through mirrors and glass),
    /// shared by the pixels' samples.
    #[serde(default)]
    pub pixel_texture_evaluations: u64,
    /// Hits that read their pixel's shared textures.
    #[serde(default)]
    pub pixel_texture_reads: u64,
    /// Hits that could have read them but evaluated their own.
    #[serde(default)]
    pub pixel_texture_misses: u64,
    /// Path vertices whose footprint was computed.
    #[serde(default)]
    pub footprints: u64,
    /// Hits whose footprint nothing read, there or later, never computed.
    #[serde(default)]
    pub footprints_skipped: u64,
}

impl Counts {
    /// Adds another render's counts (of other samples or pixels).
    pub fn add(&mut self, o: &Counts) {
        self.samples += o.samples;
        self.rays += o.rays;
        self.shadow_rays += o.shadow_rays;
        self.nonfinite_samples += o.nonfinite_samples;
        self.clamped_samples += o.clamped_samples;
        self.pixel_texture_evaluations += o.pixel_texture_evaluations;
        self.pixel_texture_reads += o.pixel_texture_reads;
        self.pixel_texture_misses += o.pixel_texture_misses;
        self.footprints += o.footprints;
        self.footprints_skipped += o.footprints_skipped;
    }
}

impl From<&RenderCounts> for Counts {
    fn from(c: &RenderCounts) -> Counts {
        Counts {
            samples: c.samples,
            rays: c.rays,
            shadow_rays: c.shadow_rays,
            nonfinite_samples: c.nonfinite_samples,
            clamped_samples: c.clamped_samples,
            pixel_texture_evaluations: c.pixel_texture_evaluations,
            pixel_texture_reads: c.pixel_texture_reads,
            pixel_texture_misses: c.pixel_texture_misses,
            footprints: c.footprints,
            footprints_skipped: c.footprints_skipped,
        }
    }
}

/// Rates over the render phase.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Throughput {
    /// Camera samples per second.
    pub samples_per_s: f64,
    /// Rays (closest-hit and shadow) per second.
    pub rays_per_s: f64,
}

/// Values that were not finite: samples left out, the graph nodes that first gave non-finite
/// values, and the first samples of each kind with where their value came from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NonFiniteStats {
    /// Samples whose radiance was not finite.
    pub samples: u64,
    /// The first of them.
    pub first: Vec<NonFiniteSampleStats>,
    /// Per graph node: evaluations in which it was the first to give a non-finite value.
    pub nodes: Vec<NonFiniteNode>,
    /// The first samples on whose path a texture value went non-finite.
    pub values: Vec<NonFiniteSampleStats>,
}

/// One sample of [`NonFiniteStats`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NonFiniteSampleStats {
    /// Pixel column.
    pub x: u32,
    /// Pixel row (0 = top).
    pub y: u32,
    /// Sample index within the pixel.
    pub sample: u32,
    /// Where a texture value first went non-finite on its path, if one did.
    pub origin: Option<NonFiniteOrigin>,
}

/// Where a texture value went non-finite.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NonFiniteOrigin {
    /// The material shaded.
    pub material: String,
    /// The graph's document.
    pub graph: String,
    /// The node (`nodegraph/node`).
    pub node: String,
    /// Its category.
    pub category: String,
    /// The footprint's centre.
    pub uv: [f32; 2],
    /// The footprint's standard deviation along its major axis.
    pub sigma: f32,
    /// The path vertex (0 = first hit).
    pub bounce: u32,
}

/// A node that gave non-finite values.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct NonFiniteNode {
    /// The graph's document.
    pub graph: String,
    /// The node.
    pub node: String,
    /// Its category.
    pub category: String,
    /// Evaluations in which it was the first to give a non-finite value.
    pub count: u64,
}

/// One scene graph's statistics.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct GraphStats {
    /// The document it came from.
    pub document: String,
    /// Per node.
    pub nodes: Vec<NodeStats>,
    /// Work counters.
    #[serde(default)]
    pub work: WorkStats,
}

/// One node's statistics.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NodeStats {
    /// `nodegraph/node`.
    pub name: String,
    /// The node's category.
    pub category: String,
    /// Evaluations.
    pub evaluations: u64,
    /// Answers from the cache.
    #[serde(default)]
    pub lookups: u64,
    /// Estimated seconds (evaluations × the mean of the timed ones).
    #[serde(default)]
    pub estimated_s: f64,
    /// Evaluations in which it was the first to give a non-finite value.
    #[serde(default)]
    pub nonfinite: u64,
}

/// Work counters of a graph.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct WorkStats {
    /// Noise octaves evaluated.
    pub octaves: u64,
    /// Lattice cells visited.
    pub lattice: u64,
}

impl GraphStats {
    /// Per scene graph, from a render's evaluation statistics.
    pub fn of_render(graphs: &[SceneGraph], stats: &[graph::EvalStats]) -> Vec<GraphStats> {
        graphs
            .iter()
            .zip(stats)
            .map(|(sg, st)| {
                let g = sg.graph();
                let at = |v: &Vec<u64>, i: usize| v.get(i).copied().unwrap_or(0);
                let nodes = g
                    .node_ids()
                    .map(|id| {
                        let i = id.0 as usize;
                        NodeStats {
                            name: g.node_name(id).to_string(),
                            category: g.node_category(id).to_string(),
                            evaluations: at(&st.evaluations, i),
                            lookups: at(&st.lookups, i),
                            estimated_s: st.estimated_seconds(i),
                            nonfinite: at(&st.nonfinite, i),
                        }
                    })
                    .collect();
                GraphStats {
                    document: sg.name.clone(),
                    nodes,
                    work: WorkStats { octaves: st.work.octaves, lattice: st.work.lattice },
                }
            })
            .collect()
    }
}

/// The profile and plan of a `--strategy auto` render.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PlanStats {
    /// `auto`.
    pub strategy: String,
    /// Wall time of the profiling render.
    pub profile_s: f64,
    /// Wall time of the planner.
    pub plan_s: f64,
    /// Samples the profile traced.
    pub profile_samples: u64,
    /// The planner's search method.
    pub method: String,
    /// Candidate nodes.
    pub candidates: u64,
    /// Plans the search evaluated.
    pub plans_evaluated: u64,
    /// The cached nodes' names.
    pub cached_nodes: Vec<String>,
    /// The cached nodes.
    pub nodes: Vec<plan::PlanNode>,
    /// What the model predicted for the plan.
    pub predicted: plan::Summary,
}

/// The tile cache's counters over a render.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CacheReport {
    /// The strategy, as `--strategy` spells it.
    pub strategy: String,
    /// The cached nodes (`nodegraph/node`).
    pub cached_nodes: Vec<String>,
    /// The totals over all cached nodes (at the same level of the document).
    #[serde(flatten)]
    pub totals: CacheTotals,
    /// Per cached node.
    pub nodes: Vec<CacheNodeStats>,
}

/// The tile cache's totals over a render (`tessera bench` reports the same).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct CacheTotals {
    /// The byte budget.
    pub budget_bytes: u64,
    /// Most bytes of live tiles at any time.
    pub peak_bytes: u64,
    /// Filtered lookups.
    pub lookups: u64,
    /// Tile requests answered by a resident tile.
    pub tile_hits: u64,
    /// Tile requests that found none.
    pub tile_misses: u64,
    /// Tiles filled (on a miss, or with a co-filled sibling's texels).
    pub tiles_filled: u64,
    /// Tiles made from texels computed alongside another node's fill (co-filled siblings;
    /// counted in `tiles_filled`).
    pub tiles_co_filled: u64,
    /// Texels filled.
    pub texels_filled: u64,
    /// Half-float channel values stored clamped to ±65504.
    pub texels_saturated: u64,
    /// Tiles evicted.
    pub evictions: u64,
    /// Fills of tiles evicted before.
    pub refills: u64,
}

/// One cached node's counters.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CacheNodeStats {
    /// `nodegraph/node`.
    pub name: String,
    /// Filtered lookups.
    pub lookups: u64,
    /// Per level it used.
    pub levels: Vec<CacheLevelStats>,
}

/// One level's counters of a cached node.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct CacheLevelStats {
    /// The mip level.
    pub level: u8,
    /// Tile requests.
    pub requests: u64,
    /// Requests answered by a resident tile.
    pub hits: u64,
    /// Requests that found none.
    pub misses: u64,
    /// Tiles filled.
    pub fills: u64,
    /// Tiles made from a co-filled sibling's texels (counted in `fills`).
    pub co_fills: u64,
    /// Texels filled.
    pub texels_filled: u64,
    /// Half-float channel values stored clamped.
    #[serde(default)]
    pub texels_saturated: u64,
    /// Tiles evicted.
    pub evictions: u64,
    /// Fills of tiles evicted before.
    pub refills: u64,
    /// Most bytes of live tiles at any time.
    pub peak_bytes: u64,
}

impl CacheTotals {
    /// The totals of `nc`'s counters so far.
    pub fn of(nc: &NodeCache) -> CacheTotals {
        let st = nc.stats();
        let t = st.total();
        CacheTotals {
            budget_bytes: st.budget_bytes,
            peak_bytes: st.peak_bytes,
            lookups: st.textures.iter().map(|x| x.lookups).sum(),
            tile_hits: t.hits,
            tile_misses: t.misses,
            tiles_filled: t.fills,
            tiles_co_filled: t.prefills,
            texels_filled: t.texels_filled,
            texels_saturated: t.texels_saturated,
            evictions: t.evictions,
            refills: t.refills,
        }
    }
}

impl CacheReport {
    /// The counters of `nc` after a render with `strategy`.
    pub fn of(nc: &NodeCache, graphs: &[SceneGraph], strategy: String) -> CacheReport {
        let st = nc.stats();
        let names = nc.cached_node_names(graphs);
        // Textures are added in the order of the names.
        let nodes = names
            .iter()
            .zip(&st.textures)
            .map(|(name, tex)| CacheNodeStats {
                name: name.to_string(),
                lookups: tex.lookups,
                levels: tex
                    .levels
                    .iter()
                    .enumerate()
                    .filter(|(_, l)| l.requests + l.misses + l.fills > 0)
                    .map(|(i, l)| CacheLevelStats {
                        level: i as u8,
                        requests: l.requests,
                        hits: l.hits,
                        misses: l.misses,
                        fills: l.fills,
                        co_fills: l.prefills,
                        texels_filled: l.texels_filled,
                        texels_saturated: l.texels_saturated,
                        evictions: l.evictions,
                        refills: l.refills,
                        peak_bytes: l.peak_bytes,
                    })
                    .collect(),
            })
            .collect();
        CacheReport {
            strategy,
            cached_nodes: names.iter().map(|n| n.to_string()).collect(),
            totals: CacheTotals::of(nc),
            nodes,
        }
    }
}
