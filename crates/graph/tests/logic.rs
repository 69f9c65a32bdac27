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
            // Brute force: a 64×64 grid of Gaussian quantiles per axis.
            let n = 64;
            let q: Vec<f64> = (0..n).map(|i| inv_normal((i as f64 + 0.5) / n as f64)).collect();
            let mut hits = 0.0;
            for &a in &q {
                for &b in &q {
                    let (u, v) = (cx as f64 + sx as f64 * a, cy as f64 + sy as f64 * b);
                    hits += f64::from(u8::from(truth(op, u > 0.5, v > 0.3)));
                }
            }
            let want = hits / (n * n) as f64;
            assert!((got - want).abs() < 0.02, "{op} at {cx},{cy} σ {sx},{sy}: {got} vs {want}");
        }
    }
}

/// The standard normal quantile (Acklam's rational approximation, |error| < 1.2e-9).
fn inv_normal(p: f64) -> f64 {
    let a = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383577518672690e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    let b =
        [-5.447609879822406e1, 1.615858368580409e2, -1.556989798598866e2, 6.680131188771972e1, -1.328068155288572e1];
    let c = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    let d = [7.784695709041462e-3, 3.224671290700398e-1, 2.445134137142996, 3.754408661907416];
    let pl = 0.02425;
    if p < pl {
        let q = (-2.0 * p.ln()).sqrt();
        (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5])
            / ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0)
    } else if p > 1.0 - pl {
        -inv_normal(1.0 - p)
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q
            / (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0)
    }
}
