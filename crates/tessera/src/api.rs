//! tessera's commands for other programs (the Python package, `crates/python`): a scene loaded
//! once and rendered many times, one camera path's footprints, and bakes, with the command
//! line's own checks, messages and results. Render options are the flags of `tessera render`,
//! so a program's render is the command's, bit for bit.

use crate::bake_cmd::{BakeJob, Baked};
use crate::{check_render_args, load_scene, RenderArgs};
use anyhow::{bail, Result};
use clap::Parser;
use render::integrator::RenderOutput;
use render::pathfootprint::FootprintMode;
use render::scene::Scene;
use render::stats::RenderStats;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A scene loaded with its `-D` defines, ready to render.
pub struct LoadedScene {
    scene: Scene,
    path: Option<PathBuf>,
    defines: Vec<(String, String)>,
    load_s: f64,
}

impl LoadedScene {
    /// Loads a scene file (the embedded demo scene when `path` is `None`).
    pub fn load(path: Option<&Path>, defines: &[(String, String)]) -> Result<LoadedScene> {
        let t = Instant::now();
        let scene = load_scene(path, defines)?;
        Ok(LoadedScene {
            scene,
            path: path.map(Path::to_path_buf),
            defines: defines.to_vec(),
            load_s: t.elapsed().as_secs_f64(),
        })
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The file it was loaded from (`None`: the embedded demo scene).
    pub fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }

    /// Its defines.
    pub fn defines(&self) -> &[(String, String)] {
        &self.defines
    }

    /// Every file it was built from ([`Scene::files`]): what a render elsewhere needs.
    pub fn files(&self) -> &[PathBuf] {
        &self.scene.files
    }

    /// Profiles and plans as `--strategy auto` does for a render with `options` (its `--spp`,
    /// `--seed`, `--budget-mb`, `--profile-share`, `--threads`, footprint and filter flags);
    /// returns the plan file (`tessera.plan/1`) as JSON, for `--strategy plan:FILE`.
    pub fn plan(&self, options: &[String]) -> Result<String> {
        let args = self.render_args(options)?;
        let job = crate::RenderJob::new(&args, &self.scene)?;
        let auto = job.pool.install(|| {
            crate::select_cmd::auto_plan(
                &self.scene,
                self.path.as_deref(),
                &self.defines,
                job.settings,
                args.profile_share,
                job.budget,
            )
        })?;
        Ok(serde_json::to_string_pretty(&auto.file)?)
    }

    /// Renders it as `tessera render SCENE OPTIONS...` does, `options` being the command's
    /// flags (`--spp 16`, `--strategy auto`, ...; not the scene nor `-D`, which the load
    /// fixed). Without `--out`, nothing is written but what `--stats-json` and `--report` ask
    /// for; with it, the files are the command's (images, or a pass file).
    pub fn render(&self, options: &[String]) -> Result<(RenderOutput, RenderStats)> {
        let args = self.render_args(options)?;
        let defines = check_render_args(&args)?;
        let write = args.out.is_some();
        crate::render_loaded(&args, &self.scene, &defines, self.load_s, write)
    }

    /// `tessera render`'s arguments: `options` with this scene and its defines.
    fn render_args(&self, options: &[String]) -> Result<RenderArgs> {
        #[derive(Parser)]
        #[command(name = "render", no_binary_name = true)]
        struct Options {
            #[command(flatten)]
            args: RenderArgs,
        }
        let mut args = Options::try_parse_from(options).map_err(|e| anyhow::anyhow!("{}", e.render()))?.args;
        if args.scene.is_some() || !args.define.is_empty() {
            bail!("the scene and its -D defines are given when it is loaded, not when it is rendered");
        }
        args.scene = self.path.clone();
        args.define = self.defines.iter().map(|(k, v)| format!("{k}={v}")).collect();
        Ok(args)
    }

    /// Traces sample 0 of pixel (`x`, `y`) as a render does and returns each vertex's
    /// footprint as `tessera footprint --json` prints it (`tessera.footprint/1`).
    pub fn footprint(&self, x: u32, y: u32, seed: Option<u64>, estimator: &str, density: f64) -> Result<String> {
        let mode: FootprintMode = estimator.parse().map_err(|e: String| anyhow::anyhow!(e))?;
        let name = self.path.as_ref().map_or("<embedded default scene>".into(), |p| p.display().to_string());
        let v = crate::footprint_cmd::trace(&self.scene, &name, (x, y), seed, mode, density)?;
        Ok(serde_json::to_string(&v)?)
    }
}

/// Bakes as `tessera bake DOCUMENT OPTIONS...` does (`--element`, `--res`, ..., not `--out`),
/// returning the texels (rows top first, channels interleaved) and their channel names.
pub fn bake(document: &Path, options: &[String]) -> Result<(graph::BakedImage, Vec<&'static str>)> {
    #[derive(Parser)]
    #[command(name = "bake", no_binary_name = true)]
    struct Options {
        #[command(flatten)]
        job: BakeJob,
    }
    let mut argv = vec![document.display().to_string()];
    argv.extend(options.iter().cloned());
    let job = Options::try_parse_from(argv).map_err(|e| anyhow::anyhow!("{}", e.render()))?.job;
    let Baked { image, .. } = job.run()?;
    let names = image.channel_names().to_vec();
    Ok((image, names))
}

/// Merges pass files as `tessera merge` does: the image, the passes' summed counts and the
/// render they were parts of.
pub fn merge(passes: &[PathBuf]) -> Result<render::pass::Merged> {
    Ok(render::pass::merge_files(passes)?)
}
