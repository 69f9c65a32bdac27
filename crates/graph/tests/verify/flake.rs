//! `flake2d`, `flake3d`: the multi-output document form, filtered values against brute-force
//! Gaussian supersampling, and finiteness. Their unfiltered values are compared with MaterialX's
//! own bakes by the conformance runner (`suite.rs`, `mtlx-refs/docs/flake*.mtlx`: exact).

use crate::common::{self, Rng};
use glam::Vec2;
use graph::{Document, EvalScratch, Footprint, Graph, LoadOptions};

fn graph_of(body: &str) -> Graph {
    let text =
        format!(r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">{body}</nodegraph></materialx>"#);
    Document::parse(&text, "test.mtlx".as_ref(), &LoadOptions::default()).unwrap().into_graph()
}

/// One flake node, every output connected (as MaterialX documents connect a multi-output node).
fn flakes(category: &str, size: f32, coverage: f32) -> Graph {
    graph_of(&format!(
        r#"<{category} name="f" type="multioutput"><input name="size" type="float" value="{size}"/><input name="coverage" type="float" value="{coverage}"/><input name="roughness" type="float" value="0.4"/></{category}>
        <output name="id" type="integer" nodename="f" output="id"/>
        <output name="rand" type="float" nodename="f" output="rand"/>
        <output name="presence" type="float" nodename="f" output="presence"/>
        <output name="flakenormal" type="vector3" nodename="f" output="flakenormal"/>"#
    ))
}

/// The outputs of one node agree: no flake gives 0, 0, 0 and the normal; a flake's id is its
/// rand scaled to 2²⁴ − 1.
#[test]
fn outputs_agree() {
    let g = flakes("flake2d", 0.05, 0.6);
    let out = |n: &str| g.output_id(&format!("g/{n}")).unwrap();
    let mut s = EvalScratch::new(&g);
    let mut rng = Rng(5);
    let (mut some, mut none) = (0, 0);
    for _ in 0..2000 {
        let fp = Footprint::point(Vec2::new(rng.uniform() as f32, rng.uniform() as f32));
        let id = g.eval_output(out("id"), &fp, &mut s).ch[0].mean;
        let rand = g.eval_output(out("rand"), &fp, &mut s).ch[0].mean;
        let presence = g.eval_output(out("presence"), &fp, &mut s).ch[0].mean;
        let n = g.eval_output(out("flakenormal"), &fp, &mut s);
        let len = (0..3).map(|k| n.ch[k].mean * n.ch[k].mean).sum::<f32>().sqrt();
        assert!((len - 1.0).abs() < 1e-5, "normal length {len}");
        if presence > 0.0 {
            some += 1;
            assert_eq!(id, (rand * 16_777_215.0) as i32 as f32);
        } else {
            none += 1;
            assert!(id == 0.0 && rand == 0.0 && n.ch[2].mean == 1.0);
        }
    }
    assert!(some > 200 && none > 200, "{some} flakes, {none} without");
}

/// An output that is not one of the node's is an error naming it.
#[test]
fn unknown_output_is_an_error() {
    let text = r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g"><flake2d name="f" type="multioutput"/><output name="o" type="float" nodename="f" output="shine"/></nodegraph></materialx>"#;
    let Err(e) = Document::parse(text, "t.mtlx".as_ref(), &LoadOptions::default()) else {
        panic!("an unknown output loads")
    };
    let e = e.to_string();
    assert!(e.contains("f.shine"), "{e}");
}

/// Filtered against supersampling (mean abs error per channel):
/// - σ ≤ 1e-6 uv: within 1e-4 of the brute force (flakes are constant inside, so the point value);
/// - where point sampling errs by more than 0.01: at most 0.7 of its error (25 cubature nodes of a
///   piecewise-constant function against 2048 samples; measured at most 0.61, in the move to the
///   ensemble);
/// - σ ≥ 3 flake cells: within 0.1 (the 64-point ensemble, itself a sample of 64 cells, against
///   the footprint's own cells: measured up to 0.075);
/// - the reported spread √var within [0.5, 1.7] × the samples' spread where it exceeds 0.01 (measured 0.6–1.6).
#[test]
fn filtered_matches_supersampling() {
    let sigmas = [1e-6, 1e-4, 1e-3, 3e-3, 1e-2, 0.03, 0.1, 0.3, 1.0];
    let mut failures = Vec::new();
    let mut sweeps = Vec::new();
    println!("{}", common::sweep_header());
    for (ci, (category, size, coverage)) in
        [("flake2d", 0.02f32, 0.5f32), ("flake2d", 0.1, 0.9), ("flake3d", 0.05, 0.3)].into_iter().enumerate()
    {
        let g = flakes(category, size, coverage);
        for output in ["rand", "presence", "flakenormal"] {
            let out = g.output_id(&format!("g/{output}")).unwrap();
            let name = format!("{category} {size} {coverage} {output}");
            let rows = common::sweep(&g, out, &sigmas, 0xf1a0 ^ ci as u64, 12, 2048, common::centre_in_square);
            for r in &rows {
                println!("{}", common::sweep_line(&name, r));
                let (sigma, ef, ep, spread, sd) = (r.sigma, r.filtered, r.point, r.spread, r.node_sigma);
                if sigma <= 1e-6 && ef > 1e-4 {
                    failures.push(format!("{name} σ={sigma}: error {ef:.2e} at a tiny footprint"));
                }
                if ep > 0.01 && r.ratio() > 0.7 {
                    failures.push(format!("{name} σ={sigma}: error ratio {:.3} > 0.7", r.ratio()));
                }
                if sigma >= 3.0 * size && ef > 0.1 {
                    failures.push(format!("{name} σ={sigma}: error {ef:.2e} > 0.1 at a coarse footprint"));
                }
                if spread > 0.01 && !(0.5..=1.7).contains(&(sd / spread)) {
                    failures.push(format!("{name} σ={sigma}: spread {sd:.2e} against {spread:.2e}"));
                }
            }
            sweeps.push((name, rows));
        }
    }
    common::write_doc(
        "filtering/flake.md",
        &format!(
            "# `flake2d`, `flake3d` filtered against supersampling\n\n\
             Written by `crates/graph/tests/verify/flake.rs` (`filtered_matches_supersampling`); cells as in \
             `nodes.md` (12 centres, 2048 samples each; graphs named category, size, coverage, output). \
             Asserted: at σ ≤ 1e-6 the error is below 1e-4; where point sampling errs by more than 0.01 the \
             ratio is below 0.7; beyond three flake cells the error is below 0.1; the reported spread is \
             0.5–1.7× the true one where that exceeds 0.01.\n\n{}",
            common::sweep_markdown(&sweeps)
        ),
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Finite at every footprint, for extreme inputs.
#[test]
fn finite_for_every_footprint() {
    for (size, coverage) in [(1e-30f32, 0.5f32), (0.0, 1.0), (-0.3, 2.0), (1e30, 0.5), (0.01, -1.0)] {
        for category in ["flake2d", "flake3d"] {
            let g = flakes(category, size, coverage);
            let mut s = EvalScratch::new(&g);
            for name in ["id", "rand", "presence", "flakenormal"] {
                let out = g.output_id(&format!("g/{name}")).unwrap();
                for uv in [Vec2::new(0.3, 0.7), Vec2::new(-1e4, 3e3)] {
                    for sigma in [0.0f32, 1e-6, 1e-2, 10.0, 1e3] {
                        let fp = if sigma == 0.0 { Footprint::point(uv) } else { Footprint::isotropic(uv, sigma) };
                        let v = g.eval_output(out, &fp, &mut s);
                        for m in &v.ch[..v.ty.channels()] {
                            assert!(m.mean.is_finite() && m.grad.is_finite() && m.var.is_finite() && m.var >= 0.0);
                        }
                    }
                }
            }
        }
    }
}
