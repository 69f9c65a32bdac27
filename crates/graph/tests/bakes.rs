//! Unfiltered evaluation against MaterialX 1.39.5's own GLSL bakes of `patterns.mtlx`.

mod common;

use glam::Vec2;
use graph::{Document, EvalScratch, Footprint};

fn compare(pattern: &str) -> (f32, f32) {
    let dir = common::shared().join("refs/materialx");
    let doc = Document::load(dir.join("patterns.mtlx")).unwrap();
    let g = doc.graph();
    let out = g.output_id(&format!("NG_{pattern}/out")).unwrap();
    let img = common::read_exr(&dir.join(format!("{pattern}.exr")));
    let r = img.channel("R").unwrap();
    let mut scratch = EvalScratch::new(g);
    let (mut max_err, mut sum) = (0.0f32, 0.0f32);
    for j in 0..img.height {
        for i in 0..img.width {
            let uv = Vec2::new((i as f32 + 0.5) / img.width as f32, 1.0 - (j as f32 + 0.5) / img.height as f32);
            let v = g.eval_output(out, &Footprint::point(uv), &mut scratch).ch[0].mean.max(0.0);
            let e = (v - r[j * img.width + i]).abs() / v.abs().max(0.05);
            max_err = max_err.max(e);
            sum += e;
        }
    }
    (max_err, sum / (img.width * img.height) as f32)
}

#[test]
fn patterns_match_materialx_bakes() {
    println!("pattern       max rel err   mean rel err");
    for p in ["uramp", "vramp", "noise2d", "cellnoise2d", "checkerboard"] {
        let (max, mean) = compare(p);
        println!("{p:<13} {max:>11.5} {mean:>14.6}");
        // RGBE quantisation: 8-bit mantissa, ≤ 2^-8 relative (1/256 of the exponent's range).
        assert!(max < 0.0081, "{p}: max relative error {max}");
    }
}
