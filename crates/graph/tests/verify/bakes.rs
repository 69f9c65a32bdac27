//! Unfiltered evaluation against MaterialX 1.39.5's own GLSL bakes of `patterns.mtlx`.

use crate::common;
use graph::bake::{self, BakeSettings};
use graph::Document;

fn compare(pattern: &str) -> (f32, f32) {
    let dir = common::shared().join("refs/materialx");
    let doc = Document::load(dir.join("patterns.mtlx")).unwrap();
    let img = common::read_exr(&dir.join(format!("{pattern}.exr")));
    let r = img.channel("R").unwrap();
    // The bake `tessera bake` makes: point evaluation at texel centres, row 0 = v = 1.
    let settings = BakeSettings::new(img.width as u32, img.height as u32);
    let baked = bake::bake_element(&doc, &format!("NG_{pattern}/out"), &settings).unwrap();
    let (mut max_err, mut sum) = (0.0f32, 0.0f32);
    for j in 0..img.height {
        for i in 0..img.width {
            let v = baked.texel(i as u32, j as u32)[0].max(0.0);
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
