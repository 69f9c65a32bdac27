//! Coarse footprints are cheaper than fine ones: octaves and lattice visits per evaluation.

use glam::Vec2;
use graph::{Document, EvalScratch, Footprint, LoadOptions};

#[test]
fn coarse_footprints_do_less_work() {
    let text = r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">
      <texcoord name="t" type="vector2"/>
      <multiply name="s" type="vector2"><input name="in1" type="vector2" nodename="t"/><input name="in2" type="vector2" value="16, 16"/></multiply>
      <fractal2d name="f" type="float"><input name="texcoord" type="vector2" nodename="s"/><input name="octaves" type="integer" value="8"/></fractal2d>
      <cellnoise2d name="c" type="float"><input name="texcoord" type="vector2" nodename="s"/></cellnoise2d>
      <add name="a" type="float"><input name="in1" type="float" nodename="f"/><input name="in2" type="float" nodename="c"/></add>
      <output name="out" type="float" nodename="a"/></nodegraph></materialx>"#;
    let doc = Document::parse(text, "cost.mtlx".as_ref(), &LoadOptions::default()).unwrap();
    let g = doc.graph();
    let out = g.output_id("g/out").unwrap();
    let mut scratch = EvalScratch::new(g);
    let mut rows = Vec::new();
    println!("{:>8} {:>10} {:>10} {:>10}", "sigma", "octaves", "lattice", "ns/eval");
    for sigma in [0.0f32, 1e-4, 1e-3, 1e-2, 0.03, 0.1, 0.3, 1.0, 10.0] {
        scratch.reset_stats();
        let n = 2000;
        let t0 = std::time::Instant::now();
        for i in 0..n {
            let uv = Vec2::new(0.37 + i as f32 * 0.013, 0.11 + i as f32 * 0.007);
            std::hint::black_box(g.eval_output(out, &Footprint::isotropic(uv, sigma), &mut scratch));
        }
        let ns = t0.elapsed().as_nanos() as f64 / n as f64;
        let w = scratch.work();
        let (oct, lat) = (w.octaves as f64 / n as f64, w.lattice as f64 / n as f64);
        println!("{sigma:>8.0e} {oct:>10.2} {lat:>10.1} {ns:>10.0}");
        rows.push((sigma, oct, lat));
    }
    let fine = rows[0];
    let coarse = rows.last().unwrap();
    // The coarsest footprint evaluates one octave (found fully filtered) and no lattice cells.
    assert!(coarse.1 <= 1.0 && coarse.2 == 0.0, "{coarse:?}");
    // Octaves never increase with the footprint.
    for w in rows.windows(2) {
        assert!(w[1].1 <= w[0].1 + 1e-9, "octaves grew: {w:?}");
    }
    assert!(fine.1 == 8.0);
    // Per-node evaluation counts: each node once per evaluation.
    assert!(scratch.evaluations().iter().all(|&c| c == 2000));
}
