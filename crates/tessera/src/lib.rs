//! The `tessera` command: renders Mitsuba 3 scenes (or an embedded demo) and reports where the
//! time went. The binary is [`run_cli`]; [`api`] offers the same renders to other programs
//! (the Python package) with the command's checks and messages.

pub mod api;
mod bake_cmd;
mod bench;
mod flip;
mod footprint_cmd;
mod heatmap;
mod merge_cmd;
mod select_cmd;
mod svg;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use render::caching::{render_cached, NodeCache, Strategy};
use render::geometry::Intersector;
use render::integrator::{Bucket, RenderOutput, RenderSettings, AOV_NO_VERTEX};
use render::pathfootprint::FootprintMode;
use render::scene::Scene;
use render::stats::{
    CacheReport, CacheTotals, GraphStats, NonFiniteNode, NonFiniteOrigin, NonFiniteSampleStats, NonFiniteStats, Phases,
    RenderStats, Throughput, STATS_SCHEMA,
};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The demo scene built into the binary, rendered when no scene is given: marble spheres, a
/// mirror and a glass ball on a marble-tile floor (procedural MaterialX graphs).
pub(crate) const DEFAULT_SCENE: &str = include_str!("../../../scenes/marble.xml");
/// The MaterialX document the default scene uses.
const DEFAULT_SCENE_MTLX: &str = include_str!("../../../scenes/marble.mtlx");

#[derive(Parser, Debug)]
#[command(name = "tessera", version, about = "A path tracer with filtered procedural textures")]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// What traces rays: auto (every primitive tested in scenes of at most 48 triangles and 56
    /// primitives, else Embree 3 where its library is installed, else the built-in BVH), bvh (the built-in BVH), embree (an error
    /// without it) or exhaustive (every primitive tested, whatever the scene).
    #[arg(long, global = true, default_value = "auto", value_parser = |s: &str| s.parse::<render::accel::Backend>())]
    accel: render::accel::Backend,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a scene (Mitsuba 3 XML) to EXR and/or PNG.
    Render(RenderArgs),
    /// Trace one camera path and print the footprint at each of its vertices.
    Footprint(footprint_cmd::FootprintArgs),
    /// Evaluate a MaterialX output on a grid of texels over a uv rectangle and write an image.
    Bake(bake_cmd::BakeArgs),
    /// Profile a short render: per-node footprint levels, tiles touched and costs (profile.json).
    Profile(select_cmd::ProfileArgs),
    /// Choose the nodes to cache from a profile: the fastest predicted plan within a budget.
    Plan(select_cmd::PlanArgs),
    /// Analyse a profile: predictions per strategy and node, against measured renders if given.
    Analyze(select_cmd::AnalyzeArgs),
    /// Render every scene of a suite with each caching strategy and the free-texture lower bound;
    /// write results.json, results.md and report.html.
    Bench(bench::BenchArgs),
    /// Merge the pass files of one render (`render --samples A..B`, `--crop`) into its image,
    /// bit for bit the image of the render unsplit.
    Merge(merge_cmd::MergeArgs),
    /// Stitch the image windows of one render (`render --crop`) into its image: `merge` by
    /// another name (either takes any mix of sample passes and windows).
    Assemble(merge_cmd::MergeArgs),
}

#[derive(clap::Args, Debug)]
struct RenderArgs {
    /// Scene file (Mitsuba 3 XML). Without it, the embedded demo scene is rendered.
    scene: Option<PathBuf>,
    /// Samples per pixel (default: the scene's sample_count).
    #[arg(long)]
    spp: Option<u32>,
    /// Seed of the random streams (default: the scene's sampler seed).
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Output image, .exr (linear float) or .png (sRGB 8-bit). Default: both <name>.exr and <name>.png.
    #[arg(long)]
    out: Option<PathBuf>,
    /// No progress bar and no summary.
    #[arg(long)]
    quiet: bool,
    /// Write timings and counters as JSON to this file.
    #[arg(long)]
    stats_json: Option<PathBuf>,
    /// Override a scene <default>: -D name=value (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE")]
    define: Vec<String>,
    /// Footprint estimator carried by camera paths: covariance, raycone, pbrt or none.
    #[arg(long, default_value = "covariance", value_parser = parse_footprint)]
    footprint: FootprintMode,
    /// Extra outputs: `footprint` writes <out>.footprint.exr (mean LOD at bounces 1, 2, 3 in
    /// R, G, B) and <out>.footprint.png (a heat map).
    #[arg(long, value_parser = ["footprint"])]
    aov: Vec<String>,
    /// Width of procedural texture filtering relative to the footprint: a number (1 = the
    /// footprint, the default; 0 = point sampling) or `auto` (narrower as spp grows:
    /// max(1/8, 1/sqrt(spp))).
    #[arg(long, default_value = "1", value_parser = |s: &str| s.parse::<render::integrator::FilterScale>())]
    filter_scale: render::integrator::FilterScale,
    /// Which procedural graph nodes are cached as mip-mapped tiles: none, outputs, all, auto
    /// (profile, plan, render), nodes:a,b,c (node names, nodegraph/node), plan:FILE or bake:RES.
    #[arg(long, default_value = "none", value_parser = |s: &str| s.parse::<Strategy>())]
    strategy: Strategy,
    /// With --strategy auto: the share of the final render's pixels the profile traces, one
    /// sample each (of its samples where they evaluate their own first-hit textures, as with
    /// --per-sample-textures); at least 1024 samples.
    #[arg(long, default_value_t = select_cmd::DEFAULT_PROFILE_SHARE)]
    profile_share: f64,
    /// With --strategy auto: the report folder (profile.json, plan.json, table.md, plots);
    /// default <out>.report next to the image.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Memory budget of the tile cache in MiB (never exceeded).
    #[arg(long, default_value_t = 512.0)]
    budget_mb: f64,
    /// Replace every procedural texture by its mean value: the free-texture lower bound on
    /// render time (for benchmarks).
    #[arg(long)]
    free_textures: bool,
    /// Evaluate every sample's first-hit textures, and those seen through perfect mirrors and
    /// glass, at its own footprint. By default the samples of a pixel that meet the same
    /// surface (the same way) share one evaluation at the pixel centre's footprint (with the
    /// default --filter-scale 1, where every sample's first-hit footprint is centred there
    /// anyway): same image up to rounding at first hits, textures behind mirrors and glass
    /// blurred once by the pixel filter instead of twice, fewer evaluations.
    #[arg(long)]
    per_sample_textures: bool,
    /// Texels per uv unit at level 0 for footprint LODs in AOVs.
    #[arg(long, default_value_t = 1024.0)]
    aov_density: f64,
    /// Make a sample with NaN or infinite radiance, or a procedural texture value that is not
    /// finite, an error naming where it came from; nothing is written.
    #[arg(long)]
    strict: bool,
    /// Take only the sample indices A to B−1 (of the --spp of the whole render) in every pixel,
    /// and write a pass file (--out NAME.exr) for `tessera merge`.
    #[arg(long, value_name = "A..B", value_parser = parse_samples)]
    samples: Option<(u32, u32)>,
    /// Render only the window x0,y0,x1,y1 of the image (columns x0 to x1−1, rows y0 to y1−1)
    /// and write a pass file (--out NAME.exr) for `tessera assemble`.
    #[arg(long, value_name = "X0,Y0,X1,Y1", value_parser = parse_crop)]
    crop: Option<[u32; 4]>,
}

fn parse_samples(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("--samples expects A..B (sample indices A to B-1, A < B), got '{}'", render::xml::excerpt(s));
    let (a, b) = s.split_once("..").ok_or_else(bad)?;
    let (a, b): (u32, u32) = (a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?);
    if a >= b {
        return Err(bad());
    }
    Ok((a, b))
}

fn parse_crop(s: &str) -> Result<[u32; 4], String> {
    let bad =
        || format!("--crop expects x0,y0,x1,y1 (whole pixels, x0 < x1, y0 < y1), got '{}'", render::xml::excerpt(s));
    let v: Vec<u32> = s.split(',').map(|p| p.trim().parse().map_err(|_| bad())).collect::<Result<_, _>>()?;
    match v[..] {
        [x0, y0, x1, y1] if x0 < x1 && y0 < y1 => Ok([x0, y0, x1, y1]),
        _ => Err(bad()),
    }
}

fn parse_footprint(s: &str) -> Result<FootprintMode, String> {
    s.parse()
}

/// The `tessera` command line: parses the arguments, runs the command, and on error prints it
/// and exits with status 1.
pub fn run_cli() {
    let cli = Cli::parse();
    render::accel::set_backend(cli.accel);
    remove_temporaries_on_signals();
    let result = match cli.command {
        Command::Render(args) => run_render(args),
        Command::Footprint(args) => footprint_cmd::run(args),
        Command::Bake(args) => bake_cmd::run(args),
        Command::Profile(args) => select_cmd::run_profile(args),
        Command::Plan(args) => select_cmd::run_plan(args),
        Command::Analyze(args) => select_cmd::run_analyze(args),
        Command::Bench(args) => bench::run(args),
        Command::Merge(args) | Command::Assemble(args) => merge_cmd::run(args),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

/// On SIGINT, SIGTERM or SIGHUP: remove the temporary files of outputs being written (the
/// final files stay as they were) and exit with 130, as an interrupted shell command does.
fn remove_temporaries_on_signals() {
    let installed = ctrlc::set_handler(|| {
        render::output::remove_temporaries();
        eprintln!("interrupted: no output was written");
        std::process::exit(130);
    });
    if let Err(e) = installed {
        eprintln!("warning: cannot handle interrupts ({e}); an interrupted run may leave temporary files");
    }
}

pub(crate) fn parse_defines(defs: &[String]) -> Result<Vec<(String, String)>> {
    defs.iter()
        .map(|d| match d.split_once('=') {
            Some((k, v)) if !k.is_empty() => Ok((k.to_string(), v.to_string())),
            _ => bail!("-D expects NAME=VALUE, got '{d}'"),
        })
        .collect()
}

/// `tessera render`: loads and renders the scene, writes the images, then reports what was asked for.
fn run_render(args: RenderArgs) -> Result<()> {
    let defines = check_render_args(&args)?;
    let t_load = Instant::now();
    let scene = load_scene(args.scene.as_deref(), &defines)?;
    let load_s = t_load.elapsed().as_secs_f64();
    render_loaded(&args, &scene, &defines, load_s, true).map(|_| ())
}

/// Renders a loaded scene as `tessera render` with `args` does, with its checks, warnings and
/// `--strict`; with `write`, writes its images (or pass file), and always what `--stats-json`
/// and `--report` ask for. Returns the render and its stats.
pub(crate) fn render_loaded(
    args: &RenderArgs,
    scene: &Scene,
    defines: &[(String, String)],
    load_s: f64,
    write: bool,
) -> Result<(RenderOutput, RenderStats)> {
    let job = RenderJob::new(args, scene)?;
    let r = render(&job, scene, defines)?;
    let nonfinite = NonFiniteReport::of(scene, &r.out);
    if args.strict && !nonfinite.is_clean() {
        bail!("--strict: {}; nothing was written", nonfinite.message());
    }

    let t_write = Instant::now();
    // Every file of this render is staged first and moved into place together at the end: when
    // one cannot be written, no old output has been replaced by a new one.
    let batch = render::output::OutputBatch::begin();
    let (images, aov_files) = match (write, job.pass()) {
        (false, _) => (Vec::new(), Vec::new()),
        (true, true) => {
            let id = select_cmd::scene_id(args.scene.as_deref(), defines)?;
            let cache = r.node_cache.as_ref().map_or("none", |c| c.identity()).to_string();
            let identity = render::pass::identity(scene, &job.settings, &id.hash, cache);
            render::pass::Pass::of_render(&r.out, identity, &id.name)?.save(&job.outputs[0])?;
            (job.outputs.clone(), Vec::new())
        }
        (true, false) => (job.outputs.clone(), write_images(&job.outputs, &r.out)?),
    };
    let write_s = t_write.elapsed().as_secs_f64();
    let render_s = r.out.time.as_secs_f64();
    let phases = Phases { load_s, cache_setup_s: r.cache_setup_s, render_s, write_s };
    let stats = stats_of(&job, scene, &r, &nonfinite, &images, &aov_files, phases);
    if let Some(path) = &args.stats_json {
        write_atomic(path, serde_json::to_string_pretty(&stats)?.as_bytes())?;
    }
    let mut report = None;
    if let Some(a) = &r.auto {
        let dir = match (&args.report, write) {
            (Some(d), _) => Some(d.clone()),
            (None, true) => {
                let stem = job.outputs[0].with_extension("");
                Some(PathBuf::from(format!("{}.report", stem.display())))
            }
            (None, false) => None,
        };
        if let Some(dir) = dir {
            let measured = select_cmd::measured_of_render(&r.out.graph_stats, r.node_cache.as_ref(), render_s);
            report = Some((a.write_report(&dir, measured)?, dir));
        }
    }
    batch.commit()?;
    if !args.quiet {
        print_summary(&job, scene, &r, &images, &aov_files);
    }
    // Never quiet: a wrong value is reported even with --quiet.
    if !nonfinite.is_clean() {
        eprintln!("warning: {}", nonfinite.message());
    }
    if r.out.counts.clamped_samples > 0 {
        eprintln!(
            "warning: {} samples had radiance beyond {:e} and were clamped to it",
            r.out.counts.clamped_samples,
            render::film::SAMPLE_LIMIT
        );
    }
    if let (Some((comparison, dir)), false) = (&report, args.quiet) {
        eprintln!("{comparison}");
        eprintln!("report: {}", dir.display());
    }
    Ok((r.out, stats))
}

/// The checks of `tessera render`'s arguments that need no scene; returns the parsed defines.
fn check_render_args(args: &RenderArgs) -> Result<Vec<(String, String)>> {
    let defines = parse_defines(&args.define)?;
    if !(args.aov_density.is_finite() && args.aov_density > 0.0) {
        bail!("--aov-density must be a positive number, got {}", args.aov_density);
    }
    check_threads(args.threads)?;
    Ok(defines)
}

/// The most worker threads `--threads` accepts: beyond any machine's cores, and far below where
/// starting them would exhaust the system's threads.
pub const MAX_THREADS: usize = 1024;

/// Checks a `--threads` value: at least 1 and at most [`MAX_THREADS`].
pub fn check_threads(threads: Option<usize>) -> Result<()> {
    match threads {
        Some(0) => bail!("--threads must be at least 1"),
        Some(n) if n > MAX_THREADS => bail!(
            "--threads {n} is more than {MAX_THREADS} (this machine has {} cores)",
            std::thread::available_parallelism().map_or(1, |c| c.get())
        ),
        _ => Ok(()),
    }
}

/// A render to do: the arguments checked against the scene, what they resolve to, and the
/// worker pool it runs on.
struct RenderJob<'a> {
    args: &'a RenderArgs,
    spp: u32,
    seed: u64,
    /// The images to write; the AOV files and the auto report are named after the first.
    outputs: Vec<PathBuf>,
    threads: usize,
    pool: rayon::ThreadPool,
    settings: RenderSettings,
    /// The tile cache's budget, bytes.
    budget: usize,
}

impl<'a> RenderJob<'a> {
    /// Resolves the samples, seed, outputs and threads (the scene's where the arguments give
    /// none) and checks the rest of the arguments.
    fn new(args: &'a RenderArgs, scene: &Scene) -> Result<RenderJob<'a>> {
        let spp = args.spp.unwrap_or(scene.spp);
        if spp == 0 || spp > 1 << 24 {
            bail!("--spp must be between 1 and {}, got {spp}", 1 << 24);
        }
        let seed = args.seed.unwrap_or(scene.seed);
        let (w, h) = (scene.camera.width, scene.camera.height);
        if let Some((a, b)) = args.samples {
            if b > spp {
                bail!("--samples {a}..{b} goes beyond the render's {spp} samples per pixel (give the whole render's --spp)");
            }
        }
        let window = match args.crop {
            Some([x0, y0, x1, y1]) if x1 > w || y1 > h => {
                bail!("--crop {x0},{y0},{x1},{y1} reaches beyond the {w} × {h} image")
            }
            Some([x0, y0, x1, y1]) => Some(render::integrator::Bucket { x0, y0, x1, y1 }),
            None => None,
        };
        let pass = args.samples.is_some() || window.is_some();
        if pass {
            match &args.out {
                Some(o) if o.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr")) => {}
                _ => bail!("--samples and --crop write a pass file, an EXR: give --out NAME.exr"),
            }
            if args.strategy == Strategy::Auto {
                bail!(
                    "--strategy auto profiles each render on its own, and passes must all cache the same nodes: \
                     profile and plan once (tessera profile, tessera plan), then render every pass with --strategy plan:FILE"
                );
            }
            if !args.aov.is_empty() {
                bail!("--aov is written by whole renders only, not with --samples or --crop");
            }
        }
        let outputs: Vec<PathBuf> = match &args.out {
            Some(p) => vec![p.clone()],
            None => {
                let stem = args
                    .scene
                    .as_ref()
                    .and_then(|p| p.file_stem())
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "tessera".into());
                vec![PathBuf::from(format!("{stem}.exr")), PathBuf::from(format!("{stem}.png"))]
            }
        };
        for o in &outputs {
            render::film::check_image_output(o)?;
        }
        if let Some(o) = &args.stats_json {
            render::film::check_output(o)?;
        }
        if let Some(o) = &args.report {
            render::film::check_file_name(o)?;
        }
        // Each output once (two outputs naming one file would each replace the other), and never
        // what the render reads: an --out naming one of the scene's textures would destroy it
        // (and change the next render). Compared as absolute paths with links resolved.
        let inputs: Vec<PathBuf> = scene.files.iter().filter_map(|f| f.canonicalize().ok()).collect();
        let named: Vec<(&PathBuf, PathBuf)> =
            outputs.iter().chain(&args.stats_json).map(|p| (p, render::output::resolved(p))).collect();
        for (i, (o, id)) in named.iter().enumerate() {
            if named[..i].iter().any(|(_, earlier)| earlier == id) {
                bail!("{}: given as two of the render's outputs; name each output once", o.display());
            }
            if inputs.contains(id) {
                bail!(
                    "{}: is one of the scene's input files ({}); write the output elsewhere",
                    o.display(),
                    id.display()
                );
            }
        }

        let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
        let pool =
            rayon::ThreadPoolBuilder::new().num_threads(threads).build().context("cannot start worker threads")?;
        let want_aov = args.aov.iter().any(|a| a == "footprint");
        if want_aov && args.footprint == FootprintMode::None {
            bail!("--aov footprint needs a footprint estimator (not --footprint none)");
        }
        let settings = RenderSettings {
            footprint: args.footprint,
            footprint_aov_density: want_aov.then_some(args.aov_density),
            free_textures: args.free_textures,
            per_sample_textures: args.per_sample_textures,
            filter_scale: args.filter_scale,
            sample_range: args.samples,
            window,
            keep_sums: pass,
            ..RenderSettings::new(spp, seed)
        };
        if !(args.budget_mb.is_finite() && args.budget_mb > 0.0 && args.budget_mb <= 1.0e6) {
            bail!("--budget-mb must be a positive number of MiB (at most 1e6), got {}", args.budget_mb);
        }
        let budget = (args.budget_mb * 1048576.0) as usize;
        if !(args.profile_share > 0.0 && args.profile_share <= 1.0) {
            bail!("--profile-share must be in (0, 1], got {}", args.profile_share);
        }
        Ok(RenderJob { args, spp, seed, outputs, threads, pool, settings, budget })
    }

    /// Whether the render is one part of a split render, written as a pass file.
    fn pass(&self) -> bool {
        self.settings.keep_sums
    }
}

/// The progress bar over the image's pixels: drawn on a terminal unless --quiet, hidden otherwise.
fn progress_bar(job: &RenderJob, scene: &Scene) -> ProgressBar {
    let window = job.settings.window.unwrap_or(Bucket::full(scene.camera.width, scene.camera.height));
    let show = !job.args.quiet && std::io::stderr().is_terminal();
    let bar = ProgressBar::with_draw_target(
        Some(window.len() as u64),
        if show { ProgressDrawTarget::stderr() } else { ProgressDrawTarget::hidden() },
    );
    bar.set_style(
        ProgressStyle::with_template("{spinner} rendering [{bar:40}] {percent:>3}% {elapsed_precise} eta {eta}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar
}

/// A finished render: its output, and the plan and the tile cache it used.
struct Rendered {
    out: RenderOutput,
    node_cache: Option<NodeCache>,
    auto: Option<select_cmd::AutoPlan>,
    cache_setup_s: f64,
}

/// The render itself, on the job's pool: `--strategy auto`'s profile and plan when asked for,
/// the tile cache, then the image, with a progress bar.
fn render(job: &RenderJob, scene: &Scene, defines: &[(String, String)]) -> Result<Rendered> {
    let (args, pool) = (job.args, &job.pool);
    let bar = progress_bar(job, scene);
    let auto = match args.strategy {
        Strategy::Auto => Some(pool.install(|| {
            select_cmd::auto_plan(scene, args.scene.as_deref(), defines, job.settings, args.profile_share, job.budget)
        })?),
        _ => None,
    };
    let t_cache = Instant::now();
    let node_cache = match &auto {
        Some(a) => pool.install(|| NodeCache::from_plan(scene, &a.file, job.budget))?,
        None => pool.install(|| NodeCache::new(scene, &args.strategy, job.budget))?,
    };
    let cache_setup_s = t_cache.elapsed().as_secs_f64();
    let out = pool.install(|| render_cached(scene, job.settings, node_cache.as_ref(), &|n| bar.inc(n)));
    bar.finish_and_clear();
    Ok(Rendered { out, node_cache, auto, cache_setup_s })
}

/// Writes the image to every output, and the footprint AOV (EXR and heat map) beside the first
/// when there is one; returns the AOV's files.
fn write_images(outputs: &[PathBuf], out: &RenderOutput) -> Result<Vec<PathBuf>> {
    for o in outputs {
        out.image.save(o)?;
    }
    let mut aov_files = Vec::new();
    if let Some(aov) = &out.footprint_aov {
        let stem = outputs[0].with_extension("");
        let exr = PathBuf::from(format!("{}.footprint.exr", stem.display()));
        let png = PathBuf::from(format!("{}.footprint.png", stem.display()));
        aov.save(&exr)?;
        heatmap::write_heatmap(aov, AOV_NO_VERTEX, &png)?;
        aov_files.push(exr);
        aov_files.push(png);
    }
    Ok(aov_files)
}

/// The summary on stderr: size, time and rates, the files written, the graphs' node
/// evaluations, the tile cache's counters and what `--strategy auto` chose.
fn print_summary(job: &RenderJob, scene: &Scene, r: &Rendered, images: &[PathBuf], aov_files: &[PathBuf]) {
    let (w, h) = (r.out.image.width, r.out.image.height);
    let (spp, threads) = (r.out.samples.len(), job.threads);
    let render_s = r.out.time.as_secs_f64();
    let c = r.out.counts;
    let total_rays = c.rays + c.shadow_rays;
    let names: Vec<String> = images.iter().chain(aov_files).map(|p| p.display().to_string()).collect();
    let wrote = if names.is_empty() { String::new() } else { format!("; wrote {}", names.join(", ")) };
    eprintln!(
        "rendered {w}x{h} at {spp} spp in {render_s:.2} s on {threads} threads: {:.3} Msamples/s, {:.2} Mrays/s by {}{wrote}",
        c.samples as f64 / render_s / 1e6,
        total_rays as f64 / render_s / 1e6,
        scene.accel.describe(),
    );
    let node_evals: u64 = r.out.graph_stats.iter().flat_map(|g| g.evaluations.iter()).sum();
    if node_evals > 0 {
        eprintln!(
            "procedural textures: {node_evals} node evaluations ({:.1} per sample) in {} graph(s)",
            node_evals as f64 / c.samples.max(1) as f64,
            scene.graphs.len()
        );
    }
    if c.pixel_texture_evaluations > 0 {
        eprintln!(
            "shared textures: {} of {} first hits and hits through mirrors and glass read their pixel's, evaluated once per pixel and surface ({} evaluations)",
            c.pixel_texture_reads,
            c.pixel_texture_reads + c.pixel_texture_misses,
            c.pixel_texture_evaluations
        );
    }
    if c.footprints_skipped > 0 {
        eprintln!(
            "footprints: {} computed, {} never needed (no texture read them, at their hit or later on the path)",
            c.footprints, c.footprints_skipped
        );
    }
    if let Some(nc) = &r.node_cache {
        let t = CacheTotals::of(nc);
        eprintln!(
            "tile cache: {} nodes cached, {} lookups, {} tile hits / {} misses, {} tiles filled ({} co-filled, {} texels), {} evictions, peak {:.1} MiB of {:.1} MiB",
            nc.cached_nodes(),
            t.lookups,
            t.tile_hits,
            t.tile_misses,
            t.tiles_filled,
            t.tiles_co_filled,
            t.texels_filled,
            t.evictions,
            t.peak_bytes as f64 / 1048576.0,
            t.budget_bytes as f64 / 1048576.0
        );
        if t.texels_saturated > 0 {
            // Usually texels of coarse tiles far outside the uv range the scene reads.
            eprintln!(
                "tile cache: {} channel values beyond the half-float range were stored as ±65504",
                t.texels_saturated
            );
        }
    }
    if let Some(a) = &r.auto {
        eprintln!(
            "auto: profiled {} samples in {:.2} s, planned in {:.3} s ({}, {} candidates): caching {}",
            a.profile.render.samples,
            a.profile_s,
            a.plan_s,
            a.result.method,
            a.result.candidates,
            if a.file.nodes.is_empty() {
                "nothing".to_string()
            } else {
                a.file.nodes.iter().map(|n| n.node.as_str()).collect::<Vec<_>>().join(", ")
            }
        );
    }
}

/// The stats (`tessera.stats/1`, a [`RenderStats`]): the settings, the files, each phase's
/// time, the counters and rates, the values that were not finite, the graphs, the plan and the
/// tile cache.
fn stats_of(
    job: &RenderJob,
    scene: &Scene,
    r: &Rendered,
    nonfinite: &NonFiniteReport,
    images: &[PathBuf],
    aov_files: &[PathBuf],
    phases: Phases,
) -> RenderStats {
    let args = job.args;
    let c = r.out.counts;
    let total_rays = c.rays + c.shadow_rays;
    let display = |p: &PathBuf| p.display().to_string();
    RenderStats {
        schema: STATS_SCHEMA.into(),
        scene: args.scene.as_ref().map(display).unwrap_or_else(|| "<embedded default scene>".into()),
        images: images.iter().map(display).collect(),
        aovs: aov_files.iter().map(display).collect(),
        footprint: format!("{:?}", args.footprint).to_lowercase(),
        accel: scene.accel.describe(),
        width: scene.camera.width,
        height: scene.camera.height,
        spp: job.spp,
        seed: job.seed,
        threads: job.threads as u32,
        phases,
        counts: (&c).into(),
        nonfinite: nonfinite.stats(),
        throughput: Throughput {
            samples_per_s: c.samples as f64 / phases.render_s,
            rays_per_s: total_rays as f64 / phases.render_s,
        },
        graphs: GraphStats::of_render(&scene.graphs, &r.out.graph_stats),
        plan: r.auto.as_ref().map(|a| a.stats()),
        cache: r.node_cache.as_ref().map(|nc| CacheReport::of(nc, &scene.graphs, args.strategy.to_string())),
    }
}

/// What a render says about values that were not finite: samples left out of their pixels
/// (with the first ones' origins), graph nodes that gave non-finite values, and the first
/// shading points where they did.
struct NonFiniteReport<'a> {
    scene: &'a Scene,
    out: &'a render::integrator::RenderOutput,
    /// (graph index, node, evaluations in which that node was the first to go non-finite).
    nodes: Vec<(usize, graph::NodeId, u64)>,
}

impl<'a> NonFiniteReport<'a> {
    fn of(scene: &'a Scene, out: &'a render::integrator::RenderOutput) -> NonFiniteReport<'a> {
        let mut nodes = Vec::new();
        for (gi, st) in out.graph_stats.iter().enumerate() {
            for (ni, &n) in st.nonfinite.iter().enumerate() {
                if n > 0 {
                    nodes.push((gi, graph::NodeId(ni as u32), n));
                }
            }
        }
        NonFiniteReport { scene, out, nodes }
    }

    fn is_clean(&self) -> bool {
        self.out.counts.nonfinite_samples == 0 && self.nodes.is_empty()
    }

    /// One paragraph: the count, the first samples' origins, the nodes and the first shading
    /// points.
    fn message(&self) -> String {
        let graphs = &self.scene.graphs;
        let lines = |v: &[render::shading::NonFiniteSample]| {
            v.iter().map(|s| s.describe(graphs)).collect::<Vec<_>>().join("; ")
        };
        let mut m = String::new();
        let samples = self.out.counts.nonfinite_samples;
        if samples > 0 {
            m += &format!(
                "{samples} samples had NaN or infinite radiance and were left out of their pixels; the first: {}",
                lines(&self.out.nonfinite)
            );
        }
        if !self.nodes.is_empty() {
            if !m.is_empty() {
                m += ". ";
            }
            let nodes: Vec<String> = self
                .nodes
                .iter()
                .map(|&(gi, id, n)| {
                    let (sg, g) = (&graphs[gi], graphs[gi].graph());
                    format!("graph {}: node `{}` ({}) {n} times", sg.file_name(), g.node_name(id), g.node_category(id))
                })
                .collect();
            m += &format!(
                "procedural texture values that were not finite came first from: {}; the first such shading points: {}",
                nodes.join("; "),
                lines(&self.out.graph_nonfinite)
            );
        }
        m
    }

    fn stats(&self) -> NonFiniteStats {
        let scene = self.scene;
        let sample = |s: &render::shading::NonFiniteSample| NonFiniteSampleStats {
            x: s.x,
            y: s.y,
            sample: s.sample,
            origin: s.origin.as_ref().map(|o| {
                let sg = &scene.graphs[o.graph as usize];
                let g = sg.graph();
                NonFiniteOrigin {
                    material: o.material.clone(),
                    graph: sg.file_name().to_string(),
                    node: g.node_name(o.at.node).to_string(),
                    category: g.node_category(o.at.node).to_string(),
                    uv: [o.at.uv.x, o.at.uv.y],
                    sigma: o.at.sigma,
                    bounce: o.bounce,
                }
            }),
        };
        let nodes = self
            .nodes
            .iter()
            .map(|&(gi, id, count)| {
                let sg = &scene.graphs[gi];
                NonFiniteNode {
                    graph: sg.file_name().to_string(),
                    node: sg.graph().node_name(id).to_string(),
                    category: sg.graph().node_category(id).to_string(),
                    count,
                }
            })
            .collect();
        NonFiniteStats {
            samples: self.out.counts.nonfinite_samples,
            first: self.out.nonfinite.iter().map(sample).collect(),
            nodes,
            values: self.out.graph_nonfinite.iter().map(sample).collect(),
        }
    }
}

/// Loads a scene file, or the embedded demo scene when none is given.
pub(crate) fn load_scene(path: Option<&Path>, defines: &[(String, String)]) -> Result<Scene> {
    Ok(match path {
        Some(path) => render::loader::load_file(path, defines)?,
        None => render::loader::load_str_with_files(
            DEFAULT_SCENE,
            Path::new("<embedded default scene>"),
            Path::new("."),
            defines,
            &[("marble.mtlx", DEFAULT_SCENE_MTLX)],
        )?,
    })
}

/// Writes `bytes` to `path` through a temporary file renamed into place.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    Ok(render::film::write_through_temp(path, |tmp| {
        std::fs::write(tmp, bytes).map_err(|e| render::error::Error::in_file(path, format!("cannot write: {e}")))
    })?)
}
