//! `tessera footprint`: trace one camera path and print each vertex's footprint.
//!
//! The path is sample 0 of the pixel under the given seed, exactly as `tessera render` traces it.
//! JSON schema `tessera.footprint/1`: `{ schema, scene, pixel, seed, estimator, density,
//! vertices: [...] }`, one entry per vertex with `position`, `normal` (shading), `event`
//! (`reflect`, `refract`, `diffuse`, `emit`, `absorb`, `escape`), `alpha` (Beckmann-equivalent
//! roughness of the sampled lobe), `eta` (relative IOR η_o/η_i of a refraction, 1 otherwise),
//! `cov_world` (3×3, row-major nested arrays, = T Σ Tᵀ), `uv`, `cov_uv` (2×2), `lod`
//! (log2 of the footprint's major-axis standard deviation in texels of `density` per uv unit).
//! An escaping ray adds a last entry with `event: "escape"` and its `direction`.

use crate::{load_scene, parse_defines};
use anyhow::{bail, Result};
use footprint::Vertex;
use glam::{DMat2, Vec3};
use render::geometry::SurfaceInteraction;
use render::integrator::{radiance, Event, PathObserver, RenderCounts, RenderSettings};
use render::pathfootprint::FootprintMode;
use serde_json::{json, Value};
use std::path::PathBuf;

/// Arguments of `tessera footprint`.
#[derive(clap::Args, Debug)]
pub struct FootprintArgs {
    /// Scene file (default: the embedded demo scene).
    scene: Option<PathBuf>,
    /// Pixel column and row.
    #[arg(long, num_args = 2, value_names = ["X", "Y"], required = true)]
    pixel: Vec<u32>,
    /// Seed (default: the scene's).
    #[arg(long)]
    seed: Option<u64>,
    /// Footprint estimator.
    #[arg(long, default_value = "covariance", value_parser = |s: &str| s.parse::<FootprintMode>())]
    footprint: FootprintMode,
    /// Texels per uv unit for `lod`.
    #[arg(long, default_value_t = 1024.0)]
    density: f64,
    /// Print JSON (otherwise a readable table).
    #[arg(long)]
    json: bool,
    /// Override a scene <default>: -D name=value.
    #[arg(short = 'D', value_name = "NAME=VALUE")]
    define: Vec<String>,
}

struct Recorder {
    density: f64,
    vertices: Vec<Value>,
}

fn mat2_json(m: DMat2) -> Value {
    json!([[m.x_axis.x, m.y_axis.x], [m.x_axis.y, m.y_axis.y]])
}

impl PathObserver for Recorder {
    const WANTS_FOOTPRINTS: bool = true;
    fn hit(&mut self, _depth: u32, si: &SurfaceInteraction, vertex: Option<&Vertex>, var: DMat2) {
        let mut v = json!({
            "position": [si.p.x, si.p.y, si.p.z],
            "normal": [si.sh.n.x, si.sh.n.y, si.sh.n.z],
            "uv": [si.uv.x, si.uv.y],
        });
        if let Some(vx) = vertex {
            let fp = footprint::VertexFootprint::new(var, vx);
            let w = fp.world;
            v["cov_world"] = json!([
                [w.x_axis.x, w.y_axis.x, w.z_axis.x],
                [w.x_axis.y, w.y_axis.y, w.z_axis.y],
                [w.x_axis.z, w.y_axis.z, w.z_axis.z]
            ]);
            v["cov_uv"] = mat2_json(fp.uv);
            v["lod"] = json!(fp.lod(self.density));
        }
        self.vertices.push(v);
    }

    fn event(&mut self, _depth: u32, event: Event, alpha: f32, eta: f32) {
        if let Some(v) = self.vertices.last_mut() {
            v["event"] = json!(event.name());
            v["alpha"] = json!(alpha);
            v["eta"] = json!(if event == Event::Refract { eta } else { 1.0 });
        }
    }

    fn escape(&mut self, _depth: u32, dir: Vec3) {
        self.vertices.push(json!({ "event": "escape", "direction": [dir.x, dir.y, dir.z] }));
    }
}

/// Runs `tessera footprint`.
pub fn run(args: FootprintArgs) -> Result<()> {
    let defines = parse_defines(&args.define)?;
    let scene = load_scene(args.scene.as_deref(), &defines)?;
    let name =
        args.scene.as_ref().map(|p| p.display().to_string()).unwrap_or_else(|| "<embedded default scene>".into());
    let out = trace(&scene, &name, (args.pixel[0], args.pixel[1]), args.seed, args.footprint, args.density)?;
    let (x, y, seed) = (args.pixel[0], args.pixel[1], &out["seed"]);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!("pixel ({x}, {y}), seed {seed}, estimator {}", out["estimator"].as_str().unwrap_or(""));
        for (i, v) in out["vertices"].as_array().into_iter().flatten().enumerate() {
            println!(
                "x{}  {:<8} p={}  alpha={}  lod={}",
                i + 1,
                v["event"].as_str().unwrap_or("-"),
                v.get("position").map_or("-".into(), |p| p.to_string()),
                v.get("alpha").map_or("-".into(), |a| a.to_string()),
                v.get("lod").map_or("-".into(), |a| a.to_string())
            );
        }
    }
    Ok(())
}

/// Traces sample 0 of `pixel` (with the scene's seed when `seed` is `None`), exactly as
/// `tessera render` traces it, and returns its vertices' footprints (`tessera.footprint/1`).
pub(crate) fn trace(
    scene: &render::scene::Scene,
    name: &str,
    (x, y): (u32, u32),
    seed: Option<u64>,
    estimator: FootprintMode,
    density: f64,
) -> Result<Value> {
    if x >= scene.camera.width || y >= scene.camera.height {
        bail!("--pixel {x} {y} is outside the {}×{} image", scene.camera.width, scene.camera.height);
    }
    if !(density.is_finite() && density > 0.0) {
        bail!("--density must be a positive number, got {density}");
    }
    let seed = seed.unwrap_or(scene.seed);
    let settings = RenderSettings { footprint: estimator, ..RenderSettings::new(scene.spp, seed) };
    // Sample 0 of this pixel, with the same stream and filter offset as `tessera render`.
    let (cam, mut rng) = render::integrator::camera_sample(scene, seed, x, y, 0);
    let mut rec = Recorder { density, vertices: Vec::new() };
    let mut shade = render::shading::TextureEvaluator::new(&scene.graphs, &scene.materials, render::shading::Direct);
    let l = radiance(scene, settings, &cam, &mut rng, &mut RenderCounts::default(), &mut shade, &mut rec);
    // A vertex without an event is where a path ended by Russian roulette after scattering.
    Ok(json!({
        "schema": "tessera.footprint/1",
        "scene": name,
        "pixel": [x, y],
        "seed": seed,
        "estimator": format!("{estimator:?}").to_lowercase(),
        "density": density,
        "radiance": [l.x, l.y, l.z],
        "vertices": rec.vertices,
    }))
}
