//! One run: a child `tessera render` of this same executable, and what its stats file says.

use super::results::{CacheCounts, Phases, PlanComparison};
use super::{Config, PLAN_QUANTITIES, REF_SEED_OFFSET};
use render::film::Image;
use render::stats::{PlanStats, RenderStats, STATS_SCHEMA};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

/// A successful run, parsed.
pub(super) struct Sample {
    pub(super) process_s: f64,
    pub(super) phases: Phases,
    pub(super) samples: u64,
    pub(super) rays: u64,
    pub(super) samples_per_s: f64,
    pub(super) node_evaluations: u64,
    pub(super) cache: Option<CacheCounts>,
    pub(super) plan: Option<PlanComparison>,
    pub(super) stats: Value,
    pub(super) image: Image,
}

impl Sample {
    pub(super) fn time_s(&self) -> f64 {
        let p = &self.phases;
        p.profile_s + p.plan_s + p.cache_setup_s + p.render_s
    }
}

/// What a child renders.
pub(super) enum Job<'a> {
    Strategy(&'a str),
    LowerBound,
    Reference,
}

pub(super) fn run_child(
    cfg: &Config,
    scene: &Path,
    job: Job,
    work: &Path,
    name: &str,
) -> std::result::Result<Sample, String> {
    let exr = work.join(format!("{name}.exr"));
    let json = work.join(format!("{name}.json"));
    let _ = std::fs::remove_file(&exr);
    let _ = std::fs::remove_file(&json);
    let (spp, seed) = match job {
        Job::Reference => (cfg.ref_spp, cfg.seed.wrapping_add(REF_SEED_OFFSET)),
        _ => (cfg.spp, cfg.seed),
    };
    let mut cmd = Command::new(&cfg.exe);
    cmd.arg("render")
        .arg(scene)
        .arg("--accel")
        .arg(render::accel::backend().name())
        .arg("--quiet")
        .arg("--spp")
        .arg(spp.to_string())
        .arg("--seed")
        .arg(seed.to_string());
    cmd.arg("--out").arg(&exr).arg("--stats-json").arg(&json).arg("-D").arg(format!("res={}", cfg.res));
    for d in &cfg.defines {
        cmd.arg("-D").arg(d);
    }
    if let Some(t) = cfg.threads {
        cmd.arg("--threads").arg(t.to_string());
    }
    cmd.arg("--budget-mb").arg(cfg.budget_mb.to_string());
    match job {
        Job::Strategy(s) => cmd.arg("--strategy").arg(s),
        Job::LowerBound => cmd.arg("--free-textures"),
        Job::Reference => cmd.args(["--strategy", "none", "--aov", "footprint"]),
    };
    let t0 = Instant::now();
    let out = cmd.output().map_err(|e| format!("cannot run {}: {e}", cfg.exe.display()))?;
    let process_s = t0.elapsed().as_secs_f64();
    if !out.status.success() {
        return Err(child_error(&out));
    }
    let stats: Value = std::fs::read(&json)
        .map_err(|e| format!("{}: cannot read the stats JSON: {e}", json.display()))
        .and_then(|b| serde_json::from_slice(&b).map_err(|e| format!("{}: bad stats JSON: {e}", json.display())))?;
    let image = Image::load_exr(&exr).map_err(|e| format!("cannot read the rendered image: {e}"))?;
    parse_sample(stats, image, process_s).map_err(|e| format!("{}: {e}", json.display()))
}

/// The child's error message: its `error:` line, or the last lines of its stderr.
fn child_error(out: &std::process::Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = err.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
    let msg = match lines.iter().position(|l| l.starts_with("error")) {
        Some(i) => {
            let first = lines[i].strip_prefix("error:").unwrap_or(lines[i]).trim();
            std::iter::once(first).chain(lines[i + 1..].iter().take(2).copied()).collect::<Vec<_>>().join(" ")
        }
        None => lines.iter().rev().take(3).rev().copied().collect::<Vec<_>>().join(" "),
    };
    let status = match out.status.code() {
        Some(c) => format!("exit status {c}"),
        None => "killed by a signal".to_string(),
    };
    let mut msg = if msg.is_empty() { status } else { format!("{msg} ({status})") };
    if msg.len() > 600 {
        let cut = (0..=600).rev().find(|&i| msg.is_char_boundary(i)).unwrap_or(0);
        msg.truncate(cut);
        msg.push('…');
    }
    msg
}

fn parse_sample(stats: Value, image: Image, process_s: f64) -> std::result::Result<Sample, String> {
    let typed: RenderStats =
        serde_json::from_value(stats.clone()).map_err(|e| format!("not a valid {STATS_SCHEMA} document: {e}"))?;
    let plan = typed.plan.as_ref();
    let phases = Phases {
        load_s: typed.phases.load_s,
        profile_s: plan.map_or(0.0, |p| p.profile_s),
        plan_s: plan.map_or(0.0, |p| p.plan_s),
        cache_setup_s: typed.phases.cache_setup_s,
        render_s: typed.phases.render_s,
        write_s: typed.phases.write_s,
    };
    let cache =
        typed.cache.as_ref().map(|c| CacheCounts { cached_nodes: c.cached_nodes.len() as u64, totals: c.totals });
    let samples = typed.counts.samples;
    let mut sample = Sample {
        process_s,
        phases,
        samples,
        rays: typed.counts.rays + typed.counts.shadow_rays,
        samples_per_s: samples as f64 / phases.render_s.max(1e-12),
        node_evaluations: typed.node_evaluations(),
        cache,
        plan: None,
        stats: Value::Null,
        image,
    };
    sample.plan = plan.map(|p| plan_comparison(p, &sample));
    sample.stats = stats;
    Ok(sample)
}

fn plan_comparison(plan: &PlanStats, s: &Sample) -> PlanComparison {
    let c = s.cache.clone().unwrap_or_default().totals;
    let measured_values = [
        s.node_evaluations as f64,
        c.lookups as f64,
        c.tiles_filled as f64,
        c.texels_filled as f64,
        c.peak_bytes as f64,
        s.phases.render_s,
    ];
    let p = &plan.predicted;
    let predicted_values = [p.evaluations, p.lookups, p.tiles_filled, p.texels_filled, p.peak_bytes, p.render_s];
    let mut predicted = BTreeMap::new();
    let mut measured = BTreeMap::new();
    let mut ratio = BTreeMap::new();
    for ((k, m), p) in PLAN_QUANTITIES.iter().zip(measured_values).zip(predicted_values) {
        measured.insert(k.to_string(), m);
        predicted.insert(k.to_string(), p);
        if m > 0.0 {
            ratio.insert(k.to_string(), p / m);
        }
    }
    let cached_nodes = plan.cached_nodes.clone();
    PlanComparison { profile_s: s.phases.profile_s, plan_s: s.phases.plan_s, cached_nodes, predicted, measured, ratio }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plans_are_compared_with_the_measured_counters_and_timed_end_to_end() {
        let stats = serde_json::json!({
            "phases": { "load_s": 0.01, "cache_setup_s": 0.5, "render_s": 2.0, "write_s": 0.02 },
            "counts": { "samples": 1000, "rays": 10, "shadow_rays": 5 },
            "graphs": [ { "nodes": [ { "evaluations": 30 }, { "evaluations": 70 } ] },
                        { "nodes": [ { "evaluations": 100 } ] } ],
            "cache": { "cached_nodes": ["g/a", "g/b"], "budget_bytes": 1000, "peak_bytes": 400, "lookups": 50,
                       "tile_hits": 40, "tile_misses": 10, "tiles_filled": 10, "texels_filled": 640,
                       "evictions": 0, "refills": 0 },
            "plan": { "strategy": "auto", "profile_s": 0.25, "plan_s": 0.25, "cached_nodes": ["g/a", "g/b"],
                      "predicted": { "evaluations": 100, "lookups": 50, "tiles_filled": 20, "texels_filled": 1280,
                                     "peak_bytes": 800, "texture_thread_s": 0.5, "render_s": 1.0 } }
        });
        let stats_with_plan = stats.clone();
        let s = parse_sample(stats, Image::new(1, 1), 3.0).unwrap();
        assert_eq!(s.time_s(), 0.25 + 0.25 + 0.5 + 2.0);
        assert_eq!((s.node_evaluations, s.rays, s.samples), (200, 15, 1000));
        assert_eq!(s.samples_per_s, 500.0);
        let p = s.plan.unwrap();
        assert_eq!(p.cached_nodes, ["g/a", "g/b"]);
        assert_eq!(p.measured["evaluations"], 200.0);
        assert_eq!(p.measured["texels_filled"], 640.0);
        assert_eq!(p.ratio["evaluations"], 0.5);
        assert_eq!(p.ratio["peak_bytes"], 2.0);
        assert_eq!(p.ratio["render_s"], 0.5);
        assert_eq!(p.ratio["texels_filled"], 2.0);
        assert_eq!(p.ratio["tiles_filled"], 2.0);
        // A plan whose prediction lacks a quantity is not a valid stats document.
        let mut partial = stats_with_plan.clone();
        partial["plan"]["predicted"].as_object_mut().unwrap().remove("texels_filled");
        assert!(parse_sample(partial, Image::new(1, 1), 3.0).err().unwrap().contains("texels_filled"));
        // Stats without a plan, a cache or a render time.
        let bare = serde_json::json!({ "phases": { "load_s": 0.0, "render_s": 1.0 }, "counts": { "samples": 4 },
                                       "cache": null });
        let b = parse_sample(bare, Image::new(1, 1), 1.0).unwrap();
        assert!(b.plan.is_none() && b.cache.is_none() && b.time_s() == 1.0);
        let broken = serde_json::json!({ "phases": {}, "counts": { "samples": 4 } });
        assert!(parse_sample(broken, Image::new(1, 1), 1.0).err().unwrap().contains("render_s"));
    }
}
