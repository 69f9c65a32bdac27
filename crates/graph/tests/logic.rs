//! `and`, `or`, `xor`, `not`: at points, the truth tables; over a footprint, the probability
//! that the result is true, against brute-force supersampling. The operands are thresholds of u
//! and of v, independent under an axis-aligned Gaussian footprint, where the model's
//! independence assumption is exact.

use glam::{Mat2, Vec2};
use graph::{Document, EvalScratch, Footprint, LoadOptions};

fn doc(op: &str) -> Document {
    let body = if op == "not" {
        r#"<not name="r" type="boolean"><input name="in" type="boolean" nodename="a"/></not>"#.to_string()
    } else {
        format!(
            r#"<{op} name="r" type="boolean"><input name="in1" type="boolean" nodename="a"/><input name="in2" type="boolean" nodename="b"/></{op}>"#
        )
    };
    let text = format!(
        r#"<?xml version="1.0"?>
<materialx version="1.39">
  <nodegraph name="g">
    <texcoord name="t" type="vector2"/>
    <separate2 name="s" type="multioutput"><input name="in" type="vector2" nodename="t"/></separate2>
    <ifgreater name="a" type="boolean"><input name="value1" type="float" nodename="s" output="outx"/><input name="value2" type="float" value="0.5"/></ifgreater>
    <ifgreater name="b" type="boolean"><input name="value1" type="float" nodename="s" output="outy"/><input name="value2" type="float" value="0.3"/></ifgreater>
    {body}
    <ifgreater name="f" type="float"><input name="value1" type="boolean" nodename="r"/><input name="value2" type="boolean" value="false"/><input name="in1" type="float" value="1"/><input name="in2" type="float" value="0"/></ifgreater>
    <output name="out" type="boolean" nodename="r"/>
  </nodegraph>
</materialx>"#
    );
    Document::parse(&text, "logic.mtlx".as_ref(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{op}: {e}"))
}

fn truth(op: &str, a: bool, b: bool) -> bool {
    match op {
        "and" => a && b,
        "or" => a || b,
        "xor" => a != b,
        _ => !a,
    }
}

#[test]
fn logic_nodes_match_truth_tables_and_supersampling() {
    for op in ["and", "or", "xor", "not"] {
        let d = doc(op);
        let g = d.graph();
        let out = g.output_id("g/out").or_else(|| g.output_id("out")).expect("output");
        let mut scratch = EvalScratch::new(g);
        for (u, v) in [(0.2f32, 0.1f32), (0.7, 0.1), (0.2, 0.6), (0.8, 0.9)] {
            let got = g.eval_output(out, &Footprint::point(Vec2::new(u, v)), &mut scratch).ch[0].mean;
            let want = truth(op, u > 0.5, v > 0.3);
            assert_eq!(got, if want { 1.0 } else { 0.0 }, "{op} at ({u}, {v})");
        }
        for (cx, cy, sx, sy) in [(0.48f32, 0.33f32, 0.05f32, 0.04f32), (0.55, 0.25, 0.2, 0.1), (0.5, 0.3, 0.01, 0.3)] {
            let fp = Footprint::new(Vec2::new(cx, cy), Mat2::from_diagonal(Vec2::new(sx * sx, sy * sy)));
            let got = g.eval_output(out, &fp, &mut scratch).ch[0].mean as f64;
            // Brute force: a 201×201 grid over ±5σ per axis with Gaussian weights.
            let n = 201;
            let t: Vec<(f64, f64)> = (0..n)
                .map(|i| {
                    let x = -5.0 + 10.0 * i as f64 / (n - 1) as f64;
                    (x, (-0.5 * x * x).exp())
                })
                .collect();
            let (mut hits, mut total) = (0.0, 0.0);
            for &(a, wa) in &t {
                for &(b, wb) in &t {
                    let (u, v) = (cx as f64 + sx as f64 * a, cy as f64 + sy as f64 * b);
                    hits += wa * wb * f64::from(u8::from(truth(op, u > 0.5, v > 0.3)));
                    total += wa * wb;
                }
            }
            let want = hits / total;
            assert!((got - want).abs() < 0.02, "{op} at {cx},{cy} σ {sx},{sy}: {got} vs {want}");
        }
    }
}
