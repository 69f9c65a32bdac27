//! Plan files (schema [`PLAN_SCHEMA`]): which nodes a render caches, as the planner chose them,
//! with what the model predicted. `tessera render --strategy plan:FILE` reads them.

use serde::{Deserialize, Serialize};

use crate::error::{PlanError, Result};
use crate::model::{PlanSpec, Prediction, Target};
use crate::planner::SearchResult;
use crate::profile::{Profile, SceneId};

/// The schema name and version every plan file carries.
pub const PLAN_SCHEMA: &str = "tessera.plan/1";

/// A plan file.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct PlanFile {
    /// [`PLAN_SCHEMA`].
    pub schema: String,
    /// The scene the plan was made for.
    pub scene: SceneId,
    /// The memory budget it was made for, in bytes.
    pub budget_bytes: u64,
    /// The render it was made for.
    pub target: TargetJson,
    /// The cached nodes.
    pub nodes: Vec<PlanNode>,
    /// What the model predicted for it.
    pub predicted: Summary,
    /// How it was found.
    pub search: SearchInfo,
}

/// A cached node of a plan.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct PlanNode {
    /// The graph (document) name.
    pub graph: String,
    /// The node's full name, `nodegraph/node`.
    pub node: String,
    /// Finest level served from the cache (finer requests evaluate the node); 0 = every level.
    #[serde(default)]
    pub min_level: u8,
}

/// [`Target`] in JSON.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct TargetJson {
    /// Camera samples.
    pub samples: u64,
    /// Threads.
    pub threads: u32,
}

/// The totals the model predicts for a plan (a [`Prediction`]'s, in plan files and render stats)
/// and a render measures (`tessera analyze`, `--strategy auto` reports): one type for both, so
/// predicted and measured are compared field by field.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Summary {
    /// Node evaluations.
    pub evaluations: f64,
    /// Cache lookups.
    pub lookups: f64,
    /// Tiles filled.
    pub tiles_filled: f64,
    /// Texels filled.
    pub texels_filled: f64,
    /// Bytes of the working set.
    pub peak_bytes: f64,
    /// Thread-seconds on textures.
    pub texture_thread_s: f64,
    /// Wall seconds of the render.
    pub render_s: f64,
}

impl From<&Prediction> for Summary {
    fn from(p: &Prediction) -> Summary {
        Summary {
            evaluations: p.evaluations,
            lookups: p.lookups,
            tiles_filled: p.tiles_filled,
            texels_filled: p.texels_filled,
            peak_bytes: p.peak_bytes,
            texture_thread_s: p.texture_thread_s,
            render_s: p.render_s,
        }
    }
}

/// How the plan was found.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct SearchInfo {
    /// Search method.
    pub method: String,
    /// Candidate nodes.
    pub candidates: usize,
    /// Plans predicted.
    pub plans_evaluated: u64,
    /// Seconds the search took.
    pub seconds: f64,
}

impl PlanFile {
    /// The plan file for a search result.
    pub fn new(profile: &Profile, target: Target, budget_bytes: u64, r: &SearchResult) -> PlanFile {
        PlanFile {
            schema: PLAN_SCHEMA.into(),
            scene: profile.scene.clone(),
            budget_bytes,
            target: TargetJson { samples: target.samples, threads: target.threads },
            nodes: nodes_of(profile, &r.plan),
            predicted: Summary::from(&r.prediction),
            search: SearchInfo {
                method: r.method.clone(),
                candidates: r.candidates,
                plans_evaluated: r.plans_evaluated,
                seconds: r.seconds,
            },
        }
    }

    /// Parses and checks a plan file.
    pub fn from_json(text: &str) -> Result<PlanFile> {
        let p: PlanFile = serde_json::from_str(text)
            .map_err(|e| PlanError::Plan(format!("line {} column {}: {e}", e.line(), e.column())))?;
        if p.schema != PLAN_SCHEMA {
            return Err(PlanError::Plan(format!("schema is '{}', expected '{PLAN_SCHEMA}'", p.schema)));
        }
        if let Some(n) = p.nodes.iter().find(|n| n.min_level > 31) {
            return Err(PlanError::Plan(format!("node '{}': min_level {} is beyond 31", n.node, n.min_level)));
        }
        Ok(p)
    }

    /// The plan as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a plan serialises")
    }

    /// The plan over `profile`'s graphs; errors name nodes the profile does not have.
    pub fn to_spec(&self, profile: &Profile) -> Result<PlanSpec> {
        let mut spec = PlanSpec::none(profile);
        for pn in &self.nodes {
            let g = profile
                .graphs
                .iter()
                .position(|g| g.name == pn.graph)
                .ok_or_else(|| PlanError::Plan(format!("graph '{}' is not in the profile", pn.graph)))?;
            let n = profile.graphs[g]
                .nodes
                .iter()
                .position(|n| n.name == pn.node)
                .ok_or_else(|| PlanError::Plan(format!("node '{}' is not in graph '{}'", pn.node, pn.graph)))?;
            if !profile.graphs[g].nodes[n].cacheable {
                return Err(PlanError::Plan(format!("node '{}' cannot be cached", pn.node)));
            }
            spec.cached[g][n] = Some(pn.min_level);
        }
        Ok(spec)
    }
}

/// The cached nodes of `plan` by name.
pub fn nodes_of(profile: &Profile, plan: &PlanSpec) -> Vec<PlanNode> {
    let mut out = Vec::new();
    for (g, graph) in profile.graphs.iter().enumerate() {
        for (n, node) in graph.nodes.iter().enumerate() {
            if let Some(min_level) = plan.cached[g][n] {
                out.push(PlanNode { graph: graph.name.clone(), node: node.name.clone(), min_level });
            }
        }
    }
    out
}
