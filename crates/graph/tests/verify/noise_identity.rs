//! Bit-identity harness for the noise nodes: every 2D and 3D noise node kind (`noise`, `fractal`,
//! `cellnoise`, `worleynoise`, `unifiednoise`), every output type, over a deterministic grid of
//! parameter sets, coordinate mappings and footprints (points, tiny to huge isotropic, anisotropic
//! and correlated, rank one; flat and oblique surfaces for the 3D nodes), plus the public
//! unfiltered functions. The raw f32 bits of every channel's moments are written or compared:
//!
//! ```text
//! NOISE_ID_WRITE=/tmp/noise.bits cargo test --release -p graph --test verify noise_identity -- --ignored
//! NOISE_ID_CHECK=/tmp/noise.bits cargo test --release -p graph --test verify noise_identity -- --ignored
//! ```
//!
//! Write the reference with the code before a change that claims not to alter behaviour, check
//! after it.

use glam::{Mat2, Vec2, Vec3};
use graph::{Document, EvalScratch, Footprint, Geometry, LoadOptions};

/// One graph: a label and its document.
struct Case {
    label: String,
    xml: String,
}

fn input(name: &str, ty: &str, value: &str) -> String {
    format!(r#"<input name="{name}" type="{ty}" value="{value}"/>"#)
}

/// The coordinate chains: 2D `texcoord · scale + offset`, 3D `position · scale + offset`.
const COORDS_2D: &[(&str, &str)] = &[("8, 8", "0, 0"), ("3.7, -11.3", "-20.5, 4.25"), ("1e7, 3", "1.6e7, 0.5")];
const COORDS_3D: &[(&str, &str)] =
    &[("4, 4, 4", "0, 0, 0"), ("3.7, -5.3, 2.9", "-20.5, 4.25, 0.75"), ("1e7, 3, 3", "1.6e7, 0.5, 0")];

/// Integer inputs driven by a node whose filtered mean is fractional (`convert` of a ramp).
const FRACTIONAL_OCTAVES: &str = "@frac";

fn document(dim: usize, category: &str, ty: &str, params: &[String], coord: (&str, &str)) -> String {
    let (vty, src, name) =
        if dim == 2 { ("vector2", "texcoord", "texcoord") } else { ("vector3", "position", "position") };
    let mut body = String::new();
    let mut extra = String::new();
    for p in params {
        if let Some(rest) = p.strip_prefix(FRACTIONAL_OCTAVES) {
            // `@frac:NAME`: NAME is an integer input fed by convert(extract(t, 0) · 3 + 1.3).
            let input_name = &rest[1..];
            extra.push_str(
                r#"<extract name="ex" type="float"><input name="in" type="VTY" nodename="t"/><input name="index" type="integer" value="0"/></extract>
<multiply name="exs" type="float"><input name="in1" type="float" nodename="ex"/><input name="in2" type="float" value="3"/></multiply>
<add name="exo" type="float"><input name="in1" type="float" nodename="exs"/><input name="in2" type="float" value="1.3"/></add>
<convert name="oc" type="integer"><input name="in" type="float" nodename="exo"/></convert>
"#,
            );
            body.push_str(&format!(r#"<input name="{input_name}" type="integer" nodename="oc"/>"#));
        } else if let Some(rest) = p.strip_prefix("@jx:") {
            // `@jx:NAME`: NAME is a float input fed by extract(t, 1) · 0.2 + 0.6 (not a constant).
            extra.push_str(
                r#"<extract name="jy" type="float"><input name="in" type="VTY" nodename="t"/><input name="index" type="integer" value="1"/></extract>
<multiply name="jys" type="float"><input name="in1" type="float" nodename="jy"/><input name="in2" type="float" value="0.2"/></multiply>
<add name="jyo" type="float"><input name="in1" type="float" nodename="jys"/><input name="in2" type="float" value="0.6"/></add>
"#,
            );
            body.push_str(&format!(r#"<input name="{rest}" type="float" nodename="jyo"/>"#));
        } else {
            body.push_str(p);
        }
    }
    let extra = extra.replace("VTY", vty);
    format!(
        r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">
<{src} name="t" type="{vty}"/>
<multiply name="s" type="{vty}"><input name="in1" type="{vty}" nodename="t"/><input name="in2" type="{vty}" value="{}"/></multiply>
<add name="c" type="{vty}"><input name="in1" type="{vty}" nodename="s"/><input name="in2" type="{vty}" value="{}"/></add>
{extra}<{category} name="x" type="{ty}"><input name="{name}" type="{vty}" nodename="c"/>{body}</{category}>
<output name="out" type="{ty}" nodename="x"/></nodegraph></materialx>"#,
        coord.0, coord.1
    )
}

/// Every graph of the harness, in a fixed order.
fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    for dim in [2, 3] {
        let coords = if dim == 2 { COORDS_2D } else { COORDS_3D };
        let vty = if dim == 2 { "vector2" } else { "vector3" };
        let cat = |c: &str| format!("{c}{dim}d");
        let mut kinds: Vec<(String, &str, Vec<String>)> = Vec::new();
        // noise
        for ty in ["float", "vector2", "vector3", "vector4", "color3"] {
            kinds.push((cat("noise"), ty, vec![]));
            kinds.push((cat("noise"), ty, vec![input("amplitude", "float", "0.7"), input("pivot", "float", "0.25")]));
            let amp = match ty {
                "float" => "-1.5",
                "vector2" => "0.5, -2",
                "vector4" => "0.5, 1.5, -2, 3",
                _ => "0.5, 1.5, -2",
            };
            kinds.push((cat("noise"), ty, vec![input("amplitude", ty, amp)]));
        }
        // fractal
        let fractal_sets: Vec<Vec<String>> = vec![
            vec![],
            vec![input("octaves", "integer", "1")],
            vec![
                input("octaves", "integer", "6"),
                input("lacunarity", "float", "2.1"),
                input("diminish", "float", "0.6"),
                input("amplitude", "float", "0.6"),
            ],
            vec![
                input("octaves", "integer", "10"),
                input("lacunarity", "float", "1.7"),
                input("diminish", "float", "0.8"),
            ],
            vec![
                input("octaves", "integer", "4"),
                input("lacunarity", "float", "-2.3"),
                input("diminish", "float", "1.25"),
            ],
            vec![input("octaves", "integer", "0")],
            vec![
                input("octaves", "integer", "64"),
                input("lacunarity", "float", "3"),
                input("diminish", "float", "0.9"),
            ],
            vec![format!("{FRACTIONAL_OCTAVES}:octaves"), input("diminish", "float", "0.7")],
        ];
        for ty in ["float", "vector2", "vector3", "vector4"] {
            for set in &fractal_sets {
                kinds.push((cat("fractal"), ty, set.clone()));
            }
        }
        // cell
        for ty in ["float", "vector3"] {
            kinds.push((cat("cellnoise"), ty, vec![]));
        }
        // Worley
        for ty in ["float", "vector2", "vector3"] {
            for jitter in ["1", "0.5", "0", "1.4"] {
                for style in ["0", "1"] {
                    kinds.push((
                        cat("worleynoise"),
                        ty,
                        vec![input("jitter", "float", jitter), input("style", "integer", style)],
                    ));
                }
            }
            kinds.push((cat("worleynoise"), ty, vec!["@jx:jitter".to_string()]));
        }
        // unified
        let (freq, off) = if dim == 2 { ("2.5, 1.5", "3, -1") } else { ("2.5, 1.5, 0.75", "3, -1, 2") };
        let unified_sets: Vec<Vec<String>> = vec![
            vec![],
            vec![input("jitter", "float", "0.8")],
            vec![
                input("freq", vty, freq),
                input("offset", vty, off),
                input("outmin", "float", "-0.5"),
                input("outmax", "float", "2"),
                input("clampoutput", "boolean", "false"),
            ],
            vec![
                input("octaves", "integer", "5"),
                input("lacunarity", "float", "1.9"),
                input("diminish", "float", "0.7"),
                input("jitter", "float", "1.00001"),
            ],
            vec![input("style", "integer", "1"), input("jitter", "float", "0.6")],
            vec![format!("{FRACTIONAL_OCTAVES}:octaves"), "@jx:jitter".to_string()],
        ];
        for kind in ["0", "1", "2", "3", "4"] {
            for set in &unified_sets {
                let mut set = set.clone();
                set.push(input("type", "integer", kind));
                kinds.push((cat("unifiednoise"), "float", set));
            }
        }
        for (ci, &coord) in coords.iter().enumerate() {
            for (k, (category, ty, params)) in kinds.iter().enumerate() {
                // The precision-limit mapping for a few cases of each kind only.
                if ci == 2 && k % 3 != 0 {
                    continue;
                }
                out.push(Case {
                    label: format!("{category}/{ty} coord {ci} params {params:?}"),
                    xml: document(dim, category, ty, params, coord),
                });
            }
        }
    }
    out
}

/// An oblique surface through space: every position channel spreads, and the channels correlate.
fn oblique(uv: Vec2) -> Geometry {
    let dpdu = Vec3::new(1.7, 0.9, 1.1);
    let dpdv = Vec3::new(0.4, 1.9, -0.7);
    let n = dpdu.cross(dpdv).normalize();
    let t = dpdu.normalize();
    Geometry {
        p: Vec3::new(0.3, -0.8, 2.1) + dpdu * uv.x + dpdv * uv.y,
        n,
        t,
        b: n.cross(t),
        dpdu,
        dpdv,
        dndu: Vec3::ZERO,
        dndv: Vec3::ZERO,
    }
}

/// The footprints: centres on a grid, each with every covariance; for 3D graphs, on the flat
/// baking quad (a plane z = const, one thin axis) and on an oblique surface.
fn footprints(dim: usize) -> Vec<Footprint> {
    let covs = [
        Mat2::ZERO,
        Mat2::from_diagonal(Vec2::splat(1e-12)),
        Mat2::from_diagonal(Vec2::splat(1e-8)),
        Mat2::from_diagonal(Vec2::splat(1e-5)),
        Mat2::from_diagonal(Vec2::splat(1e-4)),
        Mat2::from_diagonal(Vec2::splat(1e-3)),
        Mat2::from_diagonal(Vec2::splat(1e-2)),
        Mat2::from_diagonal(Vec2::splat(0.25)),
        Mat2::from_diagonal(Vec2::splat(100.0)),
        Mat2::from_cols(Vec2::new(4e-4, 3e-4), Vec2::new(3e-4, 9e-4)),
        Mat2::from_cols(Vec2::new(2e-5, -1e-5), Vec2::new(-1e-5, 3e-3)),
        Mat2::from_diagonal(Vec2::new(1e-3, 0.0)),
        Mat2::from_diagonal(Vec2::new(0.0, 4e-2)),
    ];
    let mut out = Vec::new();
    for i in 0..5 {
        for j in 0..5 {
            let uv = Vec2::new(-0.31 + 0.337 * i as f32, -0.17 + 0.291 * j as f32);
            for cov in covs {
                out.push(Footprint::new(uv, cov));
                if dim == 3 {
                    out.push(Footprint::with_geometry(uv, cov, oblique(uv)));
                }
            }
        }
    }
    out
}

/// Appends the bits of `x`.
fn put(bits: &mut Vec<u8>, x: f32) {
    bits.extend_from_slice(&x.to_bits().to_le_bytes());
}

/// The public unfiltered functions over a grid (one record of 4 values per point).
fn point_functions(bits: &mut Vec<u8>, labels: &mut Vec<String>) {
    for i in 0..40 {
        for j in 0..40 {
            let p = Vec2::new(-13.7 + 0.6173 * i as f32, 5.3 - 0.5791 * j as f32);
            let p3 = Vec3::new(p.x, p.y, 0.77 + 0.131 * (i + j) as f32);
            let w = graph::worley_point(p, 0.8, (i % 2) as i32, 1 + (j % 3));
            let w3 = graph::worley3_point(p3, 0.8, (j % 2) as i32, 1 + (i % 3));
            let vals = [
                graph::perlin_float(p),
                graph::fractal_point(p, 5, 2.0, 0.5),
                graph::fractal_point(p, 3, -1.7, 0.8),
                graph::perlin3(p3),
                graph::fractal3_point(p3, 5, 2.0, 0.5),
                graph::fractal3_point(p3, 3, 1.9, 0.7),
                w[0],
                w[1],
                w[2],
                w3[0],
                w3[1],
                w3[2],
            ];
            for v in vals.chunks(4) {
                for &x in v {
                    put(bits, x);
                }
                labels.push(format!("point functions at {p} / {p3}"));
            }
        }
    }
}

/// Every record: 16 f32 (per channel: mean, ∂/∂u, ∂/∂v, variance) per evaluation, and its label.
fn records() -> (Vec<u8>, Vec<String>) {
    let (mut bits, mut labels) = (Vec::new(), Vec::new());
    point_functions(&mut bits, &mut labels);
    let fps = [footprints(2), footprints(3)];
    for case in cases() {
        let doc = Document::parse(&case.xml, "noise_identity.mtlx".as_ref(), &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{}: {e}\n{}", case.label, case.xml));
        let g = doc.graph();
        let out = g.output_id("out").or_else(|| g.output_id("g/out")).expect("output");
        let mut scratch = EvalScratch::new(g);
        let dim = if case.label.contains("3d/") { 1 } else { 0 };
        for (f, fp) in fps[dim].iter().enumerate() {
            let v = g.eval_output(out, fp, &mut scratch);
            for m in &v.ch {
                for x in [m.mean, m.grad.x, m.grad.y, m.var] {
                    put(&mut bits, x);
                }
            }
            labels.push(format!("{} footprint {f} {:?} cov {:?}", case.label, fp.uv, fp.cov));
        }
    }
    (bits, labels)
}

#[test]
#[ignore = "driven by NOISE_ID_WRITE / NOISE_ID_CHECK"]
fn noise_identity() {
    let (bits, labels) = records();
    println!("{} records, {} bytes", labels.len(), bits.len());
    if let Ok(path) = std::env::var("NOISE_ID_WRITE") {
        std::fs::write(&path, &bits).unwrap_or_else(|e| panic!("{path}: {e}"));
        println!("wrote {path}");
    }
    if let Ok(path) = std::env::var("NOISE_ID_CHECK") {
        let reference = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
        assert_eq!(reference.len(), bits.len(), "record count differs from {path}");
        let floats = |b: &[u8]| -> Vec<f32> {
            b.chunks(4).map(|c| f32::from_bits(u32::from_le_bytes([c[0], c[1], c[2], c[3]]))).collect()
        };
        // Records are 16 values, except the point functions' (4).
        let mut offset = 0;
        let mut differ = 0;
        for (k, label) in labels.iter().enumerate() {
            let len = if label.starts_with("point functions") { 16 } else { 64 };
            if bits[offset..offset + len] != reference[offset..offset + len] {
                if differ < 20 {
                    let (a, b) = (floats(&reference[offset..offset + len]), floats(&bits[offset..offset + len]));
                    println!("record {k} differs: {label}\n  reference {a:?}\n  now       {b:?}");
                }
                differ += 1;
            }
            offset += len;
        }
        assert_eq!(differ, 0, "{differ} of {} records differ from {path}", labels.len());
        println!("all {} records identical to {path}", labels.len());
    }
}
