//! MaterialX's `ramp` node: unfiltered against MaterialX's own definition (its `NG_ramp` node
//! graph, transcribed node for node into library nodes), filtered against brute-force Gaussian
//! quadrature of the unfiltered ramp, and the filtered slope against finite differences.

// Channel loops index several per-channel arrays at once.
#![allow(clippy::needless_range_loop)]

use glam::{Mat2, Vec2};
use graph::{Document, EvalScratch, Footprint, Graph, LoadOptions, OutputId};
use std::fmt::Write as _;

/// A ramp configuration: type, interpolation, num_intervals, 10 positions, 10 colours.
#[derive(Clone)]
struct Config {
    kind: i32,
    interp: i32,
    count: i32,
    at: [f32; 10],
    color: [[f32; 4]; 10],
}

fn config(kind: i32, interp: i32, count: i32, used: &[f32]) -> Config {
    // Unused positions lie beyond the used ones (all distinct: MaterialX divides by the width).
    let mut at = [0.0f32; 10];
    for (k, a) in at.iter_mut().enumerate() {
        *a = used.get(k).copied().unwrap_or(1.5 + 0.1 * k as f32);
    }
    let color = std::array::from_fn(|k| {
        let t = k as f32;
        [(0.37 * t + 0.1).fract(), (0.61 * t + 0.3).fract(), (0.23 * t + 0.7).fract(), 1.0 - 0.05 * t]
    });
    Config { kind, interp, count, at, color }
}

fn c4(c: [f32; 4]) -> String {
    format!("{}, {}, {}, {}", c[0], c[1], c[2], c[3])
}

/// The document: our `ramp` (output `ours`) and MaterialX's `NG_ramp` for this configuration
/// written out with library nodes (output `reference`), the `switch`es resolved for the
/// configuration's `type` and `interpolation`.
fn document(c: &Config) -> Graph {
    let mut b = String::new();
    let _ = write!(b, r#"<ramp name="r" type="color4">"#);
    let _ = write!(b, r#"<input name="type" type="integer" value="{}"/>"#, c.kind);
    let _ = write!(b, r#"<input name="interpolation" type="integer" value="{}"/>"#, c.interp);
    let _ = write!(b, r#"<input name="num_intervals" type="integer" value="{}"/>"#, c.count);
    for k in 0..10 {
        let _ = write!(b, r#"<input name="interval{}" type="float" value="{}"/>"#, k + 1, c.at[k]);
        let _ = write!(b, r#"<input name="color{}" type="color4" value="{}"/>"#, k + 1, c4(c.color[k]));
    }
    b.push_str(r#"</ramp><output name="ours" type="color4" nodename="r"/>"#);
    // The ramp coordinate x.
    b.push_str(r#"<texcoord name="tc" type="vector2"/>"#);
    b.push_str(
        r#"<separate2 name="sep" type="multioutput"><input name="in" type="vector2" nodename="tc"/></separate2>"#,
    );
    b.push_str(
        r#"<subtract name="half" type="vector2"><input name="in1" type="vector2" nodename="tc"/><input name="in2" type="vector2" value="0.5, 0.5"/></subtract>
           <separate2 name="sh" type="multioutput"><input name="in" type="vector2" nodename="half"/></separate2>"#,
    );
    match c.kind {
        0 => b.push_str(r#"<dot name="x" type="float"><input name="in" type="float" nodename="sep" output="outx"/></dot>"#),
        1 => b.push_str(
            r#"<atan2 name="at" type="float"><input name="iny" type="float" nodename="sh" output="outx"/><input name="inx" type="float" nodename="sh" output="outy"/></atan2>
               <divide name="dv" type="float"><input name="in1" type="float" nodename="at"/><input name="in2" type="float" value="6.28319"/></divide>
               <add name="x" type="float"><input name="in1" type="float" nodename="dv"/><input name="in2" type="float" value="0.5"/></add>"#,
        ),
        2 => b.push_str(
            r#"<multiply name="cm" type="vector2"><input name="in1" type="vector2" nodename="half"/><input name="in2" type="vector2" value="1.414, 1.414"/></multiply>
               <magnitude name="x" type="float"><input name="in" type="vector2" nodename="cm"/></magnitude>"#,
        ),
        _ => b.push_str(
            r#"<absval name="ab" type="vector2"><input name="in" type="vector2" nodename="half"/></absval>
               <multiply name="ab2" type="vector2"><input name="in1" type="vector2" nodename="ab"/><input name="in2" type="vector2" value="2, 2"/></multiply>
               <separate2 name="s6" type="multioutput"><input name="in" type="vector2" nodename="ab"/></separate2>
               <separate2 name="s7" type="multioutput"><input name="in" type="vector2" nodename="ab2"/></separate2>
               <ifgreater name="x" type="float"><input name="value1" type="float" nodename="s6" output="outx"/><input name="value2" type="float" nodename="s6" output="outy"/><input name="in1" type="float" nodename="s7" output="outx"/><input name="in2" type="float" nodename="s7" output="outy"/></ifgreater>"#,
        ),
    }
    // NG_ramp_gradient, nine times; gradient 1's previous colour is color1.
    let mut prev = format!(r#"value="{}""#, c4(c.color[0]));
    for k in 1..=9 {
        let (lo, hi) = (c.at[k - 1], c.at[k]);
        let (c0, c1) = (c4(c.color[k - 1]), c4(c.color[k]));
        let _ = write!(
            b,
            r#"<clamp name="cl{k}" type="float"><input name="in" type="float" nodename="x"/><input name="low" type="float" value="{lo}"/><input name="high" type="float" value="{hi}"/></clamp>
               <remap name="rm{k}" type="float"><input name="in" type="float" nodename="cl{k}"/><input name="inlow" type="float" value="{lo}"/><input name="inhigh" type="float" value="{hi}"/><input name="outlow" type="float" value="0"/><input name="outhigh" type="float" value="1"/></remap>
               <smoothstep name="ss{k}" type="float"><input name="in" type="float" nodename="x"/><input name="low" type="float" value="{lo}"/><input name="high" type="float" value="{hi}"/></smoothstep>
               <mix name="mx{k}" type="color4"><input name="bg" type="color4" value="{c0}"/><input name="fg" type="color4" value="{c1}"/><input name="mix" type="float" nodename="{t}"/></mix>
               <ifgreater name="st{k}" type="color4"><input name="value1" type="float" value="{hi}"/><input name="value2" type="float" nodename="x"/><input name="in1" type="color4" value="{c0}"/><input name="in2" type="color4" value="{c1}"/></ifgreater>
               <ifgreater name="g3_{k}" type="color4"><input name="value1" type="float" nodename="x"/><input name="value2" type="float" value="{lo}"/><input name="in1" type="color4" nodename="{sel}"/><input name="in2" type="color4" {prev}/></ifgreater>
               <ifgreatereq name="g{k}" type="color4"><input name="value1" type="integer" value="{k}"/><input name="value2" type="integer" value="{n}"/><input name="in1" type="color4" {prev}/><input name="in2" type="color4" nodename="g3_{k}"/></ifgreatereq>"#,
            t = if c.interp == 0 { format!("rm{k}") } else { format!("ss{k}") },
            sel = if c.interp < 2 { format!("mx{k}") } else { format!("st{k}") },
            n = c.count,
        );
        prev = format!(r#"nodename="g{k}""#);
    }
    b.push_str(r#"<output name="reference" type="color4" nodename="g9"/>"#);
    let text =
        format!(r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">{b}</nodegraph></materialx>"#);
    Document::parse(&text, "ramp.mtlx".as_ref(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}")).into_graph()
}

fn configs() -> Vec<Config> {
    let mut v = Vec::new();
    for kind in 0..4 {
        for interp in 0..3 {
            v.push(config(kind, interp, 2, &[0.2, 0.8]));
            v.push(config(kind, interp, 5, &[0.0, 0.15, 0.4, 0.45, 0.9]));
            // Unsorted positions: later intervals override earlier ones where x passes them.
            v.push(config(kind, interp, 4, &[0.3, 0.7, 0.1, 0.5]));
        }
    }
    // Ten intervals, the most a ramp has.
    v.push(config(0, 1, 10, &[0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]));
    v.push(config(2, 0, 12, &[0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]));
    v
}

fn outputs(g: &Graph) -> (OutputId, OutputId) {
    (g.output_id("g/ours").unwrap(), g.output_id("g/reference").unwrap())
}

/// Unfiltered, the node equals MaterialX's node graph definition everywhere (uv inside and
/// outside the unit square).
#[test]
fn unfiltered_matches_materialx_definition() {
    for c in configs() {
        let g = document(&c);
        let (ours, reference) = outputs(&g);
        let mut s = EvalScratch::new(&g);
        for i in 0..97 {
            for j in 0..89 {
                let uv = Vec2::new(-0.3 + 1.6 * (i as f32 + 0.31) / 97.0, -0.25 + 1.5 * (j as f32 + 0.47) / 89.0);
                let fp = Footprint::point(uv);
                let a = g.eval_output(ours, &fp, &mut s);
                let b = g.eval_output(reference, &fp, &mut s);
                for k in 0..4 {
                    let (x, y) = (a.ch[k].mean, b.ch[k].mean);
                    assert!(
                        (x - y).abs() <= 1e-5,
                        "type {} interp {} n {} at {uv}: channel {k} ours {x}, MaterialX graph {y}",
                        c.kind,
                        c.interp,
                        c.count
                    );
                }
            }
        }
    }
}

/// Mean and variance of the unfiltered ramp of `u` over `u ~ N(m, σ²)` by midpoint quadrature.
fn quadrature(g: &Graph, out: OutputId, uv: Vec2, sigma: f32, s: &mut EvalScratch) -> ([f64; 4], [f64; 4]) {
    let n = 40_000;
    let (mut e, mut e2, mut wsum) = ([0.0f64; 4], [0.0f64; 4], 0.0f64);
    for i in 0..n {
        let z = -8.0 + 16.0 * (i as f64 + 0.5) / n as f64;
        let w = (-0.5 * z * z).exp();
        let v = g.eval_output(out, &Footprint::point(uv + Vec2::new((sigma as f64 * z) as f32, 0.0)), s);
        for k in 0..4 {
            let x = v.ch[k].mean as f64;
            e[k] += w * x;
            e2[k] += w * x * x;
        }
        wsum += w;
    }
    let mean = e.map(|x| x / wsum);
    let var = std::array::from_fn(|k| (e2[k] / wsum - mean[k] * mean[k]).max(0.0));
    (mean, var)
}

/// The standard (u) ramp filtered: exact moments of a piecewise polynomial of a Gaussian
/// coordinate, checked against quadrature of the unfiltered ramp, and its slope against finite
/// differences of the filtered mean.
#[test]
fn standard_ramp_filtered_against_quadrature() {
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for c in configs().into_iter().filter(|c| c.kind == 0) {
        let g = document(&c);
        let (ours, _) = outputs(&g);
        let mut s = EvalScratch::new(&g);
        for &sigma in &[1e-3f32, 0.01, 0.05, 0.2, 1.0] {
            for &u in &[-0.4f32, 0.013, 0.17, 0.41, 0.5, 0.77, 0.93, 1.3] {
                let uv = Vec2::new(u, 0.3);
                // Anisotropic with a v spread too: the standard ramp reads u alone.
                let cov = Mat2::from_cols(Vec2::new(sigma * sigma, 0.0), Vec2::new(0.0, 4.0 * sigma * sigma));
                let f = g.eval_output(ours, &Footprint::new(uv, cov), &mut s);
                let (mean, var) = quadrature(&g, ours, uv, sigma, &mut s);
                let h = 1e-2 * sigma;
                let fp = g.eval_output(ours, &Footprint::new(uv + Vec2::new(h, 0.0), cov), &mut s);
                let fm = g.eval_output(ours, &Footprint::new(uv - Vec2::new(h, 0.0), cov), &mut s);
                for k in 0..4 {
                    let em = (f.ch[k].mean as f64 - mean[k]).abs();
                    let ev = (f.ch[k].var as f64 - var[k]).abs();
                    assert!(
                        em < 2e-4 && ev < 2e-4,
                        "interp {} n {} σ {sigma} u {u} ch {k}: mean {} vs {}, var {} vs {}",
                        c.interp,
                        c.count,
                        f.ch[k].mean,
                        mean[k],
                        f.ch[k].var,
                        var[k]
                    );
                    let fd = (fp.ch[k].mean as f64 - fm.ch[k].mean as f64) / (2.0 * h as f64);
                    let eg = (f.ch[k].grad.x as f64 - fd).abs() / (1.0 + fd.abs());
                    assert!(eg < 2e-2, "interp {} σ {sigma} u {u} ch {k}: slope {} vs {fd}", c.interp, f.ch[k].grad.x);
                    assert!(f.ch[k].grad.y == 0.0);
                    worst = (worst.0.max(em), worst.1.max(ev), worst.2.max(eg));
                }
            }
        }
    }
    println!("worst: mean {:.2e}, variance {:.2e}, relative slope {:.2e}", worst.0, worst.1, worst.2);
}

/// A footprint far wider than the ramp sees it half below its first position and half beyond
/// its last: the mean of `color1` and the last colour.
#[test]
fn wide_standard_ramp_fades_to_its_ends() {
    let c = config(0, 1, 5, &[0.0, 0.15, 0.4, 0.45, 0.9]);
    let g = document(&c);
    let (ours, _) = outputs(&g);
    let f = g.eval_output(ours, &Footprint::isotropic(Vec2::new(0.5, 0.5), 1e4), &mut EvalScratch::new(&g));
    for k in 0..4 {
        let want = 0.5 * (c.color[0][k] + c.color[4][k]);
        assert!((f.ch[k].mean - want).abs() < 1e-3, "channel {k}: {} vs {want}", f.ch[k].mean);
    }
}

/// Radial, circular and box ramps read a nonlinear coordinate: propagated as a Gaussian from
/// its cubature mean and spread. Small footprints against 2D brute-force supersampling,
/// including one across the radial ramp's seam (where the angle wraps from 1 to 0).
#[test]
fn shaped_ramps_filtered_against_supersampling() {
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    for c in configs().into_iter().filter(|c| c.kind > 0) {
        let g = document(&c);
        let (ours, _) = outputs(&g);
        let mut s = EvalScratch::new(&g);
        // Points away from the centre (where the angle and the distance are not smooth) and
        // from the box's diagonals (where its coordinate has a ridge: a footprint across one
        // sees a skewed, not a Gaussian, coordinate); the first crosses the radial seam below
        // the centre.
        for &(uv, sigma) in &[
            (Vec2::new(0.5, 0.2), 0.01f32),
            (Vec2::new(0.8, 0.35), 0.004),
            (Vec2::new(0.1, 0.82), 0.008),
            (Vec2::new(0.65, 0.7), 0.003),
        ] {
            let f = g.eval_output(ours, &Footprint::isotropic(uv, sigma), &mut s);
            let n = 20_000;
            let mut acc = [0.0f64; 4];
            for _ in 0..n {
                let r = (-2.0 * next().max(1e-300).ln()).sqrt();
                let th = 2.0 * std::f64::consts::PI * next();
                let d = Vec2::new((r * th.cos()) as f32, (r * th.sin()) as f32) * sigma;
                let v = g.eval_output(ours, &Footprint::point(uv + d), &mut s);
                for k in 0..4 {
                    acc[k] += v.ch[k].mean as f64 / n as f64;
                }
            }
            for k in 0..4 {
                let e = (f.ch[k].mean as f64 - acc[k]).abs();
                assert!(
                    e < 0.03,
                    "type {} interp {} n {} at {uv} σ {sigma} ch {k}: filtered {} vs supersampled {}",
                    c.kind,
                    c.interp,
                    c.count,
                    f.ch[k].mean,
                    acc[k]
                );
            }
        }
    }
}

/// Evaluation at every footprint is finite, whatever the configuration.
#[test]
fn finite_everywhere() {
    for c in configs() {
        let g = document(&c);
        let (ours, _) = outputs(&g);
        let mut s = EvalScratch::new(&g);
        for &sigma in &[0.0f32, 1e-6, 1e-3, 0.1, 3.0, 1e3] {
            for &uv in &[Vec2::new(0.5, 0.5), Vec2::new(0.5, 0.2), Vec2::new(-3.0, 7.0), Vec2::new(0.2, 0.8)] {
                let f = g.eval_output(ours, &Footprint::isotropic(uv, sigma), &mut s);
                for m in &f.ch {
                    assert!(m.mean.is_finite() && m.var.is_finite() && m.grad.is_finite(), "{uv} σ {sigma}: {f:?}");
                }
            }
        }
    }
}
