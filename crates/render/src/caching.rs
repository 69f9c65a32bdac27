//! Caching of graph nodes as virtual mip-mapped textures (the `cache` crate), and the
//! strategies that choose which nodes are cached.
//!
//! A cached node's downstream consumers read it through filtered tile lookups; a tile is filled
//! on demand by evaluating the node at each texel centre with a one-texel footprint, its own
//! inputs read through their strategy (cached or evaluated). Tiles are pure functions of
//! (node, level, tile), so images do not depend on threads or on what was evicted.
//!
//! Approximation: a lookup returns the node's filtered mean only (its uv gradient and spread
//! over the footprint read as zero), so nodes downstream of a cached node treat it as locally
//! constant over the footprint. Lookups finer than level 0 evaluate the node directly.

use crate::error::{Error, Result};
use crate::integrator::{render_with, RenderOutput, RenderSettings};
use crate::material::{MaterialGraph, SceneGraph};
use crate::scene::Scene;
use crate::shading::{Direct, GraphSource};
use cache::{CacheConfig, CacheStats, Filter, TexelFormat, TextureDesc, TextureId, TileCache};
use graph::{EvalScratch, EvalStats, Filtered, Footprint, Graph, Moments, NodeId, NodeOverride, Source, ValueType};
use std::cell::{Cell, RefCell};
use std::str::FromStr;

/// Texels per uv unit at level 0 of every cached node (2^14): finer than any footprint the demo
/// scenes ask for at close range; a virtual texture costs memory only where it is read.
pub const LEVEL0_TEXELS_PER_UV: f32 = 16384.0;
/// Coarsest level (texels 2^6 uv units wide).
pub const MAX_LEVEL: u8 = 20;

/// The virtual texture a cached node of `channels` channels gets (except in bakes): half floats
/// at [`LEVEL0_TEXELS_PER_UV`] down to [`MAX_LEVEL`]. The profiler taps the same layout.
pub fn node_texture(channels: u8) -> TextureDesc {
    TextureDesc { channels, format: TexelFormat::F16, texels_per_uv: LEVEL0_TEXELS_PER_UV, max_level: MAX_LEVEL }
}

/// Renders `scene`, reading the nodes `cache` holds from its tiles (every node evaluated on
/// every request without one); `progress` is called with the pixels each image bucket finished.
pub fn render_cached(
    scene: &Scene,
    settings: RenderSettings,
    cache: Option<&NodeCache>,
    progress: &(dyn Fn(u64) + Sync),
) -> RenderOutput {
    match cache {
        Some(nc) => render_with(scene, settings, &|| CacheAccess::new(nc, &scene.graphs), progress),
        None => render_with(scene, settings, &|| Direct, progress),
    }
}

/// Which nodes to cache (`--strategy`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Strategy {
    /// Evaluate every node on every request (shade on hit).
    None,
    /// Cache only the nodes whose values the materials read (graph outputs).
    Outputs,
    /// Cache every node that computes a value (not `texcoord`, `constant` or coordinate-valued
    /// nodes, whose caching would only lose precision).
    All,
    /// Cache the named nodes (`nodegraph/node`, or `node` when unique).
    Nodes(Vec<String>),
    /// The texture-baking workflow: before rendering, evaluate every bound output over the uv
    /// rectangle the scene's shapes use at `RES × RES` texels with all coarser mip levels, then
    /// sample it like a bitmap (footprints finer than a baked texel read the finest level).
    Bake(u32),
    /// The nodes (and finest cached levels) of a plan file (`tessera.plan/1`, written by
    /// `tessera plan` or `--strategy auto`).
    Plan(std::path::PathBuf),
    /// Profile, plan and render (resolved by the caller into [`NodeCache::from_plan`]).
    Auto,
}

impl std::fmt::Display for Strategy {
    /// The strategy as `--strategy` spells it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Strategy::None => f.write_str("none"),
            Strategy::Outputs => f.write_str("outputs"),
            Strategy::All => f.write_str("all"),
            Strategy::Auto => f.write_str("auto"),
            Strategy::Nodes(n) => write!(f, "nodes:{}", n.join(",")),
            Strategy::Plan(p) => write!(f, "plan:{}", p.display()),
            Strategy::Bake(r) => write!(f, "bake:{r}"),
        }
    }
}

impl FromStr for Strategy {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Ok(match s {
            "none" => Strategy::None,
            "outputs" => Strategy::Outputs,
            "all" => Strategy::All,
            "auto" => Strategy::Auto,
            _ if s.starts_with("plan:") && s.len() > 5 => Strategy::Plan(s[5..].into()),
            _ if s.starts_with("bake:") => {
                let res: u32 =
                    s[5..].parse().map_err(|_| format!("bake:RES needs a whole number of texels, got '{s}'"))?;
                if !(1..=65536).contains(&res) {
                    return Err(format!("bake resolution must be 1 to 65536 texels, got {res}"));
                }
                Strategy::Bake(res)
            }
            _ => match s.strip_prefix("nodes:") {
                Some(list) if !list.trim().is_empty() => {
                    Strategy::Nodes(list.split(',').map(|n| n.trim().to_string()).filter(|n| !n.is_empty()).collect())
                }
                _ => {
                    return Err(format!(
                        "unknown strategy '{s}' (expected none, outputs, all, auto, nodes:a,b,c, plan:FILE or bake:RES)"
                    ))
                }
            },
        })
    }
}

pub(crate) fn channels(ty: ValueType) -> Option<u8> {
    match ty {
        ValueType::Float | ValueType::Integer | ValueType::Boolean => Some(1),
        ValueType::Vector2 => Some(2),
        ValueType::Vector3 | ValueType::Color3 => Some(3),
        ValueType::Vector4 | ValueType::Color4 => None,
    }
}

/// Whether caching node `id` can pay: it computes something, is not a coordinate, and depends
/// on the shading point through uv alone (a texture over uv cannot hold what varies with the
/// surface's position or frame).
pub(crate) fn worth_caching(g: &Graph, id: NodeId) -> bool {
    !matches!(g.node_category(id), "texcoord" | "constant") && g.node_type(id) != ValueType::Vector2 && g.is_uv_only(id)
}

/// Per node of `g`: whether a cached value of it (a mean: tiles hold no spread and no gradient)
/// leaves the mean of every graph output it reaches as the filtered evaluation gives it. True
/// where each path to the outputs runs through sums, differences, inversions and channel moves,
/// or through products, quotients, mixes and remaps whose other inputs are constants: the means
/// of those depend on their inputs' means alone. A path through anything else (a `smoothstep`
/// or `clamp` of it, a product of two varying values, whose mean has their covariance) would
/// read the missing spread: caching rusted_metal's `rust_field`, read by smoothstep masks, made
/// `auto`'s image 2–6× further from the uncached one.
pub(crate) fn means_suffice(g: &Graph) -> Vec<bool> {
    let n = g.node_count();
    let mut consumers: Vec<Vec<(NodeId, &'static str)>> = vec![Vec::new(); n];
    for c in g.node_ids() {
        for (name, s) in g.node_inputs(c) {
            if let Source::Node { node, .. } = s {
                consumers[node.0 as usize].push((c, name));
            }
        }
    }
    // Consumers have larger ids (the order is topological): decide them first.
    let mut ok = vec![true; n];
    for i in (0..n).rev() {
        ok[i] = consumers[i].iter().all(|&(c, input)| ok[c.0 as usize] && passes_means(g, c, input));
    }
    ok
}

/// Whether node `c`'s mean depends on its input `input`'s mean alone (not its spread or gradient).
fn passes_means(g: &Graph, c: NodeId, input: &str) -> bool {
    let others_constant =
        g.node_inputs(c).iter().filter(|(name, _)| *name != input).all(|(_, s)| matches!(s, Source::Constant(_)));
    match g.node_category(c) {
        "add" | "subtract" | "invert" | "convert" | "extract" | "separate2" | "separate3" | "separate4"
        | "combine2" | "combine3" | "combine4" | "dot" => true,
        "multiply" | "mix" => others_constant,
        "divide" => input == "in1" && others_constant,
        "remap" => input == "in" && others_constant,
        _ => false,
    }
}

/// Marks the nodes of `plan` in `chosen` with their finest cached levels; errors name nodes the
/// scene's graphs do not have or cannot cache.
fn select_plan(
    graphs: &[SceneGraph],
    plan: &plan::PlanFile,
    chosen: &mut [Vec<bool>],
    min_level: &mut [Vec<u8>],
) -> std::result::Result<(), String> {
    for pn in &plan.nodes {
        let Some(gi) = graphs.iter().position(|g| g.file_name() == pn.graph) else {
            let names: Vec<&str> = graphs.iter().map(|g| g.file_name()).collect();
            return Err(format!(
                "the plan caches nodes of graph '{}', which this scene does not use (its graphs: {}); was the plan made for another scene?",
                pn.graph,
                names.join(", ")
            ));
        };
        let g = graphs[gi].graph();
        let Some(id) = g.node_id(&pn.node) else {
            return Err(format!(
                "the plan caches node '{}', which graph '{}' does not have; was the plan made for another version of it?",
                pn.node, pn.graph
            ));
        };
        if channels(g.node_type(id)).is_none() || !worth_caching(g, id) {
            return Err(format!("the plan caches node '{}', which cannot be cached in texture space", pn.node));
        }
        chosen[gi][id.0 as usize] = true;
        min_level[gi][id.0 as usize] = pn.min_level.min(MAX_LEVEL);
    }
    Ok(())
}

/// The scene's node cache: one virtual texture per cached node.
pub struct NodeCache {
    cache: TileCache,
    /// Per scene graph, per node: its texture when cached.
    textures: Vec<Vec<Option<TextureId>>>,
    filter: Filter,
    /// Baked textures read every footprint from the cache (finer ones clamp to level 0).
    baked: bool,
    /// Per graph, per node: the finest level served from the cache (finer requests evaluate).
    min_level: Vec<Vec<u8>>,
    /// Per graph: whether none of its nodes is cached (its evaluations never ask the cache).
    uncached: Vec<bool>,
    /// A hash of everything that decides the cached values ([`NodeCache::identity`]).
    identity: String,
    /// Per graph, per cached node: the other cached nodes whose tiles its fills compute too
    /// ([`co_filled`]).
    siblings: Vec<Vec<Vec<(NodeId, TextureId)>>>,
}

/// For each cached node, the cached nodes of the same graph that some material's request looks
/// up together with it (both on the request's frontier: reached from its outputs through
/// uncached nodes only) and that neither feed it nor read it. A request that looks one up at a
/// footprint looks the others up at the same footprint, so their tiles at a level are wanted
/// together, and one evaluation of their shared upstream fills both
/// ([`Graph::eval_nodes_direct`] gives each exactly its own value). A node that feeds another is
/// left out: the other reads it through the cache, not evaluated; so is one whose texture has
/// another texel density (a bake's), whose texel of the same index lies elsewhere. Cached nodes
/// inside the frontier are read only by their consumers' fills, at their consumers' tiles, and
/// get none.
fn co_filled(
    graphs: &[SceneGraph],
    materials: &[crate::material::Material],
    textures: &[Vec<Option<TextureId>>],
    cache: &TileCache,
) -> Vec<Vec<Vec<(NodeId, TextureId)>>> {
    let mut siblings: Vec<Vec<Vec<(NodeId, TextureId)>>> = textures.iter().map(|t| vec![Vec::new(); t.len()]).collect();
    for m in materials {
        for mg in &m.graphs {
            let gi = mg.graph as usize;
            let g = graphs[gi].graph();
            // The request's frontier: cached nodes reached from its outputs through uncached ones.
            let mut frontier: Vec<(NodeId, TextureId)> = Vec::new();
            let mut seen = vec![false; g.node_count()];
            let mut stack: Vec<NodeId> = mg
                .order
                .outputs()
                .iter()
                .filter_map(|&o| match g.output(o).source {
                    Source::Node { node, .. } => Some(node),
                    _ => None,
                })
                .collect();
            while let Some(n) = stack.pop() {
                if std::mem::replace(&mut seen[n.0 as usize], true) {
                    continue;
                }
                match textures[gi][n.0 as usize] {
                    Some(t) => frontier.push((n, t)),
                    None => stack.extend(g.node_inputs(n).iter().filter_map(|(_, s)| match s {
                        Source::Node { node, .. } => Some(*node),
                        _ => None,
                    })),
                }
            }
            for &(a, ta) in &frontier {
                for &(b, tb) in &frontier {
                    // Texels are shared by index: both textures must lay them out alike (bakes
                    // size each node's texture to its own uv rectangle).
                    let alike = cache.texture(ta).texels_per_uv == cache.texture(tb).texels_per_uv;
                    let related = a == b || !alike || g.upstream(a).contains(&b) || g.upstream(b).contains(&a);
                    let list = &mut siblings[gi][a.0 as usize];
                    if !related && !list.iter().any(|&(n, _)| n == b) {
                        list.push((b, tb));
                    }
                }
            }
        }
    }
    siblings
}

/// A uv rectangle `(min, max)`.
pub(crate) type UvRect = (glam::Vec2, glam::Vec2);

fn union(r: Option<UvRect>, lo: glam::Vec2, hi: glam::Vec2) -> Option<UvRect> {
    Some(match r {
        Some((l, h)) => (l.min(lo), h.max(hi)),
        None => (lo, hi),
    })
}

/// The uv rectangle each material's shapes cover (a mesh without texture coordinates, a sphere
/// and a disk cover [0, 1]²); `None` for a material no shape carries.
pub(crate) fn material_uv_bounds(scene: &Scene) -> Vec<Option<UvRect>> {
    use crate::geometry::ShapeGeometry;
    let mut b: Vec<Option<UvRect>> = vec![None; scene.materials.len()];
    for shape in &scene.shapes {
        let (lo, hi) = match &shape.geometry {
            ShapeGeometry::Mesh { mesh, .. } => match &mesh.uvs {
                Some(uvs) => {
                    uvs.iter().fold((glam::Vec2::splat(f32::MAX), glam::Vec2::splat(f32::MIN)), |(l, h), u| {
                        (l.min(*u), h.max(*u))
                    })
                }
                None => (glam::Vec2::ZERO, glam::Vec2::ONE),
            },
            // Spheres (φ/2π, θ/π) and disks (r, φ/2π) map onto [0, 1]².
            ShapeGeometry::Sphere { .. } | ShapeGeometry::Disk { .. } => (glam::Vec2::ZERO, glam::Vec2::ONE),
        };
        let e = &mut b[shape.material as usize];
        *e = union(*e, lo, hi);
    }
    b
}

/// Which nodes of each scene graph a strategy caches, with their finest cached levels and,
/// for bakes, the uv rectangle each must cover.
struct Selection {
    chosen: Vec<Vec<bool>>,
    min_level: Vec<Vec<u8>>,
    rects: Vec<Vec<Option<UvRect>>>,
}

impl Selection {
    /// Nothing chosen.
    fn empty(graphs: &[SceneGraph]) -> Selection {
        fn per_node<T: Clone>(graphs: &[SceneGraph], v: T) -> Vec<Vec<T>> {
            graphs.iter().map(|g| vec![v.clone(); g.graph().node_count()]).collect()
        }
        Selection { chosen: per_node(graphs, false), min_level: per_node(graphs, 0), rects: per_node(graphs, None) }
    }

    /// `bake:RES`: every bound output that depends on uv alone, over its materials' shapes' uv
    /// rectangles.
    fn bake_outputs(&mut self, scene: &Scene) {
        let (graphs, materials) = (&scene.graphs[..], &scene.materials[..]);
        let bounds = material_uv_bounds(scene);
        for (mi, m) in materials.iter().enumerate() {
            let Some((lo, hi)) = bounds[mi] else { continue };
            for mg in &m.graphs {
                let g = graphs[mg.graph as usize].graph();
                for &out in mg.order.outputs() {
                    if let Source::Node { node, .. } = g.output(out).source {
                        // Outputs that read the surface's geometry are evaluated directly.
                        if channels(g.node_type(node)).is_some() && g.is_uv_only(node) {
                            self.chosen[mg.graph as usize][node.0 as usize] = true;
                            let r = &mut self.rects[mg.graph as usize][node.0 as usize];
                            *r = union(*r, lo, hi);
                        }
                    }
                }
            }
        }
    }

    /// `outputs`: the nodes the materials read, where caching can pay.
    fn outputs(&mut self, graphs: &[SceneGraph], materials: &[crate::material::Material]) {
        for m in materials {
            for mg in &m.graphs {
                let g = graphs[mg.graph as usize].graph();
                for &out in mg.order.outputs() {
                    if let Source::Node { node, .. } = g.output(out).source {
                        self.chosen[mg.graph as usize][node.0 as usize] |= worth_caching(g, node);
                    }
                }
            }
        }
    }

    /// `all`: every node where caching can pay.
    fn all(&mut self, graphs: &[SceneGraph]) {
        for (gi, sg) in graphs.iter().enumerate() {
            for id in sg.graph().node_ids() {
                self.chosen[gi][id.0 as usize] = worth_caching(sg.graph(), id);
            }
        }
    }

    /// `nodes:a,b,c`: the named nodes (`nodegraph/node`, or `node` when unique); errors name
    /// what is missing, ambiguous or not cacheable.
    fn named(&mut self, graphs: &[SceneGraph], names: &[String]) -> Result<()> {
        for name in names {
            let mut found = Vec::new();
            for (gi, sg) in graphs.iter().enumerate() {
                let g = sg.graph();
                for id in g.node_ids() {
                    let full = g.node_name(id);
                    if full == name || full.rsplit('/').next() == Some(name.as_str()) {
                        found.push((gi, id));
                    }
                }
            }
            match found.as_slice() {
                [(gi, id)] => {
                    if channels(graphs[*gi].graph().node_type(*id)).is_none() {
                        return Err(Error::plain(format!("node '{name}' has 4 channels; the cache stores at most 3")));
                    }
                    if !graphs[*gi].graph().is_uv_only(*id) {
                        return Err(Error::plain(format!(
                            "--strategy nodes: node '{name}' depends on the surface's position or frame \
                             (position, normal, tangent, bitangent or a 3D noise upstream), not on uv alone; \
                             it cannot be cached as a texture over uv"
                        )));
                    }
                    self.chosen[*gi][id.0 as usize] = true;
                }
                [] => {
                    let all: Vec<&str> =
                        graphs.iter().flat_map(|g| g.graph().node_ids().map(|id| g.graph().node_name(id))).collect();
                    // Names that contain the one asked for first (a misspelt or partial name),
                    // and never more than a few: a scene may have thousands of nodes.
                    const SHOWN: usize = 8;
                    let lower = name.to_lowercase();
                    let (near, far): (Vec<&str>, Vec<&str>) =
                        all.iter().partition(|n| n.to_lowercase().contains(&lower));
                    let shown: Vec<&str> = near.iter().chain(&far).take(SHOWN).copied().collect();
                    let more = all.len() - shown.len();
                    let tail = if more > 0 { format!(", and {more} more") } else { String::new() };
                    let what = if near.is_empty() { "the scene's nodes" } else { "nodes with that in their name" };
                    return Err(Error::plain(format!(
                        "--strategy nodes: no node named '{}' ({what}: {}{tail})",
                        crate::xml::excerpt(name),
                        shown.join(", ")
                    )));
                }
                _ => {
                    return Err(Error::plain(format!(
                        "--strategy nodes: '{name}' names several nodes; use the full name nodegraph/node"
                    )))
                }
            }
        }
        Ok(())
    }
}

impl NodeCache {
    /// Builds the cache for `strategy` within `budget_bytes`; `None` for [`Strategy::None`].
    /// For [`Strategy::Bake`] the textures are filled before this returns.
    pub fn new(scene: &Scene, strategy: &Strategy, budget_bytes: usize) -> Result<Option<NodeCache>> {
        NodeCache::with_co_filling(scene, strategy, budget_bytes, true)
    }

    /// [`NodeCache::new`], with co-filling ([`co_filled`]) on or off. The images are the same
    /// either way (tests compare them); off is for measuring what co-filling saves.
    pub fn with_co_filling(
        scene: &Scene,
        strategy: &Strategy,
        budget_bytes: usize,
        co_fill: bool,
    ) -> Result<Option<NodeCache>> {
        let graphs = &scene.graphs[..];
        let mut sel = Selection::empty(graphs);
        match strategy {
            Strategy::None => return Ok(None),
            Strategy::Auto => {
                return Err(Error::plain(
                    "--strategy auto is resolved by profiling and planning first (tessera render does this)",
                ))
            }
            Strategy::Plan(path) => {
                let text = std::fs::read_to_string(path)
                    .map_err(|e| Error::plain(format!("{}: cannot read the plan file: {e}", path.display())))?;
                let plan =
                    plan::PlanFile::from_json(&text).map_err(|e| Error::plain(format!("{}: {e}", path.display())))?;
                select_plan(graphs, &plan, &mut sel.chosen, &mut sel.min_level)
                    .map_err(|e| Error::plain(format!("{}: {e}", path.display())))?;
            }
            Strategy::Bake(_) => sel.bake_outputs(scene),
            Strategy::Outputs => sel.outputs(graphs, &scene.materials),
            Strategy::All => sel.all(graphs),
            Strategy::Nodes(names) => sel.named(graphs, names)?,
        }
        let bake = match strategy {
            Strategy::Bake(res) => Some(*res),
            _ => None,
        };
        NodeCache::build(graphs, &scene.materials, bake, sel.chosen, sel.min_level, sel.rects, budget_bytes, co_fill)
            .map(Some)
    }

    /// The cache for the chosen nodes; with `bake` (texels across each uv rectangle), the baked
    /// textures, filled before this returns. (The selection's three per-node tables come as
    /// they are, each an argument.)
    #[allow(clippy::too_many_arguments)]
    fn build(
        graphs: &[SceneGraph],
        materials: &[crate::material::Material],
        bake: Option<u32>,
        chosen: Vec<Vec<bool>>,
        min_level: Vec<Vec<u8>>,
        rects: Vec<Vec<Option<UvRect>>>,
        budget_bytes: usize,
        co_fill: bool,
    ) -> Result<NodeCache> {
        // Threads wait for a tile another thread is filling: the direct-evaluation alternative
        // was measured to change images between thread counts, and images must not.
        let config = CacheConfig { in_flight: cache::InFlight::Wait, ..CacheConfig::with_budget(budget_bytes) };
        let mut cache = TileCache::new(config).map_err(|e| Error::plain(format!("--budget-mb: {e}")))?;
        let mut textures = Vec::with_capacity(graphs.len());
        let mut identity = format!("tile={};", config.tile_size);
        for (gi, sg) in graphs.iter().enumerate() {
            let g = sg.graph();
            let mut per_node = vec![None; g.node_count()];
            for id in g.node_ids() {
                if !chosen[gi][id.0 as usize] {
                    continue;
                }
                let Some(ch) = channels(g.node_type(id)) else { continue };
                let desc = match (bake, rects[gi][id.0 as usize]) {
                    (Some(res), Some((lo, hi))) => {
                        let extent = (hi - lo).max_element().max(1e-6);
                        TextureDesc {
                            texels_per_uv: res as f32 / extent,
                            max_level: (res as f32).log2().ceil().clamp(0.0, cache::MAX_LEVEL as f32) as u8,
                            ..node_texture(ch)
                        }
                    }
                    _ => node_texture(ch),
                };
                per_node[id.0 as usize] = Some(cache.add_texture(desc).map_err(|e| Error::plain(e.to_string()))?);
                let level = min_level[gi][id.0 as usize];
                identity.push_str(&format!("{gi}/{}@{level}:{desc:?};", g.node_name(id)));
            }
            textures.push(per_node);
        }
        let baked = bake.is_some();
        // Trilinear, not anisotropic probes: on the demo scenes the probes filled 8× more texels
        // (finer levels along grazing footprints) and made caching slower than evaluating;
        // trilinear blurs elongated footprints along their minor axis instead.
        let uncached = textures.iter().map(|t| t.iter().all(Option::is_none)).collect();
        let filter = Filter::TRILINEAR;
        identity.push_str(&format!("baked={baked};filter={filter:?}"));
        let identity = plan::text_hash(&[identity.as_bytes()]);
        // Without materials no request looks two nodes up together: no siblings.
        let siblings = co_filled(graphs, if co_fill { materials } else { &[] }, &textures, &cache);
        let nc = NodeCache { cache, textures, filter, baked, min_level, uncached, identity, siblings };
        if baked {
            nc.bake(graphs, &rects)?;
        }
        Ok(nc)
    }

    /// The cache for a plan (as [`Strategy::Plan`] reads from a file); `None` when the plan
    /// caches nothing.
    pub fn from_plan(scene: &Scene, plan: &plan::PlanFile, budget_bytes: usize) -> Result<Option<NodeCache>> {
        let graphs = &scene.graphs[..];
        let mut sel = Selection::empty(graphs);
        select_plan(graphs, plan, &mut sel.chosen, &mut sel.min_level).map_err(Error::plain)?;
        if sel.chosen.iter().flatten().all(|c| !c) {
            return Ok(None);
        }
        NodeCache::build(graphs, &scene.materials, None, sel.chosen, sel.min_level, sel.rects, budget_bytes, true)
            .map(Some)
    }

    /// Fills every tile of every level of the baked textures over their uv rectangles. The
    /// tiles at one place and level of the nodes one graph co-fills ([`co_filled`]) are filled
    /// by one job, the first's fill computing the others' texels with its own.
    fn bake(&self, graphs: &[SceneGraph], rects: &[Vec<Option<UvRect>>]) -> Result<()> {
        use rayon::prelude::*;
        use std::collections::BTreeMap;
        let t = self.cache.config().tile_size as f32;
        // (graph, level, tile y, tile x) → the baked nodes with a tile there, highest id first
        // (the order in which a request looks them up, which co-filling assumes).
        let mut jobs: BTreeMap<(u32, u8, i64, i64), Vec<(NodeId, TextureId, glam::Vec2)>> = BTreeMap::new();
        let mut bytes = 0usize;
        for (gi, per_node) in self.textures.iter().enumerate() {
            for (n, tex) in per_node.iter().enumerate().rev() {
                let (Some(tex), Some((lo, hi))) = (tex, rects[gi][n]) else { continue };
                let desc = self.cache.texture(*tex);
                for level in 0..=desc.max_level {
                    let d = desc.texels_per_uv / (1u64 << level) as f32;
                    let (x0, y0) = ((lo.x * d / t).floor() as i64, (lo.y * d / t).floor() as i64);
                    let (x1, y1) = ((hi.x * d / t).floor() as i64, (hi.y * d / t).floor() as i64);
                    for ty in y0..=y1 {
                        for tx in x0..=x1 {
                            let centre = glam::Vec2::new((tx as f32 + 0.5) * t / d, (ty as f32 + 0.5) * t / d);
                            jobs.entry((gi as u32, level, ty, tx)).or_default().push((NodeId(n as u32), *tex, centre));
                            bytes += self.cache.tile_bytes(*tex);
                        }
                    }
                }
            }
        }
        if bytes > self.cache.config().budget_bytes {
            return Err(Error::plain(format!(
                "the bake needs {:.1} MiB but --budget-mb allows {:.1} MiB; raise the budget or lower the resolution",
                bytes as f64 / 1048576.0,
                self.cache.config().budget_bytes as f64 / 1048576.0
            )));
        }
        let jobs: Vec<_> = jobs.into_iter().collect();
        jobs.par_iter().for_each_init(
            || CacheAccess::new(self, graphs),
            |access, ((g, level, _, _), tiles)| {
                for &(node, tex, centre) in tiles {
                    let fill = |req: cache::TexelRequest| access.fill_texel(*g, node, &req);
                    self.cache.lookup_level(tex, centre, f32::from(*level), &fill);
                }
            },
        );
        Ok(())
    }

    /// A hash of what decides the values the cache serves: each cached node with its finest
    /// cached level and texture layout, the tile size, the filter, and whether it is baked; not
    /// the budget, which changes only how often tiles are filled again. Two renders whose
    /// caches have the same identity (and that agree otherwise) make the same image.
    pub fn identity(&self) -> &str {
        &self.identity
    }

    /// The cached nodes whose tiles the fills of `node` (of scene graph `graph`) compute too.
    pub fn co_filled_with(&self, graph: u32, node: NodeId) -> Vec<NodeId> {
        self.siblings[graph as usize][node.0 as usize].iter().map(|&(n, _)| n).collect()
    }

    /// Number of cached nodes.
    pub fn cached_nodes(&self) -> usize {
        self.textures.iter().flatten().filter(|t| t.is_some()).count()
    }

    /// Names of the cached nodes, per graph.
    pub fn cached_node_names<'a>(&self, graphs: &'a [SceneGraph]) -> Vec<&'a str> {
        let mut names = Vec::new();
        for (gi, per_node) in self.textures.iter().enumerate() {
            for (n, t) in per_node.iter().enumerate() {
                if t.is_some() {
                    names.push(graphs[gi].graph().node_name(NodeId(n as u32)));
                }
            }
        }
        names
    }

    /// The cache's statistics.
    pub fn stats(&self) -> CacheStats {
        self.cache.stats()
    }
}

/// Per-thread access to a [`NodeCache`]: scratch memory for tile fills (a fill evaluates a node,
/// whose cached inputs may fill further tiles, so fills nest).
pub struct CacheAccess<'a> {
    cache: &'a NodeCache,
    graphs: &'a [SceneGraph],
    /// Per graph: scratches for fills (a fill can need another cached node's fill, so one is
    /// taken per nesting level). Their statistics accumulate until read by
    /// [`CacheAccess::merge_fill_stats_into`]: merging them per fill cost more than a cheap
    /// texel's evaluation.
    pool: RefCell<Vec<Vec<EvalScratch>>>,
    /// This thread's handle on the tile cache (its recent tiles and counts).
    reader: cache::Reader<'a>,
    /// The co-filling tile fills in progress on this thread, innermost last (a fill can need
    /// another cached node's fill): [`CacheAccess::fill_texel`].
    co_fills: RefCell<Vec<CoFill>>,
    /// Finished [`CoFill`]s' buffers, reused.
    co_spare: RefCell<Vec<CoFill>>,
    /// The values a co-filling evaluation writes (one per node it evaluates).
    co_values: RefCell<Vec<Filtered>>,
}

/// One tile fill that co-fills: the filled node's tile, and the siblings whose texels each of
/// its texels' evaluations computes as well, kept until the fill ends and then made their tiles
/// ([`TileCache::prefill`]).
struct CoFill {
    graph: u32,
    /// The filled node.
    node: NodeId,
    level: u8,
    tile: [i32; 2],
    /// The evaluation's nodes: the filled one first, then its siblings.
    nodes: Vec<NodeId>,
    /// The siblings' texels, sibling by sibling, each in the fill's order.
    texels: Vec<[f32; 3]>,
}

impl Default for CoFill {
    fn default() -> Self {
        CoFill { graph: 0, node: NodeId(0), level: 0, tile: [0; 2], nodes: Vec::new(), texels: Vec::new() }
    }
}

impl<'a> CacheAccess<'a> {
    /// Access for one thread.
    pub fn new(cache: &'a NodeCache, graphs: &'a [SceneGraph]) -> Self {
        CacheAccess {
            cache,
            graphs,
            pool: RefCell::new(graphs.iter().map(|_| Vec::new()).collect()),
            reader: cache.cache.reader(),
            co_fills: RefCell::default(),
            co_spare: RefCell::default(),
            co_values: RefCell::default(),
        }
    }

    /// The override for graph `graph`.
    pub fn for_graph(&self, graph: u32) -> GraphOverride<'_, 'a> {
        GraphOverride { access: self, graph, level: Cell::new(None) }
    }

    /// `f` with graph `graph` and a scratch of its pool (taken per call: a fill can need
    /// another's, which takes its own).
    fn with_scratch<R>(&self, graph: u32, f: impl FnOnce(&Graph, &mut EvalScratch) -> R) -> R {
        let g = self.graphs[graph as usize].graph();
        let mut scratch = self.pool.borrow_mut()[graph as usize].pop().unwrap_or_else(|| EvalScratch::new(g));
        let r = f(g, &mut scratch);
        self.pool.borrow_mut()[graph as usize].push(scratch);
        r
    }

    fn fill(&self, graph: u32, node: NodeId, fp: &Footprint) -> Filtered {
        self.with_scratch(graph, |g, scratch| g.eval_node_direct(node, fp, scratch, &self.for_graph(graph)))
    }

    /// The value of texel `req` of `node`'s texture (its channels' means).
    ///
    /// A tile fill of a node with siblings ([`co_filled`]) evaluates, at each of its texels, the
    /// siblings that lookups read at this level (their finest cached level is at most this one)
    /// and whose tile here was not resident when the fill began, in one pass with the node; it
    /// keeps their texels, and when its last texel is done makes them their tiles
    /// ([`TileCache::prefill`]), resident for every thread: the lookups that follow at the same
    /// footprint read them, under a budget that evicts too. Texels evaluated alone (the budget
    /// gave their lookup no tile) co-fill nothing. Each texel's value is the node's own
    /// evaluation, bit for bit, whichever way it was computed.
    fn fill_texel(&self, graph: u32, node: NodeId, req: &cache::TexelRequest) -> [f32; 3] {
        let mean = |f: &Filtered| [f.ch[0].mean, f.ch[1].mean, f.ch[2].mean];
        let fp = Footprint::new(req.uv, req.covariance());
        let nc = self.cache;
        let all_siblings = &nc.siblings[graph as usize][node.0 as usize];
        let Some(place) = req.place.filter(|_| !all_siblings.is_empty()) else {
            // Nobody co-fills this node, and it co-fills nobody (the relation is symmetric); or
            // the texel is evaluated alone.
            return mean(&self.fill(graph, node, &fp));
        };
        if place.index == 0 {
            self.begin_co_fill(graph, node, req.level, place);
        }
        // This fill's entry: the innermost (fills it needs end before its next texel), if its
        // first texel found siblings to evaluate.
        let at = {
            let fills = self.co_fills.borrow();
            let i = fills.len().checked_sub(1);
            i.filter(|&i| {
                let f = &fills[i];
                f.graph == graph && f.node == node && f.level == req.level && f.tile == place.tile
            })
        };
        let Some(at) = at else {
            return mean(&self.fill(graph, node, &fp));
        };
        // Taken out for the evaluation, during which nested fills (a cached node upstream) push
        // and pop their own entries.
        let nodes = std::mem::take(&mut self.co_fills.borrow_mut()[at].nodes);
        let mut values = std::mem::take(&mut *self.co_values.borrow_mut());
        values.resize(nodes.len(), Filtered::zero(graph::ValueType::Float));
        self.with_scratch(graph, |g, scratch| {
            g.eval_nodes_direct(&nodes, &fp, scratch, &self.for_graph(graph), &mut values)
        });
        let v = mean(&values[0]);
        let mut fills = self.co_fills.borrow_mut();
        let co = &mut fills[at];
        for (k, f) in values.iter().skip(1).enumerate() {
            co.texels[k * place.count as usize + place.index as usize] = mean(f);
        }
        co.nodes = nodes;
        drop(fills);
        *self.co_values.borrow_mut() = values;
        if place.index + 1 == place.count {
            self.end_co_fill(place);
        }
        v
    }

    /// At the first texel of a tile fill of `node`: the siblings it evaluates along.
    fn begin_co_fill(&self, graph: u32, node: NodeId, level: u8, place: cache::TilePlace) {
        let nc = self.cache;
        let (gi, min_level) = (graph as usize, &nc.min_level[graph as usize]);
        let mut co = self.co_spare.borrow_mut().pop().unwrap_or_default();
        (co.graph, co.node, co.level, co.tile) = (graph, node, level, place.tile);
        co.nodes.clear();
        co.nodes.push(node);
        let size = i64::from(nc.cache.config().tile_size);
        let texel = [i64::from(place.tile[0]) * size, i64::from(place.tile[1]) * size];
        for &(s, tex) in &nc.siblings[gi][node.0 as usize] {
            if min_level[s.0 as usize] <= level && !nc.cache.is_resident(tex, level, texel) {
                co.nodes.push(s);
            }
        }
        if co.nodes.len() == 1 {
            self.co_spare.borrow_mut().push(co);
            return;
        }
        co.texels.clear();
        co.texels.resize((co.nodes.len() - 1) * place.count as usize, [0.0; 3]);
        self.co_fills.borrow_mut().push(co);
    }

    /// After the last texel of a co-filling tile fill: the siblings' tiles made from their
    /// texels (those another thread has filled meanwhile are left as they are).
    fn end_co_fill(&self, place: cache::TilePlace) {
        let Some(co) = self.co_fills.borrow_mut().pop() else { return };
        let n = place.count as usize;
        let textures = &self.cache.textures[co.graph as usize];
        for (&s, texels) in co.nodes[1..].iter().zip(co.texels.chunks_exact(n)) {
            let tex = textures[s.0 as usize].expect("a sibling is cached");
            self.cache.cache.prefill(tex, co.level, co.tile, &|r: cache::TexelRequest| {
                let i = r.place.expect("a fill's texels have places").index as usize;
                texels[i]
            });
        }
        self.co_spare.borrow_mut().push(co);
    }
}

/// Requests evaluate their plans with cached nodes answered from the tiles.
impl GraphSource for CacheAccess<'_> {
    #[inline]
    fn evaluate(
        &mut self,
        g: &Graph,
        request: &MaterialGraph,
        fp: &Footprint,
        scratch: &mut EvalScratch,
        out: &mut [Filtered],
    ) {
        g.eval(&request.order, fp, scratch, &self.for_graph(request.graph), out);
    }

    /// The statistics of every tile fill's evaluations so far.
    fn merge_stats_into(&self, stats: &mut [EvalStats]) {
        for (scratches, out) in self.pool.borrow().iter().zip(stats.iter_mut()) {
            for s in scratches {
                s.merge_stats_into(out);
            }
        }
    }
}

/// The [`NodeOverride`] that answers cached nodes of one graph from the tile cache.
pub struct GraphOverride<'s, 'a> {
    access: &'s CacheAccess<'a>,
    graph: u32,
    /// The last footprint covariance asked about and its level at [`LEVEL0_TEXELS_PER_UV`]:
    /// every cached node of an evaluation is asked at the same footprint, and each computed the
    /// level (two logarithms and a square root) and the cache again.
    level: Cell<Option<(glam::Mat2, f32)>>,
}

impl GraphOverride<'_, '_> {
    /// [`cache::level_for`] of `cov` at [`LEVEL0_TEXELS_PER_UV`], computed once per covariance.
    #[inline]
    fn level(&self, cov: glam::Mat2) -> f32 {
        match self.level.get() {
            Some((c, l)) if c == cov => l,
            _ => {
                let l = cache::level_for(cov, LEVEL0_TEXELS_PER_UV);
                self.level.set(Some((cov, l)));
                l
            }
        }
    }
}

impl GraphOverride<'_, '_> {
    /// Whether the tiles answer `node` at `fp`, and if so its texture and the level to read
    /// (`None` for a baked texture, read at its own density): not where the footprint is finer
    /// than the plan's threshold for the node (or level 0), which is evaluated directly.
    #[inline]
    fn answered(&self, node: NodeId, fp: &Footprint) -> Option<(cache::TextureId, Option<f32>)> {
        let nc = self.access.cache;
        let (g, i) = (self.graph as usize, node.0 as usize);
        let tex = nc.textures[g][i]?;
        if nc.baked {
            return Some((tex, None));
        }
        let level = self.level(fp.cov);
        (level >= f32::from(nc.min_level[g][i])).then_some((tex, Some(level)))
    }
}

impl NodeOverride for GraphOverride<'_, '_> {
    fn never_answers(&self) -> bool {
        self.access.cache.uncached[self.graph as usize]
    }

    #[inline]
    fn answers(&self, node: NodeId, fp: &Footprint) -> bool {
        self.answered(node, fp).is_some()
    }

    fn lookup(&self, node: NodeId, fp: &Footprint) -> Option<Filtered> {
        let nc = self.access.cache;
        let (tex, level) = self.answered(node, fp)?;
        let fill = |req: cache::TexelRequest| self.access.fill_texel(self.graph, node, &req);
        let v = match level {
            Some(level) => self.access.reader.lookup_with_level(tex, fp.uv, fp.cov, level, nc.filter, &fill),
            None => self.access.reader.lookup(tex, fp.uv, fp.cov, nc.filter, &fill),
        };
        let ty = self.access.graphs[self.graph as usize].graph().node_type(node);
        let mut out = Filtered::zero(ty);
        for (k, m) in out.ch.iter_mut().enumerate().take(3) {
            *m = Moments::constant(v[k]);
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform numbers in [0, 1) from a xorshift generator seeded with `s` (not 0).
    fn xorshift(mut s: u64) -> impl FnMut() -> f64 {
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Answers one node with a fixed value (its own value stripped of spread and gradient, as a
    /// means-only tile would).
    struct Fixed(NodeId, Filtered);

    impl NodeOverride for Fixed {
        fn lookup(&self, node: NodeId, _: &Footprint) -> Option<Filtered> {
            (node == self.0).then_some(self.1)
        }
    }

    /// For every cacheable node of `g`: whether replacing its value by its mean alone (as a
    /// means-only tile would) moved some output's mean at random uv and footprints; asserts it
    /// never does where `means_suffice` says it may not. Returns (accepted, refused and moved).
    fn check_means_suffice(name: &str, g: &Graph, next: &mut impl FnMut() -> f32) -> (usize, usize) {
        let ok = means_suffice(g);
        let outputs: Vec<graph::OutputId> = g.outputs().iter().filter_map(|o| g.output_id(&o.name)).collect();
        let order = g.eval_order(&outputs);
        let mut scratch = EvalScratch::new(g);
        let (mut plain, mut fixed) = (
            vec![Filtered::zero(ValueType::Float); outputs.len()],
            vec![Filtered::zero(ValueType::Float); outputs.len()],
        );
        let (mut accepted, mut moved_where_refused) = (0, 0);
        for id in g.node_ids().filter(|&id| worth_caching(g, id) && channels(g.node_type(id)).is_some()) {
            let mut moved = false;
            for _ in 0..24 {
                let uv = glam::Vec2::new(next() * 4.0 - 1.0, next() * 4.0 - 1.0);
                let sigma = 10f32.powf(next() * 5.0 - 5.0);
                let fp = Footprint::isotropic(uv, sigma);
                g.eval(&order, &fp, &mut scratch, &graph::NoOverride, &mut plain);
                let mut v = g.eval_node_direct(id, &fp, &mut scratch, &graph::NoOverride);
                for c in v.ch.iter_mut() {
                    *c = Moments::constant(c.mean);
                }
                g.eval(&order, &fp, &mut scratch, &Fixed(id, v), &mut fixed);
                for (a, b) in plain.iter().zip(&fixed) {
                    for k in 0..a.ty.channels() {
                        let (x, y) = (a.ch[k].mean, b.ch[k].mean);
                        let same = x.to_bits() == y.to_bits() || (x - y).abs() <= 1e-5 * (1.0 + x.abs());
                        assert!(
                            same || !ok[id.0 as usize],
                            "{name}: node {} is said to need its mean alone, but an output's mean moved \
                             from {x} to {y} at uv {uv}, σ {sigma}",
                            g.node_name(id)
                        );
                        moved |= !same;
                    }
                }
            }
            accepted += usize::from(ok[id.0 as usize]);
            moved_where_refused += usize::from(moved && !ok[id.0 as usize]);
            if g.node_name(id) == "NG_rust/rust_field" {
                assert!(!ok[id.0 as usize] && moved, "rust_field: refused {} moved {moved}", !ok[id.0 as usize]);
            }
        }
        (accepted, moved_where_refused)
    }

    /// Checked by evaluation, not by the rule's own reasoning: every cacheable node of five demo
    /// graphs and of MaterialX's own test-suite documents (`shared/mtlx-suite`, written
    /// elsewhere) is replaced by its mean alone at random uv and footprints. Where
    /// `means_suffice` says yes, every output's mean must be unchanged; and the rule must say no
    /// somewhere it matters (rusted_metal's `rust_field`, read by smoothstep masks, whose
    /// replacement moves some output).
    #[test]
    fn means_suffice_where_replacing_a_node_by_its_mean_keeps_the_outputs_means() {
        let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut uniform = xorshift(0x2545_F491_4F6C_DD1D);
        let mut next = || uniform() as f32;
        let add = |t: &mut (usize, usize), (a, m): (usize, usize)| *t = (t.0 + a, t.1 + m);
        let mut demo = (0, 0);
        for name in ["rusted_metal.xml", "brick_moss.xml", "tiles_planks.xml", "poster_wall.xml", "marble.xml"] {
            let scene =
                crate::loader::load_file(&root.join("scenes").join(name), &[]).unwrap_or_else(|e| panic!("{e}"));
            for sg in &scene.graphs {
                add(&mut demo, check_means_suffice(name, sg.graph(), &mut next));
            }
        }
        assert!(demo.0 >= 10 && demo.1 >= 5, "{} accepted, {} refused and moved", demo.0, demo.1);
        // MaterialX's documents (where the shared folder is beside the clone).
        // Its documents lie one folder deep, by category.
        let list = |d: std::path::PathBuf| std::fs::read_dir(d).into_iter().flatten().flatten().map(|e| e.path());
        let mut docs: Vec<std::path::PathBuf> = list(root.join("../shared/mtlx-suite/docs"))
            .flat_map(list)
            .filter(|p| p.extension().is_some_and(|x| x == "mtlx"))
            .collect();
        docs.sort();
        let opts = graph::LoadOptions { lenient: true, ..graph::LoadOptions::default() };
        let mut suite_totals = (0, 0);
        for p in &docs {
            if let Ok(doc) = graph::Document::load_with(p, &opts) {
                add(&mut suite_totals, check_means_suffice(&p.display().to_string(), doc.graph(), &mut next));
            }
        }
        eprintln!(
            "{} MaterialX documents: {} nodes accepted, {} refused and moved",
            docs.len(),
            suite_totals.0,
            suite_totals.1
        );
    }

    /// The cache picks a cached node's level with `cache::level_for` (f32) and the profiler and
    /// the footprint AOV with `footprint::lod` (f64): the planner's predictions assume they agree.
    #[test]
    fn cache_levels_and_footprint_lods_agree() {
        let mut next = xorshift(0x9E37_79B9_7F4A_7C15);
        let mut covs: Vec<glam::DMat2> = (0..20_000)
            .map(|_| {
                // A covariance R diag(σ₁², σ₂²) Rᵀ with σ from 1e-9 to 1e3 uv and any orientation.
                let (s1, s2) = (10f64.powf(next() * 12.0 - 9.0), 10f64.powf(next() * 12.0 - 9.0));
                let a = next() * std::f64::consts::TAU;
                let r = glam::DMat2::from_angle(a);
                r * glam::DMat2::from_diagonal(glam::DVec2::new(s1 * s1, s2 * s2)) * r.transpose()
            })
            .collect();
        covs.extend([
            glam::DMat2::ZERO,
            glam::DMat2::from_diagonal(glam::DVec2::new(f64::INFINITY, 1.0)),
            glam::DMat2::from_diagonal(glam::DVec2::new(f64::NAN, 1.0)),
            glam::DMat2::from_diagonal(glam::DVec2::new(-1e-6, 1e-6)),
        ]);
        for density in [1.0, 64.0, f64::from(LEVEL0_TEXELS_PER_UV), 0.0] {
            for c in &covs {
                let fine = footprint::lod(*c, density);
                let coarse = cache::level_for(c.as_mat2(), density as f32);
                // f32 covariances keep ~7 digits: the levels agree to ~1e-6 × log2 of the scale.
                assert!(
                    (fine - coarse).abs() <= 1e-4 || fine == coarse,
                    "cov {c} density {density}: {fine} vs {coarse}"
                );
            }
        }
    }
}
