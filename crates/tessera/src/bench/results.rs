//! The results of a benchmark, as `results.json` holds them: scenes, strategies, repeats, summaries.

use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;

/// The whole benchmark: `results.json`.
#[derive(Serialize)]
pub struct BenchResults {
    pub schema: &'static str,
    pub tessera_version: &'static str,
    pub created_unix_s: u64,
    pub settings: Settings,
    pub scenes: Vec<SceneResult>,
}

/// How the benchmark was run.
#[derive(Serialize)]
pub struct Settings {
    pub suite: String,
    pub res: u32,
    pub spp: u32,
    pub seed: u64,
    pub repeats: u32,
    pub ref_spp: u32,
    pub ref_seed: u64,
    pub strategies: Vec<String>,
    pub budget_mb: f64,
    pub threads: Option<u64>,
    pub defines: Vec<String>,
    pub quick: bool,
    /// What `time_s` adds up.
    pub time_definition: &'static str,
    pub flip: FlipSettings,
}

/// Which ꟻLIP and at what viewing condition.
#[derive(Serialize)]
pub struct FlipSettings {
    pub implementation: &'static str,
    pub pixels_per_degree: f32,
}

/// One scene: its reference and one entry per strategy (the lower bound last).
#[derive(Serialize)]
pub struct SceneResult {
    pub name: String,
    pub file: String,
    pub width: Option<u64>,
    pub height: Option<u64>,
    pub reference: Option<ReferenceInfo>,
    pub error: Option<String>,
    pub runs: Vec<StrategyResult>,
    #[serde(skip)]
    pub reference_png: Option<Vec<u8>>,
    #[serde(skip)]
    pub footprint_png: Option<Vec<u8>>,
}

/// The high-spp reference image of a scene.
#[derive(Serialize)]
pub struct ReferenceInfo {
    pub spp: u32,
    pub seed: u64,
    pub key: String,
    pub reused: bool,
    pub render_s: Option<f64>,
    pub image: String,
    pub footprint_image: Option<String>,
}

/// One strategy on one scene, over all repeats.
#[derive(Serialize)]
pub struct StrategyResult {
    pub strategy: String,
    pub lower_bound: bool,
    pub error: Option<String>,
    pub repeats: Vec<RepeatResult>,
    pub summary: Option<Summary>,
    pub image: Option<String>,
    pub flip_image: Option<String>,
    pub stats: Option<String>,
    #[serde(skip)]
    pub assets: RunAssets,
}

/// What the report embeds for a strategy (not in results.json).
#[derive(Default)]
pub struct RunAssets {
    pub png: Option<Vec<u8>>,
    pub flip_png: Option<Vec<u8>>,
    pub stats: Option<Value>,
}

/// One repeat of one strategy.
#[derive(Serialize, Clone)]
pub struct RepeatResult {
    pub repeat: u32,
    /// Position of this run inside its repeat (0 = first).
    pub order: u32,
    pub time_s: f64,
    pub process_s: f64,
    pub ratio_to_lower_bound: Option<f64>,
}

/// Median, minimum and maximum over repeats.
#[derive(Serialize, Clone, Copy)]
pub struct Spread {
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

impl Spread {
    pub(super) fn of(values: &[f64]) -> Option<Spread> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) };
        Some(Spread { median, min: v[0], max: v[n - 1] })
    }
}

/// Wall time of each phase, seconds (medians in a summary).
#[derive(Serialize, Clone, Copy, Default)]
pub struct Phases {
    pub load_s: f64,
    pub profile_s: f64,
    pub plan_s: f64,
    pub cache_setup_s: f64,
    pub render_s: f64,
    pub write_s: f64,
}

/// The tile cache's counters of a run: how many nodes it cached, and the render's totals.
#[derive(Serialize, Clone, Default)]
pub struct CacheCounts {
    pub cached_nodes: u64,
    #[serde(flatten)]
    pub totals: render::stats::CacheTotals,
}

/// Image error against the reference.
#[derive(Serialize, Clone, Copy)]
pub struct ImageError {
    pub rel_mse: f64,
    pub flip: f64,
}

/// A plan's predictions beside the measured values of the same run.
#[derive(Serialize, Clone)]
pub struct PlanComparison {
    pub profile_s: f64,
    pub plan_s: f64,
    pub cached_nodes: Vec<String>,
    pub predicted: BTreeMap<String, f64>,
    pub measured: BTreeMap<String, f64>,
    /// predicted / measured, where both are known and measured is positive.
    pub ratio: BTreeMap<String, f64>,
}

/// A strategy's numbers: times are medians over repeats (with spread), counters are those of
/// the median-time run.
#[derive(Serialize, Clone)]
pub struct Summary {
    pub runs_ok: u32,
    /// End-to-end time the user waits for, less loading and writing:
    /// profile_s + plan_s + cache_setup_s + render_s.
    pub time_s: Spread,
    pub ratio_to_lower_bound: Option<Spread>,
    pub process_s: Spread,
    pub phases: Phases,
    pub samples: u64,
    pub samples_per_s: f64,
    pub rays: u64,
    pub node_evaluations: u64,
    pub cache: Option<CacheCounts>,
    pub image_error: Option<ImageError>,
    pub images_identical_across_repeats: bool,
    pub plan: Option<PlanComparison>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spreads_are_medians_with_extremes() {
        let s = Spread::of(&[3.0, 1.0, 2.0]).unwrap();
        assert_eq!((s.median, s.min, s.max), (2.0, 1.0, 3.0));
        assert_eq!(Spread::of(&[4.0, 1.0]).unwrap().median, 2.5);
        assert!(Spread::of(&[f64::NAN]).is_none());
    }
}
