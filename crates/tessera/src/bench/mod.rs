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

mod references;
mod report;
mod results;
mod runs;

pub use results::{
    BenchResults, FlipSettings, ImageError, Phases, RepeatResult, RunAssets, SceneResult, Settings, Spread,
    StrategyResult, Summary,
};

use crate::flip::{self, Srgb8};
use crate::write_atomic;
use anyhow::{bail, Context, Result};
use references::{hash_file, reference};
use render::film::Image;
use runs::{run_child, Job, Sample};
use std::path::{Path, PathBuf};

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
        crate::check_threads(a.threads)?;
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
    // The free-texture lower bound alone measures nothing asked for.
    let asked_ok =
        results.scenes.iter().flat_map(|s| &s.runs).filter(|r| !r.lower_bound && r.summary.is_some()).count();
    if asked_ok == 0 {
        bail!(
            "no run of the requested strategies succeeded, only the free-texture lower bound (see {})",
            cfg.out.join("results.md").display()
        );
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
    write_atomic(&out.join("results.md"), report::markdown(results).as_bytes())?;
    write_atomic(&out.join("report.html"), report::html(results).as_bytes())?;
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
    fn file_labels_are_safe() {
        assert_eq!(file_label("bake:1024"), "bake-1024");
        assert_eq!(file_label("nodes:NG/a,b"), "nodes-NG-a-b");
    }
}
