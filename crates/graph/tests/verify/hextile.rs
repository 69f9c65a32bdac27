//! `hextiledimage`: unfiltered values against a separate transcription of MaterialX's GLSL
//! (`mx_hextiledimage.glsl`, `lib/mx_hextile.glsl`) in f64; the degenerate case that is
//! `tiledimage`; filtered values against brute-force Gaussian supersampling; cost; load errors.
//!
//! The reference below is written from the shader source, not from the node's code: GLSL's
//! column-major `mat2` and `v * M` / `M * v` products are spelled out, and so are `fract`,
//! `step`, `mix`. Everything is f64 except the per-tile hash, which MaterialX defines by `f32`
//! arithmetic (its `fract` of products near 10⁴ keeps ~3 decimals in f32; an f64 hash would
//! be a different random pattern).

use crate::common::{self, Rng};
use glam::{Mat2, Vec2};
use graph::{Document, EvalScratch, Footprint, Graph, LoadErrorKind, LoadOptions};
use std::path::{Path, PathBuf};

const W: u32 = 32;
const H: u32 = 24;

/// The test texture's texels (file rows, row 0 = top), RGBA 8-bit: smooth ramps, 4-texel
/// checks and texel noise, so that luminance varies at every scale.
fn texels() -> Vec<[u8; 4]> {
    let mut rng = Rng(0x0bad_5eed);
    let mut px = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let n = rng.uniform();
            let r = 0.7 * x as f64 / (W - 1) as f64 + 0.3 * n;
            let g = 0.5 * y as f64 / (H - 1) as f64 + 0.4 * (((x / 4 + y / 4) % 2) as f64);
            let b = 0.2 + 0.8 * rng.uniform() * n;
            let a = 0.3 + 0.7 * ((x as f64 * 0.4).sin() * 0.5 + 0.5);
            px.push([r, g, b, a].map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8));
        }
    }
    px
}

/// The texture as an RGBA PNG, written once.
fn test_png() -> PathBuf {
    static PATH: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    PATH.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("graph-hextile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("hex.png");
        let px = texels();
        let img = image::RgbaImage::from_fn(W, H, |x, y| image::Rgba(px[(y * W + x) as usize]));
        img.save(&path).unwrap();
        path
    })
    .clone()
}

/// A tangent-space normal map: the test texture's red and green (x, y), blue (z) in [0.6, 1],
/// so that every texel is a normal above the surface (`2b − 1 ≥ 0.2`).
fn normal_texels() -> Vec<[u8; 4]> {
    texels().into_iter().map(|[r, g, b, _]| [r, g, 153 + (b as u32 * 102 / 255) as u8, 255]).collect()
}

/// [`normal_texels`] as an RGB PNG, written once.
fn normal_png() -> PathBuf {
    static PATH: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    PATH.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("graph-hextile-n-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("normal.png");
        let px = normal_texels();
        let img = image::RgbImage::from_fn(W, H, |x, y| {
            let p = px[(y * W + x) as usize];
            image::Rgb([p[0], p[1], p[2]])
        });
        img.save(&path).unwrap();
        path
    })
    .clone()
}

fn graph_of(body: &str) -> Graph {
    let text =
        format!(r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">{body}</nodegraph></materialx>"#);
    Document::parse(&text, "test.mtlx".as_ref(), &LoadOptions::default()).unwrap().into_graph()
}

// ---------------------------------------------------------------------------------------------
// Reference: MaterialX's GLSL, transcribed.

/// GLSL `mat2(a, b, c, d)`: columns (a, b) and (c, d).
#[derive(Clone, Copy)]
struct Mat2x2 {
    c0: [f64; 2],
    c1: [f64; 2],
}

fn mat2(a: f64, b: f64, c: f64, d: f64) -> Mat2x2 {
    Mat2x2 { c0: [a, b], c1: [c, d] }
}

/// GLSL `M * v`.
fn m_mul_v(m: Mat2x2, v: [f64; 2]) -> [f64; 2] {
    [m.c0[0] * v[0] + m.c1[0] * v[1], m.c0[1] * v[0] + m.c1[1] * v[1]]
}

/// GLSL `v * M`: the dot products of `v` with the columns.
fn v_mul_m(v: [f64; 2], m: Mat2x2) -> [f64; 2] {
    [v[0] * m.c0[0] + v[1] * m.c0[1], v[0] * m.c1[0] + v[1] * m.c1[1]]
}

fn fract(x: f64) -> f64 {
    x - x.floor()
}

fn mix(a: f64, b: f64, t: f64) -> f64 {
    a * (1.0 - t) + b * t
}

/// `mx_hextile_hash(vec2(id) + vec2(0.12345))` in f32.
fn hash_f32(id: [i64; 2]) -> [f64; 2] {
    let fr = |x: f32| x - x.floor();
    let p = [id[0] as f32 + 0.12345f32, id[1] as f32 + 0.12345f32];
    let mut p3 = [fr(p[0] * 0.1031), fr(p[1] * 0.1030), fr(p[0] * 0.0973)];
    let yzx = [p3[1] + 33.33, p3[2] + 33.33, p3[0] + 33.33];
    let dot = p3[0] * yzx[0] + p3[1] * yzx[1] + p3[2] * yzx[2];
    for c in p3.iter_mut() {
        *c += dot;
    }
    [fr((p3[0] + p3[1]) * p3[2]) as f64, fr((p3[0] + p3[2]) * p3[1]) as f64]
}

/// `mx_schlick_gain`.
fn schlick_gain(x: f64, r: f64) -> f64 {
    let rr = r.clamp(0.001, 0.999);
    let a = (1.0 / rr - 2.0) * (1.0 - 2.0 * x);
    if x < 0.5 {
        x / (a + 1.0)
    } else {
        (a - x) / (a - 1.0)
    }
}

#[derive(Clone, Copy, Debug)]
struct Params {
    tiling: [f64; 2],
    rotation: f64,
    rotationrange: [f64; 2],
    scale: f64,
    scalerange: [f64; 2],
    offset: f64,
    offsetrange: [f64; 2],
    falloff: f64,
    falloffcontrast: f64,
    lumacoeffs: [f64; 3],
}

/// The nodedef defaults (`stdlib_defs.mtlx`).
const DEFAULTS: Params = Params {
    tiling: [1.0, 1.0],
    rotation: 1.0,
    rotationrange: [0.0, 360.0],
    scale: 1.0,
    scalerange: [0.5, 2.0],
    offset: 1.0,
    offsetrange: [0.0, 1.0],
    falloff: 0.5,
    falloffcontrast: 0.5,
    lumacoeffs: [0.2722287, 0.6740818, 0.0536895],
};

impl Params {
    /// The node's inputs that differ from the defaults, as MaterialX XML.
    fn xml(&self) -> String {
        let v2 = |n: &str, v: [f64; 2], d: [f64; 2]| {
            if v == d {
                String::new()
            } else {
                format!(r#"<input name="{n}" type="vector2" value="{}, {}"/>"#, v[0], v[1])
            }
        };
        let f = |n: &str, v: f64, d: f64| {
            if v == d {
                String::new()
            } else {
                format!(r#"<input name="{n}" type="float" value="{v}"/>"#)
            }
        };
        let d = DEFAULTS;
        let mut s = String::new();
        s += &v2("tiling", self.tiling, d.tiling);
        s += &f("rotation", self.rotation, d.rotation);
        s += &v2("rotationrange", self.rotationrange, d.rotationrange);
        s += &f("scale", self.scale, d.scale);
        s += &v2("scalerange", self.scalerange, d.scalerange);
        s += &f("offset", self.offset, d.offset);
        s += &v2("offsetrange", self.offsetrange, d.offsetrange);
        s += &f("falloff", self.falloff, d.falloff);
        s += &f("falloffcontrast", self.falloffcontrast, d.falloffcontrast);
        if self.lumacoeffs != d.lumacoeffs {
            let l = self.lumacoeffs;
            s += &format!(r#"<input name="lumacoeffs" type="color3" value="{}, {}, {}"/>"#, l[0], l[1], l[2]);
        }
        s
    }
}

/// The texture as MaterialX samples it: linear values, `v = 0` the bottom row, periodic,
/// bilinear between texel centres.
struct RefTexture {
    px: Vec<[f64; 4]>,
}

impl RefTexture {
    /// The normal-map test texture ([`normal_texels`]), linear.
    fn normal_map() -> RefTexture {
        RefTexture { px: normal_texels().iter().map(|p| p.map(|x| x as f64 / 255.0)).collect() }
    }

    fn new(srgb: bool) -> RefTexture {
        let decode = |c: f64| if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) };
        let px = texels()
            .iter()
            .map(|p| {
                let mut c = p.map(|x| x as f64 / 255.0);
                if srgb {
                    for x in c.iter_mut().take(3) {
                        *x = decode(*x);
                    }
                }
                c
            })
            .collect();
        RefTexture { px }
    }

    /// Texel (i, j), j counted from the bottom row, wrapped.
    fn texel(&self, i: i64, j: i64) -> [f64; 4] {
        let (w, h) = (W as i64, H as i64);
        let (i, j) = (i.rem_euclid(w), j.rem_euclid(h));
        self.px[((h - 1 - j) * w + i) as usize]
    }

    fn sample(&self, uv: [f64; 2]) -> [f64; 4] {
        let x = uv[0] * W as f64 - 0.5;
        let y = uv[1] * H as f64 - 0.5;
        let (i, j) = (x.floor() as i64, y.floor() as i64);
        let (fx, fy) = (x - x.floor(), y - y.floor());
        let mut out = [0.0; 4];
        for (di, dj, wgt) in
            [(0, 0, (1.0 - fx) * (1.0 - fy)), (1, 0, fx * (1.0 - fy)), (0, 1, (1.0 - fx) * fy), (1, 1, fx * fy)]
        {
            let t = self.texel(i + di, j + dj);
            for c in 0..4 {
                out[c] += wgt * t[c];
            }
        }
        out
    }
}

/// `mx_hextile_coord` at `tex_coord` (after `mx_transform_uv`): the three tiles' lookup
/// coordinates (as GL's texture coordinates), barycentric weights and rotations (radians).
fn hextile_coord(p: &Params, tex_coord: [f64; 2]) -> ([[f64; 2]; 3], [f64; 3], [f64; 3]) {
    // mx_transform_uv(tex_coord, tiling, vec2(0.0)), with fileTextureVerticalFlip (as
    // MaterialX's renderers and its TextureBaker set it): v flipped before the tiling.
    let coord = [tex_coord[0] * p.tiling[0], 1.0 - tex_coord[1] * p.tiling[1]];
    // mx_hextile_coord
    let sqrt3_2 = 3.0f64.sqrt() * 2.0;
    let st = [coord[0] * sqrt3_2, coord[1] * sqrt3_2];
    let to_skewed = mat2(1.0, 0.0, -0.57735027, 1.15470054);
    let st_skewed = m_mul_v(to_skewed, st);
    let st_frac = [fract(st_skewed[0]), fract(st_skewed[1])];
    let temp_z = 1.0 - st_frac[0] - st_frac[1];
    let s = if -temp_z < 0.0 { 0.0 } else { 1.0 }; // step(0.0, -temp.z)
    let s2 = 2.0 * s - 1.0;
    let weights = [-temp_z * s2, s - st_frac[1] * s2, s - st_frac[0] * s2];
    let base_id = [st_skewed[0].floor() as i64, st_skewed[1].floor() as i64];
    let si = s as i64;
    let ids = [
        [base_id[0] + si, base_id[1] + si],
        [base_id[0] + si, base_id[1] + 1 - si],
        [base_id[0] + 1 - si, base_id[1] + si],
    ];
    let inv_skewed = mat2(1.0, 0.0, 0.5, 1.0 / 1.15470054);
    let rr = [p.rotationrange[0].to_radians(), p.rotationrange[1].to_radians()];
    let mut coords = [[0.0; 2]; 3];
    let mut rotations = [0.0; 3];
    for (k, id) in ids.iter().enumerate() {
        let ctr = m_mul_v(inv_skewed, [id[0] as f64 / sqrt3_2, id[1] as f64 / sqrt3_2]);
        let rand = hash_f32(*id);
        let rot = mix(rr[0], rr[1], rand[0] * p.rotation);
        let rm = mat2(rot.cos(), -rot.sin(), rot.sin(), rot.cos());
        let scale = mix(1.0, mix(p.scalerange[0], p.scalerange[1], rand[1]), p.scale);
        let offset = [
            mix(p.offsetrange[0], p.offsetrange[1], rand[0] * p.offset),
            mix(p.offsetrange[0], p.offsetrange[1], rand[1] * p.offset),
        ];
        let rotated = v_mul_m([coord[0] - ctr[0], coord[1] - ctr[1]], rm);
        coords[k] = [rotated[0] / scale + ctr[0] + offset[0], rotated[1] / scale + ctr[1] + offset[1]];
        rotations[k] = rot;
    }
    (coords, weights, rotations)
}

/// `mx_hextiledimage_color4` (RGB: `mx_hextiledimage_color3`) at `tex_coord`.
fn reference(p: &Params, tex: &RefTexture, tex_coord: [f64; 2]) -> [f64; 4] {
    let (coords, weights, _) = hextile_coord(p, tex_coord);
    // The texture as GL stores it: its first row at t = 0, so a lookup at t reads v = 1 − t.
    let colours = coords.map(|at| tex.sample([at[0], 1.0 - at[1]]));
    // luminance as weights
    let mut w = [0.0; 3];
    for k in 0..3 {
        let l = p.lumacoeffs;
        let cw = colours[k][0] * l[0] + colours[k][1] * l[1] + colours[k][2] * l[2];
        let cw = mix(1.0, cw, p.falloffcontrast);
        w[k] = cw * weights[k].powf(7.0);
    }
    // mx_hextile_compute_blend_weights(cw, weights, falloff), and with cw = 1 for alpha (aw).
    let blend = |mut w: [f64; 3]| {
        let sum: f64 = w.iter().sum();
        w = w.map(|x| x / sum);
        if p.falloff != 0.5 {
            w = w.map(|x| schlick_gain(x, p.falloff));
            let sum: f64 = w.iter().sum();
            w = w.map(|x| x / sum);
        }
        w
    };
    let w = blend(w);
    let aw = blend(weights.map(|x| x.powf(7.0)));
    let mut out = [0.0; 4];
    for c in 0..3 {
        out[c] = w[0] * colours[0][c] + w[1] * colours[1][c] + w[2] * colours[2][c];
    }
    out[3] = aw[0] * colours[0][3] + aw[1] * colours[1][3] + aw[2] * colours[2][3];
    out
}

// ---------------------------------------------------------------------------------------------

fn hextile_graph(p: &Params, ty: &str, colorspace: &str) -> Graph {
    let file = test_png();
    let cs = if colorspace.is_empty() { String::new() } else { format!(r#" colorspace="{colorspace}""#) };
    graph_of(&format!(
        r#"<hextiledimage name="h" type="{ty}"><input name="file" type="filename" value="{}"{cs}/>{}</hextiledimage><output name="out" type="{ty}" nodename="h"/>"#,
        file.display(),
        p.xml()
    ))
}

fn cases() -> Vec<(&'static str, Params)> {
    vec![
        ("defaults", DEFAULTS),
        (
            "custom",
            Params {
                tiling: [2.0, 3.0],
                rotation: 0.7,
                rotationrange: [-30.0, 90.0],
                scale: 0.6,
                scalerange: [0.8, 1.5],
                offset: 0.5,
                offsetrange: [-0.2, 0.4],
                falloff: 0.2,
                falloffcontrast: 0.8,
                lumacoeffs: [0.2126, 0.7152, 0.0722],
            },
        ),
        ("soft falloff", Params { falloff: 0.85, falloffcontrast: 1.0, tiling: [0.7, 1.3], ..DEFAULTS }),
        ("no contrast", Params { falloffcontrast: 0.0, scale: 0.0, ..DEFAULTS }),
    ]
}

#[test]
fn unfiltered_matches_materialx_formulas() {
    let mut rng = Rng(0x4e7_711e);
    let mut worst = 0.0f64;
    for (name, p) in cases() {
        for (ty, cs) in [("color3", ""), ("color4", ""), ("color3", "srgb_texture")] {
            let tex = RefTexture::new(!cs.is_empty());
            let g = hextile_graph(&p, ty, cs);
            let out = g.output_id("g/out").unwrap();
            let mut scratch = EvalScratch::new(&g);
            let n = if ty == "color4" { 4 } else { 3 };
            let mut max_err = 0.0f64;
            for _ in 0..3000 {
                let uv = [rng.uniform() * 8.0 - 4.0, rng.uniform() * 8.0 - 4.0];
                let f = g.eval_output(out, &Footprint::point(Vec2::new(uv[0] as f32, uv[1] as f32)), &mut scratch);
                // The reference at the f32 point the graph saw.
                let r = reference(&p, &tex, [uv[0] as f32 as f64, uv[1] as f32 as f64]);
                for (c, rc) in r.iter().enumerate().take(n) {
                    let e = (f.ch[c].mean as f64 - rc).abs();
                    assert!(f.ch[c].var == 0.0 && f.ch[c].grad == Vec2::ZERO);
                    max_err = max_err.max(e);
                }
            }
            println!("{name:<14} {ty} {cs:<13} max |node − reference| = {max_err:.2e}");
            assert!(max_err < 1e-4, "{name} {ty} {cs}: max error {max_err:.2e}");
            worst = worst.max(max_err);
        }
    }
    println!("worst {worst:.2e}");
}

/// The GLSL's hash at a few vertices, hand-checked against the shader's arithmetic; and the
/// tile pattern really varies (a test of the reference as much as of the node).
#[test]
fn reference_sanity() {
    let h = hash_f32([0, 0]);
    assert!(h.iter().all(|x| (0.0..1.0).contains(x)));
    assert_ne!(hash_f32([1, 0]), hash_f32([0, 1]));
    let tex = RefTexture::new(false);
    // Rotations and offsets make neighbouring hex tiles differ from plain tiling.
    let plain = Params { rotationrange: [0.0, 0.0], scalerange: [1.0, 1.0], offsetrange: [0.0, 0.0], ..DEFAULTS };
    let mut differ = 0;
    for k in 0..200 {
        let uv = [0.013 * k as f64, 0.021 * k as f64 - 1.0];
        let a = reference(&DEFAULTS, &tex, uv);
        let b = reference(&plain, &tex, uv);
        let c = tex.sample(uv);
        assert!((b[0] - c[0]).abs() < 1e-12 && (b[2] - c[2]).abs() < 1e-12, "plain hex tiling is the image");
        if (a[0] - b[0]).abs() > 0.05 {
            differ += 1;
        }
    }
    assert!(differ > 100, "{differ}");
}

/// With every random range of zero width at the identity (rotation 0°, scale 1, offset 0), the
/// three blended lookups are one and the same: `hextiledimage` is `tiledimage`, unfiltered and
/// filtered at every footprint size (the tiles beyond the centre's three are taken to be like
/// them: their maps coincide).
#[test]
fn identity_ranges_are_tiledimage() {
    let file = test_png();
    let f = file.display();
    for (tiling, falloff) in [([1.0, 1.0], 0.5), ([2.5, 1.5], 0.3)] {
        let p = Params {
            tiling,
            rotationrange: [0.0, 0.0],
            scalerange: [1.0, 1.0],
            offsetrange: [0.0, 0.0],
            falloff,
            falloffcontrast: 0.9,
            ..DEFAULTS
        };
        let hex = hextile_graph(&p, "color3", "");
        let tiled = graph_of(&format!(
            r#"<tiledimage name="t" type="color3"><input name="file" type="filename" value="{f}"/><input name="uvtiling" type="vector2" value="{}, {}"/></tiledimage><output name="out" type="color3" nodename="t"/>"#,
            tiling[0], tiling[1]
        ));
        let (ho, to) = (hex.output_id("g/out").unwrap(), tiled.output_id("g/out").unwrap());
        let (mut hs, mut ts) = (EvalScratch::new(&hex), EvalScratch::new(&tiled));
        let mut rng = Rng(77);
        for sigma in [0.0, 1e-4, 1e-3, 0.01, 0.03, 0.05, 0.1, 0.3, 1.0, 3.0, 30.0] {
            let mut max_err = 0.0f64;
            let mut max_grad = 0.0f64;
            for _ in 0..200 {
                let uv = Vec2::new(rng.uniform() as f32 * 6.0 - 3.0, rng.uniform() as f32 * 6.0 - 3.0);
                let a = 0.3 + 0.7 * rng.uniform() as f32;
                let r = Mat2::from_angle(rng.uniform() as f32 * 3.2);
                let l = r * Mat2::from_diagonal(Vec2::new(sigma as f32, a * sigma as f32));
                let fp = Footprint::new(uv, l * l.transpose());
                let x = hex.eval_output(ho, &fp, &mut hs);
                let y = tiled.eval_output(to, &fp, &mut ts);
                for c in 0..3 {
                    max_err = max_err.max((x.ch[c].mean - y.ch[c].mean).abs() as f64);
                    max_grad = max_grad.max((x.ch[c].grad - y.ch[c].grad).abs().max_element() as f64);
                }
            }
            println!("tiling {tiling:?} σ={sigma:<7} max |hex − tiled| = {max_err:.2e}, gradient {max_grad:.2e}");
            assert!(max_err < 1e-5, "σ={sigma}: {max_err:.2e}");
            assert!(max_grad < 1e-3, "σ={sigma}: gradient {max_grad:.2e}");
        }
    }
}

/// Filtered values against supersampling (mean abs error per channel, values in [0, 1]):
/// - σ ≤ 1e-4 uv: within 1e-4 of the brute force (the unfiltered value);
/// - σ ≥ 1e-3 uv, where point sampling errs by more than 0.01: at most 0.3 of its error;
/// - σ ≥ 3 hex tiles (triangle edges): within 0.02 of the brute force (which is the mean over
///   the few hundred random tiles a footprint of that size covers, not the ensemble mean the
///   node returns, plus the luminance weighting's bias against the plain image mean);
/// - σ ≥ 1e-3 uv: the node's reported spread √var within [0.7, 1.6] × the samples' spread
///   (measured 0.9–1.45: over the three lookups it is combined as fully correlated, and beyond a
///   tile it is the image's global spread, which the blend reduces).
#[test]
fn filtered_matches_supersampling() {
    let sigmas = [1e-6, 1e-4, 1e-3, 3e-3, 1e-2, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0];
    let mut failures = Vec::new();
    let mut sweeps = Vec::new();
    println!("{}", common::sweep_header());
    for (ci, (name, p)) in cases().into_iter().enumerate() {
        for ty in ["color3", "color4"] {
            if ty == "color4" && ci > 1 {
                continue;
            }
            let g = hextile_graph(&p, ty, "");
            let out = g.output_id("g/out").unwrap();
            let tile_uv = 1.0 / (2.0 * 3.0f64.sqrt() * p.tiling[0].min(p.tiling[1]));
            let rows = common::sweep(&g, out, &sigmas, 0xabc0 ^ ci as u64, 12, 2048, common::centre_in_square);
            for r in &rows {
                let (sigma, ef, ep, spread, sd, ratio) =
                    (r.sigma, r.filtered, r.point, r.spread, r.node_sigma, r.ratio());
                println!("{}", common::sweep_line(&format!("{name} {ty}"), r));
                if sigma <= 1e-4 && ef > 1e-4 {
                    failures.push(format!("{name} {ty} σ={sigma}: filtered error {ef:.2e} at a tiny footprint"));
                }
                if sigma >= 1e-3 && ep > 0.01 && ratio > 0.3 {
                    failures.push(format!("{name} {ty} σ={sigma}: error ratio {ratio:.3} > 0.3"));
                }
                if sigma >= 1e-3 && !(0.7..=1.6).contains(&(sd / spread)) {
                    failures.push(format!("{name} {ty} σ={sigma}: spread {sd:.2e} against {spread:.2e}"));
                }
                if sigma as f64 >= 3.0 * tile_uv && ef > 0.02 {
                    failures.push(format!("{name} {ty} σ={sigma}: error {ef:.2e} > 0.02 at a coarse footprint"));
                }
            }
            sweeps.push((format!("{name} ({ty})"), rows));
        }
    }
    common::write_doc(
        "filtering/hextile.md",
        &format!(
            "# `hextiledimage` filtered against supersampling\n\n\
             Written by `crates/graph/tests/verify/hextile.rs` (`filtered_matches_supersampling`); cells as \
             in `nodes.md` (12 centres, 2048 samples each). Asserted: at σ ≤ 1e-4 the filtered \
             error is below 1e-4; at σ ≥ 1e-3, where point sampling errs by more than 0.01, the \
             ratio is below 0.3; beyond three hex tiles the error is below 0.02; the reported \
             spread is 0.7–1.6× the true one.\n\n{}",
            common::sweep_markdown(&sweeps)
        ),
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Coarse footprints cost no more than fine ones: beyond a few hex tiles the node reads only
/// the image's mean.
#[test]
fn coarse_footprints_cost_less() {
    let g = hextile_graph(&DEFAULTS, "color3", "");
    let out = g.output_id("g/out").unwrap();
    let mut scratch = EvalScratch::new(&g);
    let mut work_at = |sigma: f32| {
        scratch.reset_stats();
        let t = std::time::Instant::now();
        for k in 0..2000 {
            let uv = Vec2::new(k as f32 * 0.0137, k as f32 * 0.0071);
            let fp = if sigma == 0.0 { Footprint::point(uv) } else { Footprint::isotropic(uv, sigma) };
            std::hint::black_box(g.eval_output(out, &fp, &mut scratch));
        }
        (scratch.work().lattice, t.elapsed().as_secs_f64())
    };
    let point = work_at(0.0);
    let fine = work_at(1e-3);
    let mid = work_at(0.1);
    let coarse = work_at(10.0);
    println!("lattice work, seconds per 2000: point {point:?}, σ=1e-3 {fine:?}, σ=0.1 {mid:?}, σ=10 {coarse:?}");
    assert!(coarse.0 < point.0 && coarse.0 < fine.0 && mid.0 <= fine.0);
}

/// Every footprint shape gives finite moments (degenerate, huge, zero).
#[test]
fn finite_for_every_footprint() {
    for (_, p) in cases() {
        let g = hextile_graph(&p, "color4", "");
        let out = g.output_id("g/out").unwrap();
        let mut scratch = EvalScratch::new(&g);
        for uv in [Vec2::new(0.3, 0.7), Vec2::new(-12.25, 3.5), Vec2::new(1e4, -3e3)] {
            for cov in [
                Mat2::ZERO,
                Mat2::from_diagonal(Vec2::splat(1e-14)),
                Mat2::from_diagonal(Vec2::new(1e-4, 0.0)),
                Mat2::from_cols(Vec2::new(1e-2, 1e-2), Vec2::new(1e-2, 1e-2)),
                Mat2::from_diagonal(Vec2::splat(0.04)),
                Mat2::from_diagonal(Vec2::splat(1e6)),
            ] {
                let f = g.eval_output(out, &Footprint::new(uv, cov), &mut scratch);
                for m in &f.ch {
                    assert!(m.mean.is_finite() && m.var.is_finite() && m.grad.is_finite(), "{uv} {cov}: {m:?}");
                }
            }
        }
    }
}

/// A black texture with `falloffcontrast = 1` zeroes every luminance weight (MaterialX divides
/// by zero there): the node falls back to the barycentric weights and stays finite.
#[test]
fn black_texture_full_contrast_is_finite() {
    let dir = crate::common::TestDir::new("hextile-black");
    let path = dir.join("black.png");
    image::RgbImage::from_pixel(4, 4, image::Rgb([0, 0, 0])).save(&path).unwrap();
    let g = graph_of(&format!(
        r#"<hextiledimage name="h" type="color3"><input name="file" type="filename" value="{}"/><input name="falloffcontrast" type="float" value="1"/><input name="falloff" type="float" value="0.2"/></hextiledimage><output name="out" type="color3" nodename="h"/>"#,
        path.display()
    ));
    let out = g.output_id("g/out").unwrap();
    let mut scratch = EvalScratch::new(&g);
    for k in 0..100 {
        let uv = Vec2::new(k as f32 * 0.031, k as f32 * -0.017);
        for fp in [Footprint::point(uv), Footprint::isotropic(uv, 0.01)] {
            let f = g.eval_output(out, &fp, &mut scratch);
            assert!(f.ch.iter().all(|m| m.mean == 0.0 && m.grad.is_finite() && m.var.is_finite()), "{f:?}");
        }
    }
}

/// A document naming a missing file fails to load with the file and line of the input.
#[test]
fn missing_file_names_document_and_line() {
    let dir = crate::common::TestDir::new("hextile-missing");
    let path = dir.join("missing.mtlx");
    let text = "<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n  <nodegraph name=\"g\">\n    <hextiledimage name=\"h\" type=\"color3\">\n      <input name=\"file\" type=\"filename\" value=\"no_such_texture.png\"/>\n    </hextiledimage>\n    <output name=\"out\" type=\"color3\" nodename=\"h\"/>\n  </nodegraph>\n</materialx>\n";
    std::fs::write(&path, text).unwrap();
    let e = Document::load(&path).expect_err("the file is missing");
    println!("{e}");
    assert_eq!(e.location.file, path);
    assert_eq!(e.location.line, 5, "{e}");
    assert!(matches!(&e.kind, LoadErrorKind::MissingFile(p) if p == Path::new("no_such_texture.png")), "{e}");
    let msg = e.to_string();
    assert!(msg.starts_with(&format!("{}:5:", path.display())) && msg.contains("no_such_texture.png"), "{msg}");
}

/// Unknown inputs (not in the nodedef) and types without a nodedef are reported as unsupported.
#[test]
fn unsupported_inputs_and_types() {
    let file = test_png();
    for (body, what) in [
        (
            r#"<hextiledimage name="h" type="color3"><input name="file" type="filename" value="{f}"/><input name="uaddressmode" type="string" value="clamp"/></hextiledimage><output name="out" type="color3" nodename="h"/>"#,
            "uaddressmode",
        ),
        (
            r#"<hextiledimage name="h" type="float"><input name="file" type="filename" value="{f}"/></hextiledimage><output name="out" type="float" nodename="h"/>"#,
            "float",
        ),
    ] {
        let text = format!(
            r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">{}</nodegraph></materialx>"#,
            body.replace("{f}", &file.display().to_string())
        );
        let e = Document::parse(&text, "t.mtlx".as_ref(), &LoadOptions::default()).expect_err("unsupported");
        assert!(matches!(e.kind, LoadErrorKind::Unsupported { .. }), "{e}");
        assert!(e.to_string().contains(what), "{e}");
    }
}

// ---------------------------------------------------------------------------------------------
// hextilednormalmap: MaterialX's `mx_hextilednormalmap_vector3` (and `lib/mx_geometry.glsl`),
// transcribed in f64.

type V3 = [f64; 3];

fn add3(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn scale3(a: V3, k: f64) -> V3 {
    [a[0] * k, a[1] * k, a[2] * k]
}
fn dot3(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn normalize3(a: V3) -> V3 {
    let l = dot3(a, a).sqrt();
    if l > 0.0 {
        scale3(a, 1.0 / l)
    } else {
        [0.0; 3]
    }
}

/// GLSL `mat3(...)` of `mx_axis_rotation_matrix(a, r)` (nine values, column by column), times `v`.
fn axis_rotation_times(a: V3, r: f64, v: V3) -> V3 {
    let (s, c) = r.sin_cos();
    let omc = 1.0 - c;
    let m = [
        a[0] * a[0] * omc + c,
        a[0] * a[1] * omc - a[2] * s,
        a[0] * a[2] * omc + a[1] * s,
        a[1] * a[0] * omc + a[2] * s,
        a[1] * a[1] * omc + c,
        a[1] * a[2] * omc - a[0] * s,
        a[2] * a[0] * omc - a[1] * s,
        a[2] * a[1] * omc + a[0] * s,
        a[2] * a[2] * omc + c,
    ];
    // Column j is m[3j..3j+3]: (M v)_i = Σ_j M[j][i] v_j.
    [0, 1, 2].map(|i| (0..3).map(|j| m[3 * j + i] * v[j]).sum())
}

/// The frame and settings of a `hextilednormalmap` case.
#[derive(Clone, Copy)]
struct NormalCase {
    strength: f64,
    flip_g: bool,
    n: V3,
    t: V3,
    b: V3,
}

const FLAT: NormalCase =
    NormalCase { strength: 1.0, flip_g: false, n: [0.0, 0.0, 1.0], t: [1.0, 0.0, 0.0], b: [0.0, 1.0, 0.0] };

fn normal_reference(p: &Params, nc: &NormalCase, tex: &RefTexture, tex_coord: [f64; 2]) -> V3 {
    let (coords, weights, rotations) = hextile_coord(p, tex_coord);
    let n = nc.n;
    let mut grads = [[0.0; 3]; 3];
    for k in 0..3 {
        let c = tex.sample([coords[k][0], 1.0 - coords[k][1]]);
        let mut nm = [c[0], c[1], c[2]];
        if nc.flip_g {
            nm[1] = 1.0 - nm[1];
        }
        nm = nm.map(|x| 2.0 * x - 1.0);
        let tk = scale3(axis_rotation_times(n, -rotations[k], nc.t), nc.strength);
        let bk = scale3(axis_rotation_times(n, -rotations[k], nc.b), nc.strength);
        let nk = normalize3(add3(add3(scale3(tk, nm[0]), scale3(bk, nm[1])), scale3(n, nm[2])));
        // mx_normals_to_gradient
        let d = dot3(n, nk);
        grads[k] = scale3(add3(scale3(n, d), scale3(nk, -1.0)), 1.0 / d.abs().max(1e-8));
    }
    // mx_hextile_compute_blend_weights(vec3(1.0), weights, falloff)
    let mut w = weights.map(|x| x.powf(7.0));
    let sum: f64 = w.iter().sum();
    w = w.map(|x| x / sum);
    if p.falloff != 0.5 {
        w = w.map(|x| schlick_gain(x, p.falloff));
        let sum: f64 = w.iter().sum();
        w = w.map(|x| x / sum);
    }
    // mx_gradient_blend_3_normals
    let mut gg = [0.0; 3];
    for k in 0..3 {
        gg = add3(gg, scale3(grads[k], w[k].clamp(0.0, 1.0)));
    }
    normalize3(add3(n, scale3(gg, -1.0)))
}

fn normal_graph(p: &Params, nc: &NormalCase) -> Graph {
    let file = normal_png();
    let v3 =
        |name: &str, v: V3| format!(r#"<input name="{name}" type="vector3" value="{}, {}, {}"/>"#, v[0], v[1], v[2]);
    let frame = if nc.n == FLAT.n && nc.t == FLAT.t && nc.b == FLAT.b {
        String::new()
    } else {
        v3("normal", nc.n) + &v3("tangent", nc.t) + &v3("bitangent", nc.b)
    };
    graph_of(&format!(
        r#"<hextilednormalmap name="h" type="vector3"><input name="file" type="filename" value="{}"/>{}<input name="strength" type="float" value="{}"/><input name="flip_g" type="boolean" value="{}"/>{frame}</hextilednormalmap><output name="out" type="vector3" nodename="h"/>"#,
        file.display(),
        p.xml(),
        nc.strength,
        nc.flip_g
    ))
}

fn normal_cases() -> Vec<(&'static str, Params, NormalCase)> {
    let s = 0.5f64.sqrt();
    let tilted = NormalCase { strength: 0.6, flip_g: true, n: [0.0, s, s], t: [1.0, 0.0, 0.0], b: [0.0, s, -s] };
    let custom = cases()[1].1;
    vec![
        ("defaults", DEFAULTS, FLAT),
        (
            "custom tilted",
            Params { falloffcontrast: DEFAULTS.falloffcontrast, lumacoeffs: DEFAULTS.lumacoeffs, ..custom },
            tilted,
        ),
        ("soft strong", Params { falloff: 0.85, tiling: [0.7, 1.3], ..DEFAULTS }, NormalCase { strength: 2.5, ..FLAT }),
    ]
}

#[test]
fn normalmap_unfiltered_matches_materialx_formulas() {
    let tex = RefTexture::normal_map();
    let mut rng = Rng(0x4e7_0a1);
    for (name, p, nc) in normal_cases() {
        let g = normal_graph(&p, &nc);
        let out = g.output_id("g/out").unwrap();
        let mut scratch = EvalScratch::new(&g);
        let mut max_err = 0.0f64;
        let mut worst = ([0.0; 2], [0.0; 3], [0.0f32; 3]);
        for _ in 0..3000 {
            let uv = [rng.uniform() * 8.0 - 4.0, rng.uniform() * 8.0 - 4.0];
            let f = g.eval_output(out, &Footprint::point(Vec2::new(uv[0] as f32, uv[1] as f32)), &mut scratch);
            let r = normal_reference(&p, &nc, &tex, [uv[0] as f32 as f64, uv[1] as f32 as f64]);
            for (c, rc) in r.iter().enumerate() {
                assert!(f.ch[c].var == 0.0 && f.ch[c].grad == Vec2::ZERO);
                let e = (f.ch[c].mean as f64 - rc).abs();
                if e > max_err {
                    max_err = e;
                    worst = (uv, r, [0, 1, 2].map(|k| f.ch[k].mean));
                }
            }
        }
        println!("{name:<14} max |node − reference| = {max_err:.2e} at {worst:?}");
        assert!(max_err < 1e-4, "{name}: max error {max_err:.2e}");
    }
}

/// With every random range at the identity the tiles are one normal map: the node is
/// `normalmap` of `tiledimage` (unfiltered).
#[test]
fn normalmap_identity_ranges_are_normalmap_of_the_image() {
    let file = normal_png();
    let p = Params { rotationrange: [0.0, 0.0], scalerange: [1.0, 1.0], offsetrange: [0.0, 0.0], ..DEFAULTS };
    let hex = normal_graph(&p, &FLAT);
    let plain = graph_of(&format!(
        r#"<tiledimage name="t" type="vector3"><input name="file" type="filename" value="{}"/></tiledimage><normalmap name="n" type="vector3"><input name="in" type="vector3" nodename="t"/></normalmap><output name="out" type="vector3" nodename="n"/>"#,
        file.display()
    ));
    let (ho, po) = (hex.output_id("g/out").unwrap(), plain.output_id("g/out").unwrap());
    let (mut hs, mut ps) = (EvalScratch::new(&hex), EvalScratch::new(&plain));
    let mut rng = Rng(78);
    let mut max_err = 0.0f32;
    for _ in 0..500 {
        let uv = Vec2::new(rng.uniform() as f32 * 6.0 - 3.0, rng.uniform() as f32 * 6.0 - 3.0);
        let x = hex.eval_output(ho, &Footprint::point(uv), &mut hs);
        let y = plain.eval_output(po, &Footprint::point(uv), &mut ps);
        for c in 0..3 {
            max_err = max_err.max((x.ch[c].mean - y.ch[c].mean).abs());
        }
    }
    println!("max |hextilednormalmap − normalmap(tiledimage)| = {max_err:.2e}");
    assert!(max_err < 1e-5, "{max_err:.2e}");
}

/// Filtered against supersampling (mean abs error per channel of the unit normal):
/// - σ ≤ 1e-4 uv: within 1e-4 of the brute force (the unfiltered value);
/// - σ ≥ 1e-3 uv, where point sampling errs by more than 0.01: at most 0.35 of its error (the
///   normal of the blended filtered lookups is not the mean of the normals: the decode and the
///   normalisation are not linear);
/// - σ ≥ 3 hex tiles: within 0.06 of the brute force (the mean over the tiles a footprint covers,
///   against the ensemble's expectation with the decode linearised about the image's mean colour:
///   measured up to 0.053 at strength 2.5, 0.02 at strength 1);
/// - σ ≥ 1e-3 uv: the node's reported spread √var at most 3 × the samples' spread (the lookups'
///   spreads through each decode's Jacobian, combined as fully correlated: an upper bound).
#[test]
fn normalmap_filtered_matches_supersampling() {
    let sigmas = [1e-6, 1e-4, 1e-3, 3e-3, 1e-2, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0];
    let mut failures = Vec::new();
    let mut sweeps = Vec::new();
    println!("{}", common::sweep_header());
    for (ci, (name, p, nc)) in normal_cases().into_iter().enumerate() {
        let g = normal_graph(&p, &nc);
        let out = g.output_id("g/out").unwrap();
        let tile_uv = 1.0 / (2.0 * 3.0f64.sqrt() * p.tiling[0].min(p.tiling[1]));
        let rows = common::sweep(&g, out, &sigmas, 0xabd0 ^ ci as u64, 12, 2048, common::centre_in_square);
        for r in &rows {
            let (sigma, ef, ep, spread, sd, ratio) = (r.sigma, r.filtered, r.point, r.spread, r.node_sigma, r.ratio());
            println!("{}", common::sweep_line(name, r));
            if sigma <= 1e-4 && ef > 1e-4 {
                failures.push(format!("{name} σ={sigma}: filtered error {ef:.2e} at a tiny footprint"));
            }
            if sigma >= 1e-3 && ep > 0.01 && ratio > 0.35 {
                failures.push(format!("{name} σ={sigma}: error ratio {ratio:.3} > 0.35"));
            }
            if sigma >= 1e-3 && sd > 3.0 * spread.max(1e-3) {
                failures.push(format!("{name} σ={sigma}: spread {sd:.2e} against {spread:.2e}"));
            }
            if sigma as f64 >= 3.0 * tile_uv && ef > 0.06 {
                failures.push(format!("{name} σ={sigma}: error {ef:.2e} > 0.06 at a coarse footprint"));
            }
        }
        sweeps.push((name.to_string(), rows));
    }
    common::write_doc(
        "filtering/hextilednormalmap.md",
        &format!(
            "# `hextilednormalmap` filtered against supersampling\n\n\
             Written by `crates/graph/tests/verify/hextile.rs` (`normalmap_filtered_matches_supersampling`); \
             cells as in `nodes.md` (12 centres, 2048 samples each; errors of the unit normal's channels). \
             Asserted: at σ ≤ 1e-4 the filtered error is below 1e-4; at σ ≥ 1e-3, where point sampling \
             errs by more than 0.01, the ratio is below 0.35; beyond three hex tiles the error is below \
             0.06; the reported spread is at most 3× the true one.\n\n{}",
            common::sweep_markdown(&sweeps)
        ),
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Finite at every footprint, also with a degenerate frame and extreme strength.
#[test]
fn normalmap_finite_for_every_footprint() {
    let degenerate = NormalCase { strength: 1e6, flip_g: false, n: [0.0; 3], t: [0.0; 3], b: [1e20, 0.0, 0.0] };
    for nc in [FLAT, degenerate, NormalCase { strength: 0.0, ..FLAT }] {
        let g = normal_graph(&DEFAULTS, &nc);
        let out = g.output_id("g/out").unwrap();
        let mut scratch = EvalScratch::new(&g);
        for uv in [Vec2::new(0.3, 0.7), Vec2::new(-12.25, 3.5), Vec2::new(1e4, -3e3)] {
            for sigma in [0.0f32, 1e-6, 1e-3, 0.1, 1.0, 1e3] {
                let fp = if sigma == 0.0 { Footprint::point(uv) } else { Footprint::isotropic(uv, sigma) };
                let v = g.eval_output(out, &fp, &mut scratch);
                for c in 0..3 {
                    let m = v.ch[c];
                    assert!(
                        m.mean.is_finite() && m.grad.is_finite() && m.var.is_finite() && m.var >= 0.0,
                        "{uv} σ={sigma}: {m:?}"
                    );
                }
            }
        }
    }
}
