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

/// A `switch` over ten constants of distinct values, `which = 12 u − 1` (so every interval,
/// including the open-ended first and last, is crossed along u).
fn switch_doc(version: &str, n_inputs: usize, which_type: &str) -> Document {
    let ins: String = (1..=n_inputs)
        .map(|k| format!(r#"<input name="in{k}" type="float" value="{}"/>"#, (k * k) as f32 * 0.1))
        .collect();
    let which = if which_type == "integer" {
        // An integer `which` from a float: MaterialX's `floor` to integer.
        r#"<floor name="wi" type="integer"><input name="in" type="float" nodename="w"/></floor>
           <switch name="r" type="float">{INS}<input name="which" type="integer" nodename="wi"/></switch>"#
    } else {
        r#"<switch name="r" type="float">{INS}<input name="which" type="float" nodename="w"/></switch>"#
    };
    let text = format!(
        r#"<?xml version="1.0"?>
<materialx version="{version}">
  <nodegraph name="g">
    <texcoord name="t" type="vector2"/>
    <extract name="u" type="float"><input name="in" type="vector2" nodename="t"/><input name="index" type="integer" value="0"/></extract>
    <multiply name="m" type="float"><input name="in1" type="float" nodename="u"/><input name="in2" type="float" value="12"/></multiply>
    <subtract name="w" type="float"><input name="in1" type="float" nodename="m"/><input name="in2" type="float" value="1"/></subtract>
    {}
    <output name="out" type="float" nodename="r"/>
  </nodegraph>
</materialx>"#,
        which.replace("{INS}", &ins)
    );
    Document::parse(&text, "switch.mtlx".as_ref(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

/// The unfiltered switch as MaterialX 1.39.5 renders it (its `NG_switch`, and its own bakes):
/// input k (1-based) for `which < k` up to 10, 0 from 10 on; `count` inputs as written (1.38:
/// five, the five 1.39 added reading their default 0).
fn switch_pick(which: f64, count: usize) -> f64 {
    match (1..=10).find(|&k| which < k as f64) {
        Some(k) if k <= count => (k * k) as f64 * 0.1,
        _ => 0.0,
    }
}

#[test]
fn switch_picks_by_interval_and_filters_to_the_mixture() {
    for (version, count, which_type) in [("1.39", 10, "float"), ("1.39", 10, "integer"), ("1.38", 5, "float")] {
        let d = switch_doc(version, count, which_type);
        let g = d.graph();
        let out = g.output_id("g/out").expect("output");
        let mut scratch = EvalScratch::new(g);
        for i in 0..400 {
            let u = -0.1 + 1.2 * i as f32 / 399.0;
            let which = (u * 12.0 - 1.0) as f64;
            let which = if which_type == "integer" { which.floor() } else { which };
            let got = g.eval_output(out, &Footprint::point(Vec2::new(u, 0.5)), &mut scratch).ch[0].mean as f64;
            let want = switch_pick(which, count);
            assert!((got - want).abs() < 1e-6, "{version} {which_type} at u = {u}: {got} vs {want}");
        }
        if which_type == "integer" {
            // floor's filtered form is its own approximation; the float case checks the mixture.
            continue;
        }
        // Over a footprint: the Gaussian average of the picks (a fine quadrature over ±6σ).
        for (cx, sx) in [(0.3f32, 0.002f32), (0.25, 0.03), (0.5, 0.1), (0.9, 0.2), (0.04, 0.05)] {
            let fp = Footprint::new(Vec2::new(cx, 0.5), Mat2::from_diagonal(Vec2::new(sx * sx, 1e-4)));
            let f = g.eval_output(out, &fp, &mut scratch).ch[0];
            let n = 4001;
            let (mut e, mut e2, mut total) = (0.0, 0.0, 0.0);
            for j in 0..n {
                let z = -6.0 + 12.0 * j as f64 / (n - 1) as f64;
                let w = (-0.5 * z * z).exp();
                let u = cx as f64 + sx as f64 * z;
                let y = switch_pick(u * 12.0 - 1.0, count);
                e += w * y;
                e2 += w * y * y;
                total += w;
            }
            let (e, var) = (e / total, e2 / total - (e / total).powi(2));
            assert!(
                (f.mean as f64 - e).abs() < 2e-3 * (1.0 + e.abs()),
                "{version} at {cx} σ {sx}: mean {} vs {e}",
                f.mean
            );
            assert!(
                (f.var as f64 - var).abs() < 2e-3 * (1.0 + var),
                "{version} at {cx} σ {sx}: var {} vs {var}",
                f.var
            );
            // The uv gradient of the mean, against a central difference of the filtered mean.
            let h = 1e-3f32;
            let at = |c: f32, s: &mut EvalScratch| {
                let fp = Footprint::new(Vec2::new(c, 0.5), Mat2::from_diagonal(Vec2::new(sx * sx, 1e-4)));
                g.eval_output(out, &fp, s).ch[0].mean as f64
            };
            let fd = (at(cx + h, &mut scratch) - at(cx - h, &mut scratch)) / (2.0 * h as f64);
            assert!(
                (f.grad.x as f64 - fd).abs() < 1e-2 * (1.0 + fd.abs()),
                "{version} at {cx} σ {sx}: ∂u {} vs {fd}",
                f.grad.x
            );
        }
    }
}
