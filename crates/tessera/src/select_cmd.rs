//! Selective caching on the command line: `tessera profile`, `tessera plan`, `tessera analyze`,
//! and the pipeline behind `tessera render --strategy auto` (profile, plan, render, compare).

use anyhow::{bail, Context, Result};
use plan::profile::SceneId;
use plan::{Model, PlanFile, PlanSpec, Prediction, Profile, SearchOptions, SearchResult, Summary, Target};
use render::integrator::{FilterScale, RenderSettings};
use render::pathfootprint::FootprintMode;
use render::scene::Scene;
use render::stats::{CacheTotals, RenderStats, STATS_SCHEMA};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::{load_scene, parse_defines, write_atomic, DEFAULT_SCENE};

/// Default share of the final render's pixels that `--strategy auto` profiles.
pub const DEFAULT_PROFILE_SHARE: f64 = 0.01;
/// Share of the profiled pixels that take a second, timed sample (see `ProfileOptions`).
const WARM_FRACTION: f64 = 0.25;
/// Fewest samples a profile takes (or every pixel once). Predictions of the demo scenes at
/// 128² and 16 spp from 1024 samples erred as much as from 4096 (the host's drift between runs
/// dominates either) and chose the same nodes, at a quarter of the cost.
const MIN_PROFILE_SAMPLES: u64 = 1024;

#[derive(clap::Args, Debug)]
pub struct ProfileArgs {
    /// Scene file (Mitsuba 3 XML); without it, the embedded demo scene.
    scene: Option<PathBuf>,
    /// Samples per traced pixel.
    #[arg(long, default_value_t = 1)]
    spp: u32,
    /// Fraction of the pixels traced, in (0, 1].
    #[arg(long, default_value_t = 0.25)]
    pixel_fraction: f64,
    /// Seed of the random streams (default: the scene's).
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Override a scene <default>: -D name=value (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE")]
    define: Vec<String>,
    /// Texture filter width relative to the footprint (as for render); `auto` is resolved for the
    /// final render's sample count, `--final-spp`.
    #[arg(long, default_value = "1", value_parser = |s: &str| s.parse::<FilterScale>())]
    filter_scale: FilterScale,
    /// Samples per pixel of the final render the profile is for (default: the scene's): sets
    /// the texture filter width under `--filter-scale auto`, so that the profile sees the
    /// footprints that render will filter with.
    #[arg(long)]
    final_spp: Option<u32>,
    /// Where to write the profile.
    #[arg(long, default_value = "profile.json")]
    out: PathBuf,
    /// No summary.
    #[arg(long)]
    quiet: bool,
}

/// The final render a plan is for.
#[derive(clap::Args, Debug)]
pub struct FinalRender {
    /// Memory budget of the tile cache in MiB.
    #[arg(long, default_value_t = 512.0)]
    budget_mb: f64,
    /// Samples per pixel of the final render (default: the scene's).
    #[arg(long)]
    spp: Option<u32>,
    /// Threads of the final render (default: the profile's).
    #[arg(long)]
    threads: Option<u32>,
}

#[derive(clap::Args, Debug)]
pub struct PlanArgs {
    /// A profile (tessera.profile/1).
    profile: PathBuf,
    #[command(flatten)]
    render: FinalRender,
    /// Where to write the plan.
    #[arg(long, default_value = "plan.json")]
    out: PathBuf,
    /// Exhaustive search up to this many candidate nodes (local search beyond).
    #[arg(long, default_value_t = 12)]
    exhaustive_limit: usize,
    /// Cache every level of a chosen node (no per-node level thresholds).
    #[arg(long)]
    no_thresholds: bool,
}

#[derive(clap::Args, Debug)]
pub struct AnalyzeArgs {
    /// A profile (tessera.profile/1), written by tessera or another renderer.
    profile: PathBuf,
    #[command(flatten)]
    render: FinalRender,
    /// Measured renders (--stats-json files) to compare with their predictions.
    #[arg(long = "measured")]
    measured: Vec<PathBuf>,
    /// Folder for the report (table.md and SVG plots).
    #[arg(long)]
    report: Option<PathBuf>,
}

/// The scene's identity: its file name and a hash of its text and defines.
pub fn scene_id(path: Option<&Path>, defines: &[(String, String)]) -> Result<SceneId> {
    let (name, text) = match path {
        Some(p) => {
            (p.display().to_string(), std::fs::read(p).with_context(|| format!("{}: cannot read", p.display()))?)
        }
        None => ("<embedded default scene>".to_string(), DEFAULT_SCENE.as_bytes().to_vec()),
    };
    let defs: String = defines.iter().map(|(k, v)| format!("{k}={v};")).collect();
    Ok(SceneId { name, hash: plan::text_hash(&[&text, defs.as_bytes()]) })
}

/// Profiles `scene` on the current rayon pool.
pub fn profile_scene(scene: &Scene, settings: RenderSettings, pixel_fraction: f64, id: SceneId) -> Result<Profile> {
    let opts = render::profiling::ProfileOptions { settings, pixel_fraction, warm_fraction: WARM_FRACTION, scene: id };
    Ok(render::profiling::profile(scene, &opts)?)
}

/// The profile's settings for a final render: `share` of its pixels (at least
/// [`MIN_PROFILE_SAMPLES`]) traced with one sample each on a hashed subset of the pixels (a
/// quarter of them take a second, timed sample; see docs/selective-caching.md), or more samples
/// per pixel when every pixel is traced. Where the final render's samples share their pixel's
/// textures (the default: first hits, and hits behind perfect mirrors and glass), those
/// evaluations, one per pixel whatever the sample count,
/// are most of its texture time, and every profile sample pays one: a share of the samples was
/// a share of the first-hit evaluations `spp` times as large (a quarter of them for a 128² image
/// at 16 spp). Where they do not share them (`--per-sample-textures`, other footprints or
/// filter scales) every sample evaluates its own, and the share is one of the samples.
pub fn auto_profile_settings(scene: &Scene, final_settings: RenderSettings, share: f64) -> (RenderSettings, f64) {
    let pixels = u64::from(scene.camera.width) * u64::from(scene.camera.height);
    let per_pixel =
        if render::integrator::shares_pixel_textures(&final_settings) { 1 } else { u64::from(final_settings.spp) };
    let want = ((pixels * per_pixel) as f64 * share).max(MIN_PROFILE_SAMPLES as f64);
    let spp = (want / pixels as f64).ceil().max(1.0) as u32;
    let fraction = (want / (pixels as f64 * f64::from(spp))).min(1.0);
    // A different seed: the profile's samples are not the final render's.
    // The final render's texture filter width (an `auto` scale depends on the sample count).
    let settings = RenderSettings {
        spp,
        seed: final_settings.seed ^ 0x005E_ED0F_F11E,
        filter_scale: FilterScale::Fixed(final_settings.filter_scale.at(final_settings.spp)),
        ..final_settings
    };
    (settings, fraction)
}

/// Plans for `target` within `budget_bytes`.
pub fn plan_profile(
    profile: &Profile,
    target: Target,
    budget_bytes: f64,
    opts: SearchOptions,
) -> Result<(SearchResult, PlanFile)> {
    let model = Model::new(profile, target)?;
    let r = plan::search(&model, SearchOptions { budget_bytes, ..opts })?;
    let file = PlanFile::new(profile, target, budget_bytes as u64, &r);
    Ok((r, file))
}

/// What a render measured, in the model's terms (the quantities a prediction's [`Summary`]
/// holds; texture thread-seconds are not measured and read 0): its node evaluations, its tile
/// cache's totals if it had one, and its render time.
fn measured(evaluations: f64, cache: Option<&CacheTotals>, render_s: f64) -> Summary {
    let mut m = Summary { evaluations, render_s, ..Summary::default() };
    if let Some(c) = cache {
        m.lookups = c.lookups as f64;
        m.tiles_filled = c.tiles_filled as f64;
        m.texels_filled = c.texels_filled as f64;
        m.peak_bytes = c.peak_bytes as f64;
    }
    m
}

/// What a finished render measured, from its graph statistics and cache.
pub fn measured_of_render(
    graph_stats: &[graph::EvalStats],
    cache: Option<&render::caching::NodeCache>,
    render_s: f64,
) -> Summary {
    let evaluations = graph_stats.iter().flat_map(|g| g.evaluations.iter()).sum::<u64>() as f64;
    measured(evaluations, cache.map(CacheTotals::of).as_ref(), render_s)
}

/// What a render measured, from its `tessera.stats/1` document.
pub fn measured_of_stats(v: &RenderStats) -> Summary {
    measured(v.node_evaluations() as f64, v.cache.as_ref().map(|c| &c.totals), v.phases.render_s)
}

fn rel(pred: f64, meas: f64) -> String {
    if meas == 0.0 && pred == 0.0 {
        "0 %".into()
    } else if meas == 0.0 {
        "—".into()
    } else {
        format!("{:+.1} %", (pred - meas) / meas * 100.0)
    }
}

fn mib(b: f64) -> f64 {
    b / 1048576.0
}

/// Markdown rows comparing a prediction with a measurement.
pub fn comparison_table(rows: &[(String, Summary, Summary)]) -> String {
    let mut s = String::from("| strategy | quantity | predicted | measured | error |\n|---|---|---|---|---|\n");
    for (name, p, m) in rows {
        let q = [
            ("evaluations", p.evaluations, m.evaluations),
            ("lookups", p.lookups, m.lookups),
            ("tiles filled", p.tiles_filled, m.tiles_filled),
            ("texels filled", p.texels_filled, m.texels_filled),
            ("peak MiB", mib(p.peak_bytes), mib(m.peak_bytes)),
            ("render s", p.render_s, m.render_s),
        ];
        for (label, pv, mv) in q {
            let _ = writeln!(s, "| {name} | {label} | {pv:.4e} | {mv:.4e} | {} |", rel(pv, mv));
        }
    }
    s
}

/// Markdown table of predictions for named plans.
pub fn prediction_table(model: &Model, rows: &[(String, PlanSpec)]) -> String {
    let mut s = String::from(
        "| strategy | cached nodes | evaluations | lookups | tiles filled | MiB | texture thread-s | render s |\n|---|---|---|---|---|---|---|---|\n",
    );
    for (name, spec) in rows {
        let p = model.predict(spec);
        let _ = writeln!(
            s,
            "| {name} | {} | {:.3e} | {:.3e} | {:.0} | {:.1} | {:.2} | {:.2} |",
            spec.count(),
            p.evaluations,
            p.lookups,
            p.tiles_filled,
            mib(p.peak_bytes),
            p.texture_thread_s,
            p.render_s
        );
    }
    s
}

fn read_profile(path: &Path) -> Result<Profile> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))?;
    Profile::from_json(&text).with_context(|| format!("{}", path.display()))
}

fn target_for(profile: &Profile, spp: Option<u32>, threads: Option<u32>) -> Result<Target> {
    let spp = spp.unwrap_or(profile.render.scene_spp);
    if spp == 0 {
        bail!("the profile does not say the scene's sample count: give --spp");
    }
    let samples = u64::from(profile.render.width) * u64::from(profile.render.height) * u64::from(spp);
    Ok(Target { samples, threads: threads.unwrap_or(profile.render.threads).max(1) })
}

fn budget_bytes(mb: f64) -> Result<f64> {
    if !(mb.is_finite() && mb > 0.0 && mb <= 1.0e6) {
        bail!("--budget-mb must be a positive number of MiB (at most 1e6), got {mb}");
    }
    Ok(mb * 1048576.0)
}

/// `tessera profile`.
pub fn run_profile(args: ProfileArgs) -> Result<()> {
    let defines = parse_defines(&args.define)?;
    if args.spp == 0 || args.spp > 1 << 16 {
        bail!("--spp must be between 1 and 65536, got {}", args.spp);
    }
    if !(args.pixel_fraction > 0.0 && args.pixel_fraction <= 1.0) {
        bail!("--pixel-fraction must be in (0, 1], got {}", args.pixel_fraction);
    }
    crate::check_threads(args.threads)?;
    let scene = load_scene(args.scene.as_deref(), &defines)?;
    if scene.graphs.is_empty() {
        bail!("the scene has no procedural graphs: there is nothing to profile");
    }
    let id = scene_id(args.scene.as_deref(), &defines)?;
    let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let final_spp = args.final_spp.unwrap_or(scene.spp);
    if final_spp == 0 || final_spp > 1 << 16 {
        bail!("--final-spp must be between 1 and 65536, got {final_spp}");
    }
    let settings = RenderSettings {
        filter_scale: FilterScale::Fixed(args.filter_scale.at(final_spp)),
        footprint: FootprintMode::default(),
        ..RenderSettings::new(args.spp, args.seed.unwrap_or(scene.seed))
    };
    let profile = pool.install(|| profile_scene(&scene, settings, args.pixel_fraction, id))?;
    write_atomic(&args.out, profile.to_json().as_bytes())?;
    if !args.quiet {
        eprintln!(
            "profiled {} samples ({:.0} % of the pixels at {} spp) in {:.2} s: {} streams, texture work {:.2} thread-s, profiling tap {:.3} thread-s ({:.1} % of it); wrote {}",
            profile.render.samples,
            args.pixel_fraction * 100.0,
            args.spp,
            profile.render.wall_s,
            profile.streams.len(),
            profile.render.texture_thread_s,
            profile.render.tap_thread_s,
            100.0 * profile.render.tap_thread_s / profile.render.texture_thread_s.max(1e-12),
            args.out.display()
        );
    }
    Ok(())
}

/// `tessera plan`.
pub fn run_plan(args: PlanArgs) -> Result<()> {
    let profile = read_profile(&args.profile)?;
    let target = target_for(&profile, args.render.spp, args.render.threads)?;
    let budget = budget_bytes(args.render.budget_mb)?;
    let opts = SearchOptions {
        budget_bytes: budget,
        exhaustive_limit: args.exhaustive_limit.min(24),
        thresholds: !args.no_thresholds,
    };
    let (r, file) = plan_profile(&profile, target, budget, opts)?;
    let model = Model::new(&profile, target)?;
    println!("{}", prediction_table(&model, &standard_rows(&profile, &r.plan)));
    println!(
        "plan: {} of {} candidate nodes cached ({}; {} plans predicted in {:.3} s); wrote {}",
        r.plan.count(),
        r.candidates,
        r.method,
        r.plans_evaluated,
        r.seconds,
        args.out.display()
    );
    write_atomic(&args.out, file.to_json().as_bytes())
}

/// `none`, `outputs`, `all` and the plan, named.
pub fn standard_rows(profile: &Profile, plan: &PlanSpec) -> Vec<(String, PlanSpec)> {
    vec![
        ("none".into(), PlanSpec::none(profile)),
        ("outputs".into(), PlanSpec::outputs(profile)),
        ("all".into(), PlanSpec::all(profile)),
        ("plan".into(), plan.clone()),
    ]
}

/// The plan a measured render used: its cached node names (and thresholds of an auto plan).
fn spec_of_stats(profile: &Profile, v: &RenderStats) -> Result<PlanSpec> {
    let mut spec = PlanSpec::none(profile);
    let names = v.cache.as_ref().map(|c| c.cached_nodes.as_slice()).unwrap_or_default();
    for name in names {
        let mut found = false;
        for (g, graph) in profile.graphs.iter().enumerate() {
            if let Some(n) = graph.nodes.iter().position(|n| n.name == *name) {
                let min =
                    v.plan.as_ref().and_then(|p| p.nodes.iter().find(|p| p.node == *name)).map_or(0, |p| p.min_level);
                spec.cached[g][n] = Some(min);
                found = true;
            }
        }
        if !found {
            bail!("the measured render caches node '{name}', which the profile does not have (another scene?)");
        }
    }
    Ok(spec)
}

/// A `tessera.stats/1` document read from `path` (its text `text`).
pub fn read_stats(path: &Path, text: &str) -> Result<RenderStats> {
    let v: serde_json::Value = serde_json::from_str(text).with_context(|| format!("{}: not JSON", path.display()))?;
    if v["schema"] != STATS_SCHEMA {
        bail!("{}: not a {STATS_SCHEMA} document", path.display());
    }
    serde_json::from_value(v).with_context(|| format!("{}: not a valid {STATS_SCHEMA} document", path.display()))
}

/// `tessera analyze`.
pub fn run_analyze(args: AnalyzeArgs) -> Result<()> {
    let profile = read_profile(&args.profile)?;
    let target = target_for(&profile, args.render.spp, args.render.threads)?;
    let budget = budget_bytes(args.render.budget_mb)?;
    let (r, _) = plan_profile(&profile, target, budget, SearchOptions::with_budget(budget))?;
    let model = Model::new(&profile, target)?;
    let mut md = String::new();
    let _ = writeln!(md, "# Analysis of {} ({})\n", args.profile.display(), profile.scene.name);
    let _ = writeln!(
        md,
        "Target: {} samples on {} threads; budget {:.0} MiB.\n",
        target.samples, target.threads, args.render.budget_mb
    );
    let _ = writeln!(md, "{}", prediction_table(&model, &standard_rows(&profile, &r.plan)));
    let _ = writeln!(md, "{}", node_table(&profile, &model.predict(&r.plan), &r.plan));
    let mut rows = Vec::new();
    for m in &args.measured {
        let text = std::fs::read_to_string(m).with_context(|| format!("{}: cannot read", m.display()))?;
        let v = read_stats(m, &text)?;
        let spec = spec_of_stats(&profile, &v).with_context(|| format!("{}", m.display()))?;
        let t = Target { samples: v.counts.samples.max(1), threads: v.threads.max(1) };
        let pred = Model::new(&profile, t)?.predict(&spec);
        let name = v.cache.as_ref().map_or("none", |c| c.strategy.as_str()).to_string();
        rows.push((name, Summary::from(&pred), measured_of_stats(&v)));
    }
    if !rows.is_empty() {
        let _ = writeln!(md, "## Predicted against measured\n\n{}", comparison_table(&rows));
    }
    println!("{md}");
    if let Some(dir) = &args.report {
        write_report(dir, &profile, &md, (&r.prediction, &r.plan), &rows)?;
        eprintln!("wrote {}", dir.display());
    }
    Ok(())
}

/// Per node: what the model predicts under the plan.
pub fn node_table(profile: &Profile, p: &Prediction, plan: &PlanSpec) -> String {
    let mut s = String::from(
        "| node | category | cached (min level) | evaluations | lookups | tiles | MiB | thread-s |\n|---|---|---|---|---|---|---|---|\n",
    );
    for (g, graph) in profile.graphs.iter().enumerate() {
        for (n, node) in graph.nodes.iter().enumerate() {
            let np = &p.nodes[g][n];
            if np.evaluations == 0.0 && np.lookups == 0.0 {
                continue;
            }
            let cached = plan.cached[g][n].map_or("—".to_string(), |m| format!("yes ({m})"));
            let _ = writeln!(
                s,
                "| {} | {} | {cached} | {:.3e} | {:.3e} | {:.0} | {:.2} | {:.3} |",
                node.name,
                node.category,
                np.evaluations,
                np.lookups,
                np.tiles,
                mib(np.bytes),
                np.thread_s
            );
        }
    }
    s
}

/// Writes `table.md`, `levels.svg` (requests by level per stream), `node_levels.svg` (per node
/// under the plan) and, with measurements, `predicted_vs_measured.svg`.
pub fn write_report(
    dir: &Path,
    profile: &Profile,
    md: &str,
    planned: (&Prediction, &PlanSpec),
    rows: &[(String, Summary, Summary)],
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    write_atomic(&dir.join("table.md"), md.as_bytes())?;
    write_atomic(&dir.join("levels.svg"), levels_svg(profile).as_bytes())?;
    write_atomic(&dir.join("node_levels.svg"), node_levels_svg(profile, planned.0, planned.1).as_bytes())?;
    if !rows.is_empty() {
        write_atomic(&dir.join("predicted_vs_measured.svg"), scatter_svg(rows).as_bytes())?;
    }
    Ok(())
}

/// Requests by footprint level, one histogram per stream (the nodes one material reads
/// together), side by side in one SVG.
pub fn levels_svg(profile: &Profile) -> String {
    let range = (-1i64, i64::from(profile.cache.max_level));
    let charts: Vec<String> = profile
        .streams
        .iter()
        .map(|st| {
            let bins: Vec<(i64, f64)> = st.requests.iter().map(|r| (i64::from(r.level), r.requests as f64)).collect();
            let title = format!("{} · {}", st.material, profile.graphs[st.graph as usize].name);
            crate::svg::histogram(&title, &bins, range, "#4a7fb5")
        })
        .collect();
    side_by_side(&charts, 200.0, 104.0)
}

/// Per node with requests under the plan: its predicted requests by footprint level (from the
/// renderer and from cached consumers' tile fills), coloured by whether the node is cached.
pub fn node_levels_svg(profile: &Profile, p: &Prediction, plan: &PlanSpec) -> String {
    let range = (-1i64, i64::from(profile.cache.max_level));
    let mut charts = Vec::new();
    for (g, graph) in profile.graphs.iter().enumerate() {
        for (n, node) in graph.nodes.iter().enumerate() {
            let np = &p.nodes[g][n];
            if np.requests_by_level.iter().all(|&r| r <= 0.0) {
                continue;
            }
            let bins: Vec<(i64, f64)> = np
                .requests_by_level
                .iter()
                .enumerate()
                .map(|(b, &r)| (b as i64 - 1, r))
                .filter(|b| b.1 > 0.0)
                .collect();
            let (title, color) = match plan.cached[g][n] {
                Some(min) => (format!("{} (cached, levels ≥ {min})", node.name), "#c0504d"),
                None => (node.name.clone(), "#4a7fb5"),
            };
            charts.push(crate::svg::histogram(&title, &bins, range, color));
        }
    }
    side_by_side(&charts, 200.0, 104.0)
}

/// Predicted against measured, one chart per quantity, side by side in one SVG.
pub fn scatter_svg(rows: &[(String, Summary, Summary)]) -> String {
    let quantity = |label: &str, f: fn(&Summary, &Summary) -> (f64, f64)| {
        let pts: Vec<(String, f64, f64)> = rows
            .iter()
            .map(|(name, p, m)| {
                let (x, y) = f(p, m);
                (name.clone(), x, y)
            })
            .collect();
        crate::svg::scatter(label, &pts, "")
    };
    let charts = [
        quantity("evaluations", |p, m| (p.evaluations, m.evaluations)),
        quantity("cache lookups", |p, m| (p.lookups, m.lookups)),
        quantity("tiles filled", |p, m| (p.tiles_filled, m.tiles_filled)),
        quantity("peak bytes", |p, m| (p.peak_bytes, m.peak_bytes)),
        quantity("render seconds", |p, m| (p.render_s, m.render_s)),
    ];
    side_by_side(&charts, 300.0, 280.0)
}

/// Chart SVGs of size `w × h` nested in one document, in rows of three.
fn side_by_side(charts: &[String], w: f64, h: f64) -> String {
    let cols = charts.len().clamp(1, 3);
    let rows = charts.len().div_ceil(cols).max(1);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" font-family=\"sans-serif\" font-size=\"10\">\n",
        w * cols as f64,
        h * rows as f64
    );
    for (k, c) in charts.iter().enumerate() {
        let (x, y) = ((k % cols) as f64 * w, (k / cols) as f64 * h);
        s.push_str(&c.replacen("<svg ", &format!("<svg x=\"{x}\" y=\"{y}\" "), 1));
        s.push('\n');
    }
    s.push_str("</svg>\n");
    s
}

/// The result of `--strategy auto`'s profiling and planning, for the summary and the stats.
pub struct AutoPlan {
    pub profile: Profile,
    pub result: SearchResult,
    pub file: PlanFile,
    pub target: Target,
    pub profile_s: f64,
    pub plan_s: f64,
}

/// Profiles and plans for `--strategy auto` (on the current rayon pool).
pub fn auto_plan(
    scene: &Scene,
    scene_path: Option<&Path>,
    defines: &[(String, String)],
    settings: RenderSettings,
    share: f64,
    budget: usize,
) -> Result<AutoPlan> {
    let t = std::time::Instant::now();
    let (psettings, fraction) = auto_profile_settings(scene, settings, share);
    let profile = profile_scene(scene, psettings, fraction, scene_id(scene_path, defines)?)?;
    let profile_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let target = Target {
        samples: u64::from(scene.camera.width) * u64::from(scene.camera.height) * u64::from(settings.spp),
        threads: rayon::current_num_threads() as u32,
    };
    let (result, file) = plan_profile(&profile, target, budget as f64, SearchOptions::with_budget(budget as f64))?;
    Ok(AutoPlan { profile, result, file, target, profile_s, plan_s: t.elapsed().as_secs_f64() })
}

impl AutoPlan {
    /// Writes the run's report folder (tables, plots, `profile.json`, `plan.json`) with the
    /// measured render; returns the predicted-against-measured table.
    pub fn write_report(&self, dir: &Path, measured: Summary) -> Result<String> {
        let rows = vec![("auto".to_string(), Summary::from(&self.result.prediction), measured)];
        let model = Model::new(&self.profile, self.target)?;
        let comparison = comparison_table(&rows);
        let md = format!(
            "# --strategy auto\n\nProfile: {} samples in {:.2} s; plan: {} ({} candidates, {} plans predicted) in {:.3} s.\n\n## Predicted per strategy\n\n{}\n## Per node (plan)\n\n{}\n## Predicted against measured\n\n{comparison}",
            self.profile.render.samples,
            self.profile_s,
            self.result.method,
            self.result.candidates,
            self.result.plans_evaluated,
            self.plan_s,
            prediction_table(&model, &standard_rows(&self.profile, &self.result.plan)),
            node_table(&self.profile, &self.result.prediction, &self.result.plan),
        );
        write_report(dir, &self.profile, &md, (&self.result.prediction, &self.result.plan), &rows)?;
        write_atomic(&dir.join("profile.json"), self.profile.to_json().as_bytes())?;
        write_atomic(&dir.join("plan.json"), self.file.to_json().as_bytes())?;
        Ok(comparison)
    }

    /// The `"plan"` object of the stats JSON.
    pub fn stats(&self) -> render::stats::PlanStats {
        render::stats::PlanStats {
            strategy: "auto".into(),
            profile_s: self.profile_s,
            plan_s: self.plan_s,
            profile_samples: self.profile.render.samples,
            method: self.result.method.clone(),
            candidates: self.result.candidates as u64,
            plans_evaluated: self.result.plans_evaluated,
            cached_nodes: self.file.nodes.iter().map(|n| n.node.clone()).collect(),
            nodes: self.file.nodes.clone(),
            predicted: self.file.predicted,
        }
    }
}
