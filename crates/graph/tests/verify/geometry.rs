//! Geometry-dependent nodes: the default geometry (MaterialX's flat baking quad), surface
//! geometry carried by the footprint, 3D noises filtered against brute-force Gaussian
//! supersampling over a surface's uv footprint, `Graph::is_uv_only`, and load-time warnings
//! and errors.

// Channel loops index several per-channel arrays at once.
#![allow(clippy::needless_range_loop)]

use crate::common::Rng;
use glam::{Mat2, Vec2, Vec3};
use graph::{Document, EvalScratch, Footprint, Geometry, Graph, LoadOptions, OutputId};

fn graph_of(body: &str) -> Graph {
    let text =
        format!(r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">{body}</nodegraph></materialx>"#);
    Document::parse(&text, "test.mtlx".as_ref(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}")).into_graph()
}

fn eval(g: &Graph, name: &str, fp: &Footprint) -> graph::Filtered {
    g.eval_output(g.output_id(name).unwrap(), fp, &mut EvalScratch::new(g))
}

fn mean3(f: &graph::Filtered) -> Vec3 {
    Vec3::new(f.ch[0].mean, f.ch[1].mean, f.ch[2].mean)
}

const GEOMETRY_NODES: &str = r#"
  <position name="p" type="vector3"/>
  <position name="pw" type="vector3"><input name="space" type="string" value="world"/></position>
  <normal name="n" type="vector3"/>
  <tangent name="t" type="vector3"/>
  <bitangent name="b" type="vector3"/>
  <texcoord name="uv" type="vector2"/>
  <output name="p" type="vector3" nodename="p"/>
  <output name="pw" type="vector3" nodename="pw"/>
  <output name="n" type="vector3" nodename="n"/>
  <output name="t" type="vector3" nodename="t"/>
  <output name="b" type="vector3" nodename="b"/>
  <output name="uv" type="vector2" nodename="uv"/>
"#;

/// Without surface geometry, nodes see MaterialX's baking quad: position (2u − 1, 2v − 1, 0),
/// normal +z, tangent +x, bitangent +y; a uv footprint spreads the position by J Σ Jᵀ with
/// J = diag(2, 2).
#[test]
fn default_geometry_is_the_baking_quad() {
    let g = graph_of(GEOMETRY_NODES);
    let uv = Vec2::new(0.3, 0.85);
    let sigma = 0.01;
    let fp = Footprint::isotropic(uv, sigma);
    for name in ["g/p", "g/pw"] {
        let p = eval(&g, name, &fp);
        assert!((mean3(&p) - Vec3::new(-0.4, 0.7, 0.0)).length() < 1e-6, "{name}: {p:?}");
        assert!((p.ch[0].var - 4.0 * sigma * sigma).abs() < 1e-9 && (p.ch[1].var - 4.0 * sigma * sigma).abs() < 1e-9);
        assert_eq!(p.ch[2].var, 0.0);
        assert_eq!((p.ch[0].grad, p.ch[1].grad), (Vec2::new(2.0, 0.0), Vec2::new(0.0, 2.0)));
    }
    assert_eq!(mean3(&eval(&g, "g/n", &fp)), Vec3::Z);
    assert_eq!(mean3(&eval(&g, "g/t", &fp)), Vec3::X);
    assert_eq!(mean3(&eval(&g, "g/b", &fp)), Vec3::Y);
}

/// A surface's geometry at uv: an oblique plane with a non-orthogonal parametrisation.
fn plane(uv: Vec2) -> Geometry {
    let p0 = Vec3::new(0.3, -0.7, 2.1);
    let dpdu = Vec3::new(1.5, 0.3, 1.2) * 3.0;
    let dpdv = Vec3::new(-0.4, 1.1, 0.8) * 3.0;
    let n = dpdu.cross(dpdv).normalize();
    let t = (dpdu - n * n.dot(dpdu)).normalize();
    let b = n.cross(t);
    let dndu = Vec3::new(0.05, -0.02, 0.0);
    Geometry { p: p0 + dpdu * uv.x + dpdv * uv.y, n, t, b, dpdu, dpdv, dndu, dndv: Vec3::ZERO }
}

/// With surface geometry, `position` is the surface point and spreads with the surface's
/// Jacobian; `normal` spreads with ∂N/∂u, ∂N/∂v; uv-only nodes do not see the geometry.
#[test]
fn surface_geometry_reaches_the_nodes() {
    let g = graph_of(GEOMETRY_NODES);
    let uv = Vec2::new(0.4, 0.6);
    let geom = plane(uv);
    let cov = Mat2::from_cols(Vec2::new(4e-4, 1e-4), Vec2::new(1e-4, 9e-4));
    let fp = Footprint::with_geometry(uv, cov, geom);
    let p = eval(&g, "g/p", &fp);
    assert_eq!(mean3(&p), geom.p);
    for k in 0..3 {
        let grad = Vec2::new(geom.dpdu[k], geom.dpdv[k]);
        assert_eq!(p.ch[k].grad, grad);
        assert!((p.ch[k].var - grad.dot(cov * grad)).abs() < 1e-7);
    }
    let n = eval(&g, "g/n", &fp);
    assert!((mean3(&n) - geom.n).length() < 1e-7 && n.ch[0].grad == Vec2::new(0.05, 0.0));
    assert_eq!(mean3(&eval(&g, "g/t", &fp)), geom.t);
    assert_eq!(mean3(&eval(&g, "g/b", &fp)), geom.b);
    let t = eval(&g, "g/uv", &fp);
    assert_eq!((t.ch[0].mean, t.ch[1].mean), (uv.x, uv.y));
}

/// Mean absolute error of the filtered value against brute-force Gaussian supersampling over
/// the uv footprint (each sample a point on the linearised surface), and of point sampling.
fn errors(g: &Graph, out: OutputId, seed: u64, sigmas: &[f32], oblique: bool) -> Vec<(f32, f64, f64)> {
    let mut rng = Rng(seed);
    let mut scratch = EvalScratch::new(g);
    let n = g.output(out).ty.channels();
    let mut rows = Vec::new();
    for &sigma in sigmas {
        let (mut ef, mut ep) = (0.0, 0.0);
        let centres = 10;
        for _ in 0..centres {
            let uv = Vec2::new(rng.uniform() as f32 * 2.0 - 0.5, rng.uniform() as f32 * 2.0 - 0.5);
            let a = 0.3 + 0.7 * rng.uniform() as f32;
            let r = Mat2::from_angle(rng.uniform() as f32 * std::f32::consts::PI);
            let l = r * Mat2::from_diagonal(Vec2::new(sigma, a * sigma));
            let cov = l * l.transpose();
            let fp_at = |q: Vec2, c: Mat2| {
                if oblique {
                    Footprint::with_geometry(q, c, plane(q))
                } else {
                    Footprint::new(q, c)
                }
            };
            let f = g.eval_output(out, &fp_at(uv, cov), &mut scratch);
            let p = g.eval_output(out, &fp_at(uv, Mat2::ZERO), &mut scratch);
            let samples = 1024;
            let mut acc = [0.0f64; 4];
            for _ in 0..samples {
                let z = Vec2::new(rng.normal() as f32, rng.normal() as f32);
                let v = g.eval_output(out, &fp_at(uv + l * z, Mat2::ZERO), &mut scratch);
                for k in 0..n {
                    acc[k] += v.ch[k].mean as f64 / samples as f64;
                }
            }
            for k in 0..n {
                ef += (f.ch[k].mean as f64 - acc[k]).abs();
                ep += (p.ch[k].mean as f64 - acc[k]).abs();
            }
        }
        let d = (centres * n) as f64;
        rows.push((sigma, ef / d, ep / d));
    }
    rows
}

const NOISES: &[(&str, &str, &str, f64)] = &[
    (
        "noise3d",
        "float",
        r#"<noise3d name="n" type="float"><input name="position" type="vector3" nodename="s"/></noise3d>"#,
        0.3,
    ),
    (
        "noise3d vec3",
        "vector3",
        r#"<noise3d name="n" type="vector3"><input name="position" type="vector3" nodename="s"/></noise3d>"#,
        0.3,
    ),
    (
        "noise3d vec4",
        "vector4",
        r#"<noise3d name="n" type="vector4"><input name="position" type="vector3" nodename="s"/><input name="pivot" type="float" value="0.5"/></noise3d>"#,
        0.3,
    ),
    (
        "fractal3d",
        "float",
        r#"<fractal3d name="n" type="float"><input name="position" type="vector3" nodename="s"/><input name="octaves" type="integer" value="5"/></fractal3d>"#,
        0.35,
    ),
    (
        "fractal3d vec2",
        "vector2",
        r#"<fractal3d name="n" type="vector2"><input name="position" type="vector3" nodename="s"/><input name="octaves" type="integer" value="4"/></fractal3d>"#,
        0.35,
    ),
    (
        "cellnoise3d",
        "float",
        r#"<cellnoise3d name="n" type="float"><input name="position" type="vector3" nodename="s"/></cellnoise3d>"#,
        0.4,
    ),
    (
        "cellnoise3d vec3",
        "vector3",
        r#"<cellnoise3d name="n" type="vector3"><input name="position" type="vector3" nodename="s"/></cellnoise3d>"#,
        0.4,
    ),
    (
        "worleynoise3d",
        "float",
        r#"<worleynoise3d name="n" type="float"><input name="position" type="vector3" nodename="s"/><input name="jitter" type="float" value="0.8"/></worleynoise3d>"#,
        0.5,
    ),
    (
        "worleynoise3d v3 solid",
        "vector3",
        r#"<worleynoise3d name="n" type="vector3"><input name="position" type="vector3" nodename="s"/><input name="style" type="integer" value="1"/></worleynoise3d>"#,
        0.5,
    ),
    (
        "unified perlin",
        "float",
        r#"<unifiednoise3d name="n" type="float"><input name="position" type="vector3" nodename="s"/><input name="jitter" type="float" value="1.0001"/><input name="offset" type="vector3" value="0.3, 1.7, -0.2"/></unifiednoise3d>"#,
        0.3,
    ),
    (
        "unified cell",
        "float",
        r#"<unifiednoise3d name="n" type="float"><input name="position" type="vector3" nodename="s"/><input name="type" type="integer" value="1"/><input name="outmin" type="float" value="0.2"/></unifiednoise3d>"#,
        0.4,
    ),
    (
        "unified worley",
        "float",
        r#"<unifiednoise3d name="n" type="float"><input name="position" type="vector3" nodename="s"/><input name="type" type="integer" value="2"/></unifiednoise3d>"#,
        0.5,
    ),
    (
        "unified fractal",
        "float",
        r#"<unifiednoise3d name="n" type="float"><input name="position" type="vector3" nodename="s"/><input name="type" type="integer" value="3"/><input name="freq" type="vector3" value="1, 2, 1"/></unifiednoise3d>"#,
        0.5,
    ),
];

/// 3D noises filtered over the footprint of a surface point (the baking quad, where z is
/// constant, and an oblique plane, where the footprint spreads along all three axes): at tiny
/// footprints the unfiltered value, at coarse ones a small fraction of point sampling's error
/// against brute-force supersampling (the noise fades to its mean rather than aliasing).
#[test]
fn noise3d_filtered_matches_supersampling() {
    let sigmas = [1e-6f32, 1e-3, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0];
    let mut failures = Vec::new();
    println!("{:<24} {:>8} {:>8} {:>11} {:>11} {:>8}", "graph", "surface", "sigma", "filt err", "point err", "ratio");
    for (ci, (name, ty, node, ratio_bound)) in NOISES.iter().enumerate() {
        // The position scaled to a few lattice cells per uv unit.
        let body = format!(
            r#"<position name="p" type="vector3"/><multiply name="s" type="vector3"><input name="in1" type="vector3" nodename="p"/><input name="in2" type="vector3" value="3, 3, 3"/></multiply>{node}<output name="out" type="{ty}" nodename="n"/>"#
        );
        let g = graph_of(&body);
        let out = g.output_id("g/out").unwrap();
        for oblique in [false, true] {
            let surface = if oblique { "oblique" } else { "quad" };
            for (sigma, ef, ep) in errors(&g, out, 0x51ed ^ (ci as u64) << 8 ^ oblique as u64, &sigmas, oblique) {
                let ratio = ef / ep.max(1e-12);
                println!("{name:<24} {surface:>8} {sigma:>8.0e} {ef:>11.2e} {ep:>11.2e} {ratio:>8.3}");
                if sigma <= 1e-6 && ef > 2e-3 {
                    failures.push(format!("{name} {surface} σ={sigma}: filtered error {ef:.2e} at a tiny footprint"));
                }
                if sigma >= 0.1 && ep > 0.01 && ratio > *ratio_bound {
                    failures.push(format!("{name} {surface} σ={sigma}: error ratio {ratio:.3} > {ratio_bound}"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A single 3D noise under a footprint far larger than its lattice is its mean, with the
/// noise's whole variance as spread.
#[test]
fn noise3d_fades_to_its_mean() {
    let g = graph_of(
        r#"<noise3d name="n" type="float"><input name="pivot" type="float" value="0.25"/></noise3d><output name="out" type="float" nodename="n"/>
           <fractal3d name="f" type="float"><input name="octaves" type="integer" value="8"/></fractal3d><output name="f" type="float" nodename="f"/>
           <cellnoise3d name="c" type="float"/><output name="c" type="float" nodename="c"/>"#,
    );
    let fp = Footprint::isotropic(Vec2::new(0.3, 0.6), 50.0);
    let n = eval(&g, "g/out", &fp);
    assert!((n.ch[0].mean - 0.25).abs() < 1e-6 && n.ch[0].var > 0.05, "{n:?}");
    let f = eval(&g, "g/f", &fp);
    assert!(f.ch[0].mean.abs() < 1e-6 && f.ch[0].var > 0.05, "{f:?}");
    let c = eval(&g, "g/c", &fp);
    assert!((c.ch[0].mean - 0.5).abs() < 1e-6, "{c:?}");
    // Fine footprints do less work than none: octaves past the band limit are not evaluated.
    let mut s = EvalScratch::new(&g);
    g.eval_output(g.output_id("g/f").unwrap(), &Footprint::isotropic(Vec2::new(0.3, 0.6), 0.2), &mut s);
    assert!(s.work().octaves < 8, "{:?}", s.work());
}

/// `rotate3d` is MaterialX's: the transpose of the right-handed rotation (a rotation by
/// −amount), the same convention as `rotate2d` about z; filtered, it is exact (linear).
#[test]
fn rotate3d_matches_rotate2d_and_is_linear() {
    let g = graph_of(
        r#"<position name="p" type="vector3"/>
           <rotate3d name="r" type="vector3"><input name="in" type="vector3" nodename="p"/><input name="amount" type="float" value="33"/><input name="axis" type="vector3" value="0, 0, 2"/></rotate3d>
           <separate3 name="s" type="multioutput"><input name="in" type="vector3" nodename="p"/></separate3>
           <combine2 name="xy" type="vector2"><input name="in1" type="float" nodename="s" output="outx"/><input name="in2" type="float" nodename="s" output="outy"/></combine2>
           <rotate2d name="r2" type="vector2"><input name="in" type="vector2" nodename="xy"/><input name="amount" type="float" value="33"/></rotate2d>
           <rotate3d name="q" type="vector3"><input name="in" type="vector3" value="1, 0, 0"/><input name="amount" type="float" value="90"/><input name="axis" type="vector3" value="0, 0, 1"/></rotate3d>
           <rotate3d name="y" type="vector3"><input name="in" type="vector3" value="0, 0, 1"/><input name="amount" type="float" value="90"/></rotate3d>
           <output name="r" type="vector3" nodename="r"/><output name="r2" type="vector2" nodename="r2"/>
           <output name="q" type="vector3" nodename="q"/><output name="y" type="vector3" nodename="y"/>"#,
    );
    // The GLSL matrix applied to x about z: its first column, (cos, −sin, 0).
    assert!((mean3(&eval(&g, "g/q", &Footprint::point(Vec2::ZERO))) - Vec3::new(0.0, -1.0, 0.0)).length() < 1e-6);
    // About the default axis y: z goes to (sin, 0, cos) of −90°... i.e. (−1, 0, 0).
    assert!((mean3(&eval(&g, "g/y", &Footprint::point(Vec2::ZERO))) - Vec3::new(-1.0, 0.0, 0.0)).length() < 1e-6);
    let fp = Footprint::isotropic(Vec2::new(0.2, 0.7), 0.03);
    let (r, r2) = (eval(&g, "g/r", &fp), eval(&g, "g/r2", &fp));
    for k in 0..2 {
        assert!((r.ch[k].mean - r2.ch[k].mean).abs() < 1e-6);
        assert!((r.ch[k].var - r2.ch[k].var).abs() < 1e-7);
        assert!((r.ch[k].grad - r2.ch[k].grad).length() < 1e-6);
    }
    // Linear: the variance of a rotated surface point is gᵀΣg of its rotated gradient.
    let g0 = r.ch[0].grad;
    assert!((r.ch[0].var - 0.03f32.powi(2) * g0.length_squared()).abs() < 1e-7);
}

/// The transforms between object, model and world space are the identity in tessera (one
/// space); `transformnormal` normalises, as MaterialX does.
#[test]
fn transforms_between_spaces() {
    let g = graph_of(
        r#"<transformpoint name="tp" type="vector3"><input name="in" type="vector3" value="1, 2, 3"/><input name="fromspace" type="string" value="object"/><input name="tospace" type="string" value="world"/></transformpoint>
           <transformvector name="tv" type="vector3"><input name="in" type="vector3" value="-1, 0.5, 2"/><input name="fromspace" type="string" value="world"/><input name="tospace" type="string" value="model"/></transformvector>
           <transformnormal name="tn" type="vector3"><input name="in" type="vector3" value="0, 3, 4"/><input name="fromspace" type="string" value="object"/><input name="tospace" type="string" value="world"/></transformnormal>
           <output name="tp" type="vector3" nodename="tp"/><output name="tv" type="vector3" nodename="tv"/><output name="tn" type="vector3" nodename="tn"/>"#,
    );
    let fp = Footprint::point(Vec2::new(0.5, 0.5));
    assert_eq!(mean3(&eval(&g, "g/tp", &fp)), Vec3::new(1.0, 2.0, 3.0));
    assert_eq!(mean3(&eval(&g, "g/tv", &fp)), Vec3::new(-1.0, 0.5, 2.0));
    assert!((mean3(&eval(&g, "g/tn", &fp)) - Vec3::new(0.0, 0.6, 0.8)).length() < 1e-6);
}

/// A space tessera does not know is an error naming the file and line.
#[test]
fn unknown_space_is_an_error_with_its_line() {
    let text = "<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n  <nodegraph name=\"g\">\n    <position name=\"p\" type=\"vector3\">\n      <input name=\"space\" type=\"string\" value=\"camera\"/>\n    </position>\n    <output name=\"o\" type=\"vector3\" nodename=\"p\"/>\n  </nodegraph>\n</materialx>\n";
    let e = Document::parse(text, "spaces.mtlx".as_ref(), &LoadOptions::default()).unwrap_err().to_string();
    assert!(e.contains("spaces.mtlx:4") && e.contains("camera"), "{e}");
}

/// `geompropvalue` of a uv set is the texture coordinate; of position, the position; of an
/// unknown property, its default — with a warning naming the node. `texcoord` with another uv
/// set reads the only one, with a warning.
#[test]
fn geompropvalue_and_texcoord_sets() {
    let g = graph_of(
        r#"<geompropvalue name="st" type="vector2"><input name="geomprop" type="string" value="st"/></geompropvalue>
           <geompropvalue name="pp" type="vector3"><input name="geomprop" type="string" value="Pworld"/></geompropvalue>
           <geompropvalue name="dirt" type="float"><input name="geomprop" type="string" value="dirt_amount"/><input name="default" type="float" value="0.35"/></geompropvalue>
           <texcoord name="uv1" type="vector2"><input name="index" type="integer" value="1"/></texcoord>
           <output name="st" type="vector2" nodename="st"/><output name="pp" type="vector3" nodename="pp"/>
           <output name="dirt" type="float" nodename="dirt"/><output name="uv1" type="vector2" nodename="uv1"/>"#,
    );
    let fp = Footprint::isotropic(Vec2::new(0.25, 0.75), 0.01);
    for name in ["g/st", "g/uv1"] {
        let v = eval(&g, name, &fp);
        assert_eq!((v.ch[0].mean, v.ch[1].mean, v.ch[0].grad), (0.25, 0.75, Vec2::X), "{name}");
    }
    assert_eq!(mean3(&eval(&g, "g/pp", &fp)), Vec3::new(-0.5, 0.5, 0.0));
    assert_eq!(eval(&g, "g/dirt", &fp).ch[0].mean, 0.35);
    let w = g.warnings();
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(w.iter().any(|w| w.contains("g/dirt") && w.contains("dirt_amount")), "{w:?}");
    assert!(w.iter().any(|w| w.contains("g/uv1") && w.contains("uv set 1")), "{w:?}");
}

/// `is_uv_only` separates what depends on the shading point through uv alone from what reads
/// the surface: position, normal, tangent, bitangent, a 3D noise's default position, and
/// `geompropvalue` of anything but a uv set taint everything downstream.
#[test]
fn uv_only_flags() {
    let g = graph_of(
        r#"<texcoord name="uv" type="vector2"/>
           <noise2d name="n2" type="float"><input name="texcoord" type="vector2" nodename="uv"/></noise2d>
           <checkerboard name="ch" type="color3"/>
           <position name="p" type="vector3"/>
           <multiply name="ps" type="vector3"><input name="in1" type="vector3" nodename="p"/><input name="in2" type="float" value="4"/></multiply>
           <noise3d name="n3" type="float"><input name="position" type="vector3" nodename="ps"/></noise3d>
           <fractal3d name="f3" type="float"/>
           <normal name="nn" type="vector3"/>
           <dotproduct name="facing" type="float"><input name="in1" type="vector3" nodename="nn"/><input name="in2" type="vector3" value="0, 0, 1"/></dotproduct>
           <geompropvalue name="st" type="vector2"><input name="geomprop" type="string" value="UV0"/></geompropvalue>
           <noise2d name="nst" type="float"><input name="texcoord" type="vector2" nodename="st"/></noise2d>
           <geompropvalue name="other" type="float"><input name="geomprop" type="string" value="age"/></geompropvalue>
           <mix name="uvmix" type="color3"><input name="fg" type="color3" nodename="ch"/><input name="mix" type="float" nodename="n2"/></mix>
           <mix name="mixed" type="color3"><input name="fg" type="color3" nodename="uvmix"/><input name="mix" type="float" nodename="n3"/></mix>
           <ramp name="rp" type="color4"/>
           <output name="a" type="color3" nodename="mixed"/><output name="b" type="float" nodename="facing"/>"#,
    );
    let flag = |n: &str| g.is_uv_only(g.node_id(&format!("g/{n}")).unwrap());
    for n in ["uv", "n2", "ch", "uvmix", "st", "nst", "rp"] {
        assert!(flag(n), "{n} should be uv-only");
    }
    for n in ["p", "ps", "n3", "f3", "nn", "facing", "other", "mixed"] {
        assert!(!flag(n), "{n} reads geometry");
    }
}
