//! ns per evaluation of the 2D and 3D noise nodes (Perlin, fractal, cell, Worley, unified),
//! point-sampled and filtered, for comparing two builds run alternately on one machine:
//!
//! ```text
//! cargo run --release -p graph --example noise_bench [ROUNDS]
//! ```
//!
//! Each row is the fastest of `ROUNDS` (default 7) timed rounds over 64 footprint centres; the
//! coordinate is `texcoord × 8` (2D) or the position of an oblique surface × 4 (3D), so every
//! lattice axis spreads under a filtered footprint.
//! `NOISE_BENCH_ONLY=TEXT` times only the rows whose name contains `TEXT` (e.g. `fractal3d`),
//! so that a suspect row can be rerun many times or profiled on its own.

use glam::{Mat2, Vec2, Vec3};
use graph::{Document, EvalScratch, Footprint, Geometry, LoadOptions};
use std::time::Instant;

/// (row name, node category, output type, inputs after the coordinate).
const NODES: &[(&str, &str, &str, &str)] = &[
    ("perlin", "noise", "float", ""),
    ("perlin_v3", "noise", "vector3", ""),
    ("fractal", "fractal", "float", r#"<input name="octaves" type="integer" value="6"/>"#),
    ("cell", "cellnoise", "float", ""),
    ("worley", "worleynoise", "float", ""),
    ("unified_perlin", "unifiednoise", "float", r#"<input name="type" type="integer" value="0"/>"#),
    ("unified_worley", "unifiednoise", "float", r#"<input name="type" type="integer" value="2"/>"#),
    (
        "unified_fractal",
        "unifiednoise",
        "float",
        r#"<input name="type" type="integer" value="3"/><input name="jitter" type="float" value="0.9"/>"#,
    ),
];

/// Footprint standard deviations (uv units): a point, then lattice spreads of about 0.01, 0.1 and
/// 0.8 cells.
const SIGMAS: [f32; 4] = [0.0, 1e-3, 1e-2, 1e-1];

fn oblique(uv: Vec2) -> Geometry {
    let (dpdu, dpdv) = (Vec3::new(1.7, 0.9, 1.1), Vec3::new(0.4, 1.9, -0.7));
    let n = dpdu.cross(dpdv).normalize();
    let t = dpdu.normalize();
    let p = Vec3::new(0.3, -0.8, 2.1) + dpdu * uv.x + dpdv * uv.y;
    Geometry { p, n, t, b: n.cross(t), dpdu, dpdv, dndu: Vec3::ZERO, dndv: Vec3::ZERO }
}

fn main() {
    let rounds: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(7);
    let only = std::env::var("NOISE_BENCH_ONLY").unwrap_or_default();
    let uvs: Vec<Vec2> = (0..64).map(|i| Vec2::new((i as f32 * 0.618034) % 1.0, (i as f32 * 0.754878) % 1.0)).collect();
    println!("| node | σ (uv) | ns / eval |");
    println!("|---|---:|---:|");
    for dim in [2, 3] {
        for &(row, category, ty, body) in NODES {
            if !format!("{category}{dim}d {row}").contains(&only) {
                continue;
            }
            let (vty, src, name, scale) = if dim == 2 {
                ("vector2", "texcoord", "texcoord", "8, 8")
            } else {
                ("vector3", "position", "position", "4, 4, 4")
            };
            let text = format!(
                r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">
<{src} name="t" type="{vty}"/>
<multiply name="s" type="{vty}"><input name="in1" type="{vty}" nodename="t"/><input name="in2" type="{vty}" value="{scale}"/></multiply>
<{category}{dim}d name="x" type="{ty}"><input name="{name}" type="{vty}" nodename="s"/>{body}</{category}{dim}d>
<output name="out" type="{ty}" nodename="x"/></nodegraph></materialx>"#
            );
            let doc =
                Document::parse(&text, "bench.mtlx".as_ref(), &LoadOptions::default()).expect("bench graph loads");
            let g = doc.graph();
            let out = g.output_id("out").or_else(|| g.output_id("g/out")).expect("output");
            let mut scratch = EvalScratch::new(g);
            for sigma in SIGMAS {
                let fps: Vec<Footprint> = uvs
                    .iter()
                    .map(|&uv| {
                        let cov = Mat2::from_diagonal(Vec2::splat(sigma * sigma));
                        if dim == 2 {
                            Footprint::new(uv, cov)
                        } else {
                            Footprint::with_geometry(uv, cov, oblique(uv))
                        }
                    })
                    .collect();
                let mut eval_all = || {
                    for fp in &fps {
                        std::hint::black_box(g.eval_output(out, fp, &mut scratch));
                    }
                };
                // Enough passes for a round of about 20 ms.
                let t0 = Instant::now();
                eval_all();
                let passes = ((0.02 / t0.elapsed().as_secs_f64().max(1e-7)) as usize).clamp(1, 100_000);
                let mut best = f64::MAX;
                for _ in 0..rounds {
                    let t = Instant::now();
                    for _ in 0..passes {
                        eval_all();
                    }
                    best = best.min(t.elapsed().as_secs_f64() / (passes * fps.len()) as f64);
                }
                println!("| {category}{dim}d {row} | {sigma:e} | {:.1} |", best * 1e9);
            }
        }
    }
}
