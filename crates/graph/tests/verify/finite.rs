//! Filtered evaluation never produces NaN or infinity, whatever the footprint's shape: zero,
//! tiny, huge, or degenerate (rank one, as when a coordinate channel is constant).

use glam::{Mat2, Vec2};
use graph::{Document, EvalScratch, Footprint, LoadOptions, NoOverride};
use std::path::{Path, PathBuf};

fn documents() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut docs = Vec::new();
    for dir in [root.join("../../scenes"), root.join("../render/tests/data")] {
        for e in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            if e.path().extension().is_some_and(|x| x == "mtlx") {
                docs.push(e.path());
            }
        }
    }
    let suite = root.join("../../../shared/mtlx-suite/docs");
    let mut stack = vec![suite];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "mtlx") {
                docs.push(p);
            }
        }
    }
    docs.sort();
    docs
}

#[test]
fn every_output_is_finite_for_every_footprint_shape() {
    let footprints = |uv: Vec2| {
        [
            Footprint::point(uv),
            Footprint::isotropic(uv, 1e-7),
            Footprint::isotropic(uv, 3e-3),
            Footprint::isotropic(uv, 1e3),
            Footprint::new(uv, Mat2::from_diagonal(Vec2::new(1e-4, 0.0))),
            Footprint::new(uv, Mat2::from_diagonal(Vec2::new(0.0, 0.3))),
            Footprint::new(uv, Mat2::from_cols(Vec2::new(1e-2, 1e-2), Vec2::new(1e-2, 1e-2))),
        ]
    };
    let opts = LoadOptions { lenient: true, ..LoadOptions::default() };
    let mut checked = 0;
    for path in documents() {
        let Ok(doc) = Document::load_with(&path, &opts) else { continue };
        let g = doc.graph();
        let mut scratch = EvalScratch::new(g);
        for node in g.node_ids() {
            for uv in [Vec2::new(0.3, 0.7), Vec2::new(-12.25, 3.5), Vec2::new(0.5, 0.5)] {
                for fp in footprints(uv) {
                    let f = g.eval_node_direct(node, &fp, &mut scratch, &NoOverride);
                    for m in &f.ch {
                        assert!(
                            m.mean.is_finite() && m.var.is_finite() && m.grad.is_finite(),
                            "{}: node {} ({}) at {fp:?}: {m:?}",
                            path.display(),
                            g.node_name(node),
                            g.node_category(node)
                        );
                    }
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 10_000, "{checked}");
}
