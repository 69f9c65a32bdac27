//! `tessera bench`: renders every scene of a suite with every caching strategy and with free
//! textures (the lower bound on render time), at the same seed, spp and resolution, and writes
//! `results.json` (schema `tessera.bench/1`, documented in the README), `results.md` and a
//! self-contained `report.html`.
//!
//! Each run is a fresh `tessera render` process (this same executable), so no run inherits a warm
//! cache from another and the renderer's own `--stats-json` is the one source of counters and
//! timings. Repeats are interleaved: inside each repeat every strategy runs once, in an order
//! rotated from one repeat to the next, so that machine drift affects all strategies alike.
//! Image error is measured against a high-spp reference of the same scene (strategy `none`, a
//! different seed), rendered once and kept in a cache folder keyed by a hash of everything that
//! determines it.

use crate::flip::{self, Srgb8};
use crate::write_atomic;
use anyhow::{bail, Context, Result};
use render::film::Image;
use render::stats::{PlanStats, RenderStats, STATS_SCHEMA};
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Schema of `results.json`.
pub const SCHEMA: &str = "tessera.bench/1";
/// Label of the free-texture lower bound among the strategies.
pub const LOWER_BOUND: &str = "free";
const DEFAULT_STRATEGIES: &str = "none,outputs,all,bake:1024,auto";
const QUICK_STRATEGIES: &str = "none,outputs,all";
/// The scene `--quick` picks when the suite has it (the demo cheapest to render with `all`);
/// otherwise it takes the suite's first scene.
const QUICK_SCENE: &str = "rusted_metal";
/// References use `seed + REF_SEED_OFFSET` so that their samples are independent of the runs'.
const REF_SEED_OFFSET: u64 = 1_000_003;
/// Quantities a plan predicts, by the name its `predicted` object uses.
pub const PLAN_QUANTITIES: [&str; 6] =
    ["evaluations", "lookups", "tiles_filled", "texels_filled", "peak_bytes", "render_s"];

/// Arguments of `tessera bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// A folder of Mitsuba 3 scenes (every *.xml in it) or one scene file. Default: the
    /// repository's demo scenes (scenes/).
    suite: Option<PathBuf>,
    /// Folder for results.json, results.md, report.html, images/ and stats/.
    #[arg(long, default_value = "results")]
    out: PathBuf,
    /// Comma-separated strategies to compare (default none,outputs,all,bake:1024,auto; `--quick`:
    /// none,outputs,all). The free-texture lower bound is always run as well. A strategy the
    /// renderer rejects is recorded as an error and the benchmark goes on.
    #[arg(long)]
    strategies: Option<String>,
    /// Only these scenes (comma-separated file stems, e.g. marble,wood_floor).
    #[arg(long)]
    scenes: Option<String>,
    /// Samples per pixel of every run (default 16; `--quick`: 2).
    #[arg(long)]
    spp: Option<u32>,
    /// Image resolution, passed to the scenes as `-D res=R` (default 128; `--quick`: 32).
    #[arg(long)]
    res: Option<u32>,
    /// Seed of every run (the reference uses a different one).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Repeats of each run; medians are reported with min and max (default 3; `--quick`: 1).
    #[arg(long)]
    repeats: Option<u32>,
    /// Samples per pixel of the reference images (default 256; `--quick`: 16).
    #[arg(long)]
    ref_spp: Option<u32>,
    /// Folder where references are kept between benchmarks (default:
    /// $XDG_CACHE_HOME/tessera/bench-refs or ~/.cache/tessera/bench-refs).
    #[arg(long)]
    ref_cache: Option<PathBuf>,
    /// Tile cache budget of every run, MiB.
    #[arg(long, default_value_t = 512.0)]
    budget_mb: f64,
    /// Worker threads of every run (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Extra scene override for every run and the reference: -D name=value (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE")]
    define: Vec<String>,
    /// A small benchmark for tests: one scene, 32x32, 2 spp, 1 repeat, 16-spp reference,
    /// strategies none,outputs,all (explicit options still win).
    #[arg(long)]
    quick: bool,
    /// No progress lines.
    #[arg(long)]
    quiet: bool,
}

/// Everything a benchmark run needs, resolved from the arguments.
struct Config {
    exe: PathBuf,
    suite: PathBuf,
    scenes: Vec<PathBuf>,
    strategies: Vec<String>,
    res: u32,
    spp: u32,
    seed: u64,
    ref_spp: u32,
    repeats: u32,
    budget_mb: f64,
    threads: Option<usize>,
    defines: Vec<String>,
    out: PathBuf,
    ref_cache: PathBuf,
    quick: bool,
    quiet: bool,
}

impl Config {
    fn from_args(a: BenchArgs) -> Result<Config> {
        let quick = a.quick;
        let pick = |v: Option<u32>, normal: u32, small: u32| v.unwrap_or(if quick { small } else { normal });
        let (res, spp, repeats, ref_spp) =
            (pick(a.res, 128, 32), pick(a.spp, 16, 2), pick(a.repeats, 3, 1), pick(a.ref_spp, 256, 16));
        if !(1..=16384).contains(&res) {
            bail!("--res must be 1 to 16384 pixels, got {res}");
        }
        if spp == 0 || ref_spp == 0 {
            bail!("--spp and --ref-spp must be at least 1");
        }
        if !(1..=1000).contains(&repeats) {
            bail!("--repeats must be 1 to 1000, got {repeats}");
        }
        if !(a.budget_mb.is_finite() && a.budget_mb > 0.0 && a.budget_mb <= 1.0e6) {
            bail!("--budget-mb must be a positive number of MiB (at most 1e6), got {}", a.budget_mb);
        }
        if let Some(0) = a.threads {
            bail!("--threads must be at least 1");
        }
        for (name, _) in crate::parse_defines(&a.define)? {
            if name == "res" || name == "spp" {
                bail!("-D {name}=... is set by the benchmark: use --{name} instead");
            }
        }
        let suite = match a.suite {
            Some(s) => s,
            None => {
                let s = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
                if !s.is_dir() {
                    bail!("no SUITE_DIR given and the repository's scenes folder ({}) is not there", s.display());
                }
                s.canonicalize().unwrap_or(s)
            }
        };
        let mut scenes = find_scenes(&suite)?;
        if let Some(filter) = &a.scenes {
            scenes = select_scenes(&scenes, filter)?;
        } else if quick {
            let quick_scene = scenes.iter().find(|p| stem(p) == QUICK_SCENE);
            scenes = vec![quick_scene.unwrap_or(&scenes[0]).clone()];
        }
        let strategies = parse_strategies(a.strategies.as_deref().unwrap_or(if quick {
            QUICK_STRATEGIES
        } else {
            DEFAULT_STRATEGIES
        }))?;
        let ref_cache = a.ref_cache.unwrap_or_else(|| default_ref_cache(&a.out));
        let exe = std::env::current_exe().context("cannot find the tessera executable to run")?;
        Ok(Config {
            exe,
            suite,
            scenes,
            strategies,
            res,
            spp,
            seed: a.seed,
            ref_spp,
            repeats,
            budget_mb: a.budget_mb,
            threads: a.threads,
            defines: a.define,
            out: a.out,
            ref_cache,
            quick,
            quiet: a.quiet,
        })
    }

    fn progress(&self, msg: &str) {
        if !self.quiet {
            eprintln!("{msg}");
        }
    }
}

fn default_ref_cache(out: &Path) -> PathBuf {
    let base = match std::env::var_os("XDG_CACHE_HOME").filter(|v| !v.is_empty()) {
        Some(x) => Some(PathBuf::from(x)),
        None => std::env::var_os("HOME").filter(|v| !v.is_empty()).map(|h| PathBuf::from(h).join(".cache")),
    };
    match base {
        Some(b) => b.join("tessera").join("bench-refs"),
        None => out.join(".ref-cache"),
    }
}

fn stem(p: &Path) -> String {
    p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()
}

/// The scenes of a suite: the file itself, or every `*.xml` of the folder in name order.
fn find_scenes(suite: &Path) -> Result<Vec<PathBuf>> {
    if suite.is_file() {
        return Ok(vec![suite.to_path_buf()]);
    }
    if !suite.is_dir() {
        bail!("{}: no such scene file or folder", suite.display());
    }
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(suite)
        .with_context(|| format!("{}: cannot list the folder", suite.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case("xml")))
        .collect();
    scenes.sort();
    if scenes.is_empty() {
        bail!("{}: no scene (*.xml) in this folder", suite.display());
    }
    Ok(scenes)
}

fn select_scenes(scenes: &[PathBuf], filter: &str) -> Result<Vec<PathBuf>> {
    let mut chosen = Vec::new();
    for name in filter.split(',').map(str::trim).filter(|n| !n.is_empty()) {
        match scenes.iter().find(|p| stem(p) == name) {
            Some(p) if !chosen.contains(p) => chosen.push(p.clone()),
            Some(_) => {}
            None => {
                let known: Vec<String> = scenes.iter().map(|p| stem(p)).collect();
                bail!("--scenes: no scene '{name}' in the suite (it has {})", known.join(", "));
            }
        }
    }
    if chosen.is_empty() {
        bail!("--scenes names no scene");
    }
    Ok(chosen)
}

/// Splits a comma-separated strategy list. `nodes:a,b,c` keeps the names after it until the next
/// token that starts a strategy (`none`, `outputs`, `all`, `auto`, `free`, `bake:`, `nodes:`,
/// `plan:`). `free` is dropped: the lower bound is always run.
pub fn parse_strategies(list: &str) -> Result<Vec<String>> {
    let starts_strategy = |t: &str| {
        matches!(t, "none" | "outputs" | "all" | "auto" | "free")
            || ["bake:", "nodes:", "plan:"].iter().any(|p| t.starts_with(p))
    };
    let mut out: Vec<String> = Vec::new();
    for token in list.split(',').map(str::trim) {
        if token.is_empty() {
            bail!("--strategies: empty entry in '{list}'");
        }
        match out.last_mut() {
            Some(last) if last.starts_with("nodes:") && !starts_strategy(token) => {
                last.push(',');
                last.push_str(token);
            }
            _ => out.push(token.to_string()),
        }
    }
    let mut unique: Vec<String> = Vec::new();
    for s in out {
        if s != LOWER_BOUND && !unique.contains(&s) {
            unique.push(s);
        }
    }
    if unique.is_empty() {
        bail!("--strategies: give at least one strategy besides the free-texture lower bound");
    }
    Ok(unique)
}

// ---------------------------------------------------------------------------------------------
// Results (serialised as results.json)
// ---------------------------------------------------------------------------------------------

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
    fn of(values: &[f64]) -> Option<Spread> {
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

/// The tile cache's counters of a run.
#[derive(Serialize, Clone, Default)]
pub struct CacheCounts {
    pub cached_nodes: u64,
    pub budget_bytes: u64,
    pub peak_bytes: u64,
    pub lookups: u64,
    pub tile_hits: u64,
    pub tile_misses: u64,
    pub tiles_filled: u64,
    pub texels_filled: u64,
    pub evictions: u64,
    pub refills: u64,
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

// ---------------------------------------------------------------------------------------------
// One run: a child `tessera render` and what its stats JSON says
// ---------------------------------------------------------------------------------------------

/// A successful run, parsed.
struct Sample {
    process_s: f64,
    phases: Phases,
    samples: u64,
    rays: u64,
    samples_per_s: f64,
    node_evaluations: u64,
    cache: Option<CacheCounts>,
    plan: Option<PlanComparison>,
    stats: Value,
    image: Image,
}

impl Sample {
    fn time_s(&self) -> f64 {
        let p = &self.phases;
        p.profile_s + p.plan_s + p.cache_setup_s + p.render_s
    }
}

/// What a child renders.
enum Job<'a> {
    Strategy(&'a str),
    LowerBound,
    Reference,
}

fn run_child(cfg: &Config, scene: &Path, job: Job, work: &Path, name: &str) -> std::result::Result<Sample, String> {
    let exr = work.join(format!("{name}.exr"));
    let json = work.join(format!("{name}.json"));
    let _ = std::fs::remove_file(&exr);
    let _ = std::fs::remove_file(&json);
    let (spp, seed) = match job {
        Job::Reference => (cfg.ref_spp, cfg.seed.wrapping_add(REF_SEED_OFFSET)),
        _ => (cfg.spp, cfg.seed),
    };
    let mut cmd = Command::new(&cfg.exe);
    cmd.arg("render").arg(scene).arg("--quiet").arg("--spp").arg(spp.to_string()).arg("--seed").arg(seed.to_string());
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
    let cache = typed.cache.as_ref().map(|c| CacheCounts {
        cached_nodes: c.cached_nodes.len() as u64,
        budget_bytes: c.budget_bytes,
        peak_bytes: c.peak_bytes,
        lookups: c.lookups,
        tile_hits: c.tile_hits,
        tile_misses: c.tile_misses,
        tiles_filled: c.tiles_filled,
        texels_filled: c.texels_filled,
        evictions: c.evictions,
        refills: c.refills,
    });
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
    let c = s.cache.clone().unwrap_or_default();
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

// ---------------------------------------------------------------------------------------------
// References
// ---------------------------------------------------------------------------------------------

/// 64-bit FNV-1a: a stable hash (the same on every build and platform) for cache keys.
struct Fnv(u64);

impl Fnv {
    fn new() -> Fnv {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 = (self.0 ^ x as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    /// A length-prefixed part, so that parts cannot run into each other.
    fn part(&mut self, b: &[u8]) {
        self.bytes(&(b.len() as u64).to_le_bytes());
        self.bytes(b);
    }
}

/// Files a scene depends on: every attribute value naming an existing file relative to the
/// document that names it (MaterialX documents, meshes, images, included XML), followed into
/// XML and MaterialX documents a few levels deep. In document order, each once.
fn referenced_files(doc: &Path, depth: u32, seen: &mut Vec<PathBuf>) {
    let Ok(text) = std::fs::read(doc) else { return };
    let text = String::from_utf8_lossy(&text);
    let dir = doc.parent().unwrap_or(Path::new("."));
    for pattern in ["value=\"", "filename=\""] {
        for (i, _) in text.match_indices(pattern) {
            let rest = &text[i + pattern.len()..];
            let Some(end) = rest.find('"') else { continue };
            let candidate = &rest[..end];
            if candidate.is_empty() || candidate.len() > 1024 {
                continue;
            }
            let p = dir.join(candidate);
            if p.is_file() && !seen.contains(&p) {
                seen.push(p.clone());
                let ext = p.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
                if depth > 0 && (ext == "xml" || ext == "mtlx") {
                    referenced_files(&p, depth - 1, seen);
                }
            }
        }
    }
}

/// The reference's cache key: the scene and the files it names, the resolution, spp, seed,
/// extra defines, and the renderer (version and executable contents).
fn reference_key(cfg: &Config, scene: &Path, exe_hash: u64) -> Result<String> {
    let mut h = Fnv::new();
    h.part(b"tessera.bench.reference/1");
    h.part(env!("CARGO_PKG_VERSION").as_bytes());
    h.part(&exe_hash.to_le_bytes());
    h.part(&std::fs::read(scene).with_context(|| format!("{}: cannot read the scene", scene.display()))?);
    let mut files = Vec::new();
    referenced_files(scene, 3, &mut files);
    let dir = scene.parent().unwrap_or(Path::new("."));
    for f in &files {
        h.part(f.strip_prefix(dir).unwrap_or(f).to_string_lossy().as_bytes());
        h.part(&std::fs::read(f).unwrap_or_default());
    }
    h.part(&cfg.res.to_le_bytes());
    h.part(&cfg.ref_spp.to_le_bytes());
    h.part(&cfg.seed.wrapping_add(REF_SEED_OFFSET).to_le_bytes());
    for d in &cfg.defines {
        h.part(d.as_bytes());
    }
    Ok(format!("{:016x}", h.0))
}

fn hash_file(path: &Path) -> Result<u64> {
    use std::io::Read;
    let mut f = std::fs::File::open(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let mut h = Fnv::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf).with_context(|| format!("{}: cannot read", path.display()))?;
        if n == 0 {
            return Ok(h.0);
        }
        h.bytes(&buf[..n]);
    }
}

struct Reference {
    image: Image,
    srgb: Srgb8,
    footprint_png: Option<Vec<u8>>,
    info: ReferenceInfo,
}

/// The scene's reference: from the cache when its key is there, otherwise rendered (strategy
/// none, `ref_spp`, with the footprint AOV) and stored in the cache.
fn reference(
    cfg: &Config,
    scene: &Path,
    name: &str,
    work: &Path,
    exe_hash: u64,
) -> std::result::Result<Reference, String> {
    let key = reference_key(cfg, scene, exe_hash).map_err(|e| format!("{e:#}"))?;
    let exr = cfg.ref_cache.join(format!("{key}.exr"));
    let fp = cfg.ref_cache.join(format!("{key}.footprint.png"));
    let meta = cfg.ref_cache.join(format!("{key}.json"));
    let info = |reused: bool, render_s: Option<f64>, has_fp: bool| ReferenceInfo {
        spp: cfg.ref_spp,
        seed: cfg.seed.wrapping_add(REF_SEED_OFFSET),
        key: key.clone(),
        reused,
        render_s,
        image: format!("images/{name}.reference.png"),
        footprint_image: has_fp.then(|| format!("images/{name}.footprint.png")),
    };
    if let Ok(image) = Image::load_exr(&exr) {
        let render_s = std::fs::read(&meta)
            .ok()
            .and_then(|b| serde_json::from_slice::<Value>(&b).ok())
            .and_then(|v| v["phases"]["render_s"].as_f64());
        let footprint_png = std::fs::read(&fp).ok();
        let has_fp = footprint_png.is_some();
        let srgb = Srgb8::from_linear(&image);
        return Ok(Reference { image, srgb, footprint_png, info: info(true, render_s, has_fp) });
    }
    cfg.progress(&format!("  reference: {} spp (key {key})", cfg.ref_spp));
    let base = format!("{name}.reference");
    let s = run_child(cfg, scene, Job::Reference, work, &base).map_err(|e| format!("reference render failed: {e}"))?;
    let footprint_png = std::fs::read(work.join(format!("{base}.footprint.png"))).ok();
    // Keep it for the next benchmark; a cache that cannot be written only costs time.
    let store = || -> Result<()> {
        std::fs::create_dir_all(&cfg.ref_cache)
            .with_context(|| format!("{}: cannot create the folder", cfg.ref_cache.display()))?;
        if let Some(png) = &footprint_png {
            write_atomic(&fp, png)?;
        }
        write_atomic(&meta, serde_json::to_string_pretty(&s.stats)?.as_bytes())?;
        write_atomic(&exr, &std::fs::read(work.join(format!("{base}.exr")))?)
    };
    if let Err(e) = store() {
        eprintln!("warning: cannot keep the reference in {}: {e:#}", cfg.ref_cache.display());
    }
    let srgb = Srgb8::from_linear(&s.image);
    let has_fp = footprint_png.is_some();
    Ok(Reference { image: s.image, srgb, footprint_png, info: info(false, Some(s.phases.render_s), has_fp) })
}

// ---------------------------------------------------------------------------------------------
// The benchmark
// ---------------------------------------------------------------------------------------------

/// The work folder inside the output folder, removed when the benchmark ends however it ends.
struct WorkDir(PathBuf);

impl Drop for WorkDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A file-name-safe form of a strategy label.
fn file_label(label: &str) -> String {
    label.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '-' }).collect()
}

/// `tessera bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    let cfg = Config::from_args(args)?;
    if cfg.out.exists() && !cfg.out.is_dir() {
        bail!("{}: --out must be a folder", cfg.out.display());
    }
    std::fs::create_dir_all(&cfg.out).with_context(|| format!("{}: cannot create the folder", cfg.out.display()))?;
    let work = WorkDir(cfg.out.join(format!(".bench-work-{}", std::process::id())));
    std::fs::create_dir_all(&work.0).with_context(|| format!("{}: cannot create the folder", work.0.display()))?;
    let exe_hash = hash_file(&cfg.exe)?;

    let mut scenes = Vec::new();
    for (i, scene) in cfg.scenes.iter().enumerate() {
        cfg.progress(&format!("[{}/{}] {}", i + 1, cfg.scenes.len(), scene.display()));
        scenes.push(bench_scene(&cfg, scene, &work.0, exe_hash));
    }
    let threads = scenes.iter().flat_map(|s| &s.runs).find_map(|r| r.assets.stats.as_ref()?["threads"].as_u64());
    let results = BenchResults {
        schema: SCHEMA,
        tessera_version: env!("CARGO_PKG_VERSION"),
        created_unix_s: std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs()),
        settings: Settings {
            suite: cfg.suite.display().to_string(),
            res: cfg.res,
            spp: cfg.spp,
            seed: cfg.seed,
            repeats: cfg.repeats,
            ref_spp: cfg.ref_spp,
            ref_seed: cfg.seed.wrapping_add(REF_SEED_OFFSET),
            strategies: cfg.strategies.clone(),
            budget_mb: cfg.budget_mb,
            threads: cfg.threads.map(|t| t as u64).or(threads),
            defines: cfg.defines.clone(),
            quick: cfg.quick,
            time_definition: "profile_s + plan_s + cache_setup_s + render_s",
            flip: FlipSettings {
                implementation: "LDR-FLIP, NVIDIA's C++ implementation via the nv-flip crate",
                pixels_per_degree: flip::PIXELS_PER_DEGREE,
            },
        },
        scenes,
    };
    write_outputs(&cfg.out, &results)?;
    let ok = results.scenes.iter().flat_map(|s| &s.runs).filter(|r| r.summary.is_some()).count();
    let failed: Vec<String> = results
        .scenes
        .iter()
        .flat_map(|s| {
            let scene_err = s.error.as_ref().map(|e| format!("{}: {e}", s.name));
            scene_err.into_iter().chain(
                s.runs.iter().filter_map(|r| r.error.as_ref().map(|e| format!("{} {}: {e}", s.name, r.strategy))),
            )
        })
        .collect();
    if !cfg.quiet {
        for f in &failed {
            eprintln!("failed: {f}");
        }
        eprintln!(
            "wrote {}, {} and {} ({ok} strategy runs measured)",
            cfg.out.join("results.json").display(),
            cfg.out.join("results.md").display(),
            cfg.out.join("report.html").display()
        );
    }
    if ok == 0 {
        bail!("no run succeeded (see {})", cfg.out.join("results.md").display());
    }
    Ok(())
}

fn bench_scene(cfg: &Config, scene: &Path, work: &Path, exe_hash: u64) -> SceneResult {
    let name = stem(scene);
    let mut result = SceneResult {
        name: name.clone(),
        file: scene.display().to_string(),
        width: None,
        height: None,
        reference: None,
        error: None,
        runs: Vec::new(),
        reference_png: None,
        footprint_png: None,
    };
    let reference = match reference(cfg, scene, &name, work, exe_hash) {
        Ok(r) => r,
        Err(e) => {
            cfg.progress(&format!("  error: {e}"));
            result.error = Some(e);
            return result;
        }
    };
    result.width = Some(reference.image.width as u64);
    result.height = Some(reference.image.height as u64);
    result.reference_png = reference.srgb.to_png().ok();
    result.footprint_png = reference.footprint_png.clone();
    result.reference = Some(reference.info);

    // labels[i]: the strategies, then the lower bound; samples[i][repeat].
    let mut labels: Vec<Option<&str>> = cfg.strategies.iter().map(|s| Some(s.as_str())).collect();
    labels.push(None);
    let n = labels.len();
    let mut samples: Vec<Vec<Option<Sample>>> = (0..n).map(|_| Vec::new()).collect();
    let mut orders: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut errors: Vec<Option<String>> = vec![None; n];
    let mut identical = vec![true; n];
    let mut first_image: Vec<Option<Image>> = vec![None; n];
    for rep in 0..cfg.repeats {
        for pos in 0..n {
            let i = (pos + rep as usize) % n;
            let label = labels[i].unwrap_or(LOWER_BOUND);
            orders[i].push(pos as u32);
            // A strategy that failed on its first try (e.g. one the renderer rejects) is not retried.
            if rep > 0 && samples[i].first().is_some_and(|s| s.is_none()) {
                samples[i].push(None);
                continue;
            }
            let job = labels[i].map_or(Job::LowerBound, Job::Strategy);
            let run_name = format!("{name}.{}.r{rep}", file_label(label));
            match run_child(cfg, scene, job, work, &run_name) {
                Ok(s) => {
                    cfg.progress(&format!("  repeat {}/{} {label:<12} {:8.3} s", rep + 1, cfg.repeats, s.time_s()));
                    match &first_image[i] {
                        None => first_image[i] = Some(s.image.clone()),
                        Some(img) => identical[i] &= *img == s.image,
                    }
                    samples[i].push(Some(s));
                }
                Err(e) => {
                    cfg.progress(&format!("  repeat {}/{} {label:<12} error: {e}", rep + 1, cfg.repeats));
                    errors[i].get_or_insert(e);
                    samples[i].push(None);
                }
            }
        }
    }
    let lower_times: Vec<Option<f64>> = samples[n - 1].iter().map(|s| s.as_ref().map(Sample::time_s)).collect();
    let mut used_names: Vec<String> = Vec::new();
    for i in 0..n {
        let label = labels[i].unwrap_or(LOWER_BOUND).to_string();
        let mut fname = file_label(&label);
        while used_names.contains(&fname) {
            fname.push('_');
        }
        used_names.push(fname.clone());
        let runs = std::mem::take(&mut samples[i]);
        let error = errors[i].take();
        let image = first_image[i].take();
        let mut r = summarize(&label, i == n - 1, runs, &orders[i], &lower_times, error, identical[i]);
        if let (Some(img), Some(summary)) = (image, r.summary.as_mut()) {
            let srgb = Srgb8::from_linear(&img);
            r.assets.png = srgb.to_png().ok();
            r.image = Some(format!("images/{name}.{fname}.png"));
            match (flip::relative_mse(&reference.image, &img), flip::flip(&reference.srgb, &srgb)) {
                (Ok(rel_mse), Ok(f)) => {
                    summary.image_error = Some(ImageError { rel_mse, flip: f.mean });
                    r.assets.flip_png = f.map.to_png().ok();
                    r.flip_image = Some(format!("images/{name}.{fname}.flip.png"));
                }
                (Err(e), _) | (_, Err(e)) => {
                    r.error.get_or_insert(format!("cannot compare with the reference: {e:#}"));
                }
            }
        }
        if r.assets.stats.is_some() {
            r.stats = Some(format!("stats/{name}.{fname}.json"));
        }
        result.runs.push(r);
    }
    result
}

fn summarize(
    label: &str,
    lower_bound: bool,
    runs: Vec<Option<Sample>>,
    orders: &[u32],
    lower_times: &[Option<f64>],
    error: Option<String>,
    identical: bool,
) -> StrategyResult {
    let mut repeats = Vec::new();
    let mut ok: Vec<Sample> = Vec::new();
    for (rep, s) in runs.into_iter().enumerate() {
        let Some(s) = s else { continue };
        let t = s.time_s();
        let ratio = lower_times.get(rep).copied().flatten().filter(|l| *l > 0.0).map(|l| t / l);
        repeats.push(RepeatResult {
            repeat: rep as u32,
            order: orders.get(rep).copied().unwrap_or(0),
            time_s: t,
            process_s: s.process_s,
            ratio_to_lower_bound: ratio,
        });
        ok.push(s);
    }
    let mut result = StrategyResult {
        strategy: label.to_string(),
        lower_bound,
        error,
        repeats: repeats.clone(),
        summary: None,
        image: None,
        flip_image: None,
        stats: None,
        assets: RunAssets::default(),
    };
    if ok.is_empty() {
        return result;
    }
    let times: Vec<f64> = ok.iter().map(Sample::time_s).collect();
    let med = |f: fn(&Sample) -> f64| Spread::of(&ok.iter().map(f).collect::<Vec<_>>()).map_or(0.0, |s| s.median);
    // The run whose time is the (lower) median supplies the counters.
    let mut order: Vec<usize> = (0..ok.len()).collect();
    order.sort_by(|a, b| times[*a].total_cmp(&times[*b]));
    let m = &ok[order[(ok.len() - 1) / 2]];
    let ratios: Vec<f64> = repeats.iter().filter_map(|r| r.ratio_to_lower_bound).collect();
    let time_s = Spread::of(&times).unwrap_or(Spread { median: 0.0, min: 0.0, max: 0.0 });
    let process_s = Spread::of(&ok.iter().map(|s| s.process_s).collect::<Vec<_>>()).unwrap_or(time_s);
    result.summary = Some(Summary {
        runs_ok: ok.len() as u32,
        time_s,
        ratio_to_lower_bound: Spread::of(&ratios),
        process_s,
        phases: Phases {
            load_s: med(|s| s.phases.load_s),
            profile_s: med(|s| s.phases.profile_s),
            plan_s: med(|s| s.phases.plan_s),
            cache_setup_s: med(|s| s.phases.cache_setup_s),
            render_s: med(|s| s.phases.render_s),
            write_s: med(|s| s.phases.write_s),
        },
        samples: m.samples,
        samples_per_s: med(|s| s.samples_per_s),
        rays: m.rays,
        node_evaluations: m.node_evaluations,
        cache: m.cache.clone(),
        image_error: None,
        images_identical_across_repeats: identical,
        plan: m.plan.clone(),
    });
    result.assets.stats = Some(m.stats.clone());
    result
}

/// Writes results.json, results.md, report.html, the images and the stats of each median run,
/// each file complete or not at all.
fn write_outputs(out: &Path, results: &BenchResults) -> Result<()> {
    let images = out.join("images");
    let stats = out.join("stats");
    for d in [&images, &stats] {
        std::fs::create_dir_all(d).with_context(|| format!("{}: cannot create the folder", d.display()))?;
    }
    for s in &results.scenes {
        if let (Some(info), Some(png)) = (&s.reference, &s.reference_png) {
            write_atomic(&out.join(&info.image), png)?;
        }
        if let (Some(path), Some(png)) =
            (s.reference.as_ref().and_then(|r| r.footprint_image.as_ref()), &s.footprint_png)
        {
            write_atomic(&out.join(path), png)?;
        }
        for r in &s.runs {
            if let (Some(path), Some(png)) = (&r.image, &r.assets.png) {
                write_atomic(&out.join(path), png)?;
            }
            if let (Some(path), Some(png)) = (&r.flip_image, &r.assets.flip_png) {
                write_atomic(&out.join(path), png)?;
            }
            if let (Some(path), Some(v)) = (&r.stats, &r.assets.stats) {
                write_atomic(&out.join(path), serde_json::to_string_pretty(v)?.as_bytes())?;
            }
        }
    }
    write_atomic(&out.join("results.json"), serde_json::to_string_pretty(results)?.as_bytes())?;
    write_atomic(&out.join("results.md"), crate::report::markdown(results).as_bytes())?;
    write_atomic(&out.join("report.html"), crate::report::html(results).as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strategy_lists_keep_node_lists_together_and_drop_free() {
        let s = parse_strategies("none,nodes:NG_a/x,NG_a/y,all,free,bake:64,auto,all").unwrap();
        assert_eq!(s, ["none", "nodes:NG_a/x,NG_a/y", "all", "bake:64", "auto"]);
        assert!(parse_strategies("free").is_err());
        assert!(parse_strategies("none,,all").is_err());
    }

    #[test]
    fn spreads_are_medians_with_extremes() {
        let s = Spread::of(&[3.0, 1.0, 2.0]).unwrap();
        assert_eq!((s.median, s.min, s.max), (2.0, 1.0, 3.0));
        assert_eq!(Spread::of(&[4.0, 1.0]).unwrap().median, 2.5);
        assert!(Spread::of(&[f64::NAN]).is_none());
    }

    #[test]
    fn fnv_is_stable_and_parts_do_not_run_together() {
        let mut a = Fnv::new();
        a.bytes(b"a");
        assert_eq!(a.0, 0xaf63_dc4c_8601_ec8c);
        let (mut x, mut y) = (Fnv::new(), Fnv::new());
        x.part(b"ab");
        x.part(b"c");
        y.part(b"a");
        y.part(b"bc");
        assert_ne!(x.0, y.0);
    }

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

    #[test]
    fn file_labels_are_safe() {
        assert_eq!(file_label("bake:1024"), "bake-1024");
        assert_eq!(file_label("nodes:NG/a,b"), "nodes-NG-a-b");
    }
}
