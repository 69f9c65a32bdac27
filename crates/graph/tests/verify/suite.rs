//! MaterialX conformance: every bake listed in `shared/mtlx-suite/manifest.json` (MaterialX's test
//! suite) and in `tests/mtlx-refs/manifest.json` (tessera's own documents covering every
//! value-typed nodedef of the standard library, made by `scripts/mtlx-bake-refs.sh`) is made with
//! [`graph::bake`] — the function `tessera bake` runs — and compared texel by texel with
//! MaterialX 1.39.5's own GLSL bake. The per-document results are written to
//! `docs/materialx-conformance.md`, one section per reference set.
//!
//! Documents load leniently: an output that needs an unsupported node is reported with the
//! node(s) and their document lines. Tolerances:
//! - analytic outputs: `|ours − MaterialX| ≤ 1e-4 · max(1, |MaterialX|)` at every texel (absolute
//!   1e-4, relative for values beyond 1), evaluated unfiltered at texel centres;
//! - image-based outputs (entries with `texture_files`): evaluated with the one-texel filter
//!   (MaterialX's baker samples mip-mapped images at the level of its 128 × 128 pixels: a box of
//!   one pixel then a tent at that level, about the spread of our Gaussian of half a texel), and
//!   compared relative to the reference's range `R` (largest max − min of a channel, at least
//!   0.05): at most [`IMAGE_MEAN`]` · R` on average, and beyond [`IMAGE_MAX`]` · R` at no more
//!   than a fraction [`IMAGE_OUTLIERS`] of the values. GL's
//!   box-filtered mips and trilinear blend differ from our exact Gaussian filtering of the
//!   bilinear image most at the one-texel lines of the test images. As a check that this bound
//!   still discriminates, the same bake with v flipped must fail it wherever the reference is
//!   not itself nearly symmetric in v.
//!
//! Two stated exceptions, each a property of MaterialX's GPU renderer rather than of the node:
//! bakes whose output is an `asin` or `acos` node take [`GPU_ASIN_ABS`] in place of the analytic
//! tolerance (the error Mesa documents for its `asin`), and the edge texels of `splitlr` and
//! `splittb` bakes are compared with MaterialX's screen-space `mx_aastep` applied to tessera's
//! values of the node's inputs ([`aastep_texels`]).
//!
//! Texels where MaterialX's value is NaN (undefined) are not compared. Where an entry has a
//! `flat_plane_variant` (the baker's quad with normal +z, tangent +x supplied), that bake is the
//! reference: it is the geometry `graph::Footprint` gives geometry nodes.
//!
//! A third stated exception: MaterialX binds images with 16× anisotropic filtering, and Mesa's
//! llvmpipe takes the anisotropic footprint from the lookup coordinate's differences inside each
//! 2 × 2 pixel quad, ignoring the gradients a shader passes to `textureGrad` (with 16×,
//! `textureGrad` with zero gradients still averages wherever the coordinate jumps inside a quad;
//! with anisotropy 1 it is the level-0 bilinear lookup to 3.6e-3). The hex-tiling shaders pass
//! such gradients and their coordinates jump between tiles inside quads, so their bakes have an
//! `isotropic_variant` (the same shader and images with anisotropy 1,
//! `scripts/gl-anisotropy-shim.c`), and that is the reference.
//!
//! The test fails if fewer than [`MIN_PASS`] bakes pass, or if a bake that the committed table
//! lists as passing no longer does (the table is then left as it was, and the new one is written
//! beside the test binary for inspection).

use crate::common;
use graph::bake::{self, BakeFilter, BakeSettings, Orientation};
use graph::{Document, LoadOptions};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Absolute tolerance of analytic bakes (relative beyond magnitude 1).
const ANALYTIC_TOL: f32 = 1e-4;
/// Largest texel error allowed for image-based bakes, relative to the reference's range.
const IMAGE_MAX: f32 = 0.2;
/// Mean texel error allowed for image-based bakes, relative to the reference's range.
const IMAGE_MEAN: f32 = 0.025;
/// Fraction of the values of an image-based bake allowed beyond `IMAGE_MAX · R`.
const IMAGE_OUTLIERS: f32 = 0.001;
/// Mesa's documented worst-case absolute error of its GLSL `asin` (a polynomial in `√(1 − |x|)`:
/// 0.00039, Mesa commit "glsl: improve the accuracy of the asin() builtin function"), which
/// llvmpipe runs (Mesa's NIR `build_asin` keeps that polynomial, coefficients 0.086566724 and
/// −0.03102955), and of `acos` (π/2 minus the same polynomial form with its own coefficients).
/// Vulkan 1.0's precision appendix leaves the
/// trigonometric functions' precision undefined; a ULP bound from a later table was not confirmed
/// in the sources searched, so the rule rests on Mesa's own figure, which the measured errors
/// (3.88e-4 for asin, 1.6e-4 for acos) stay within.
/// Bakes whose output is an `asin` or `acos` node are compared with this absolute tolerance in
/// place of [`ANALYTIC_TOL`]; nothing else is.
const GPU_ASIN_ABS: f32 = 3.9e-4;

/// Whether a bake's output is an `asin` or `acos` node, compared with [`GPU_ASIN_ABS`]: own
/// references by their nodedef, the shared suite's by its trig document's graphs.
fn inverse_trig(nodedef: Option<&str>, doc: &str, element: &str) -> bool {
    match nodedef {
        Some(nd) => nd.starts_with("ND_asin_") || nd.starts_with("ND_acos_"),
        None => doc.ends_with("math/trig.mtlx") && (element.starts_with("asin_") || element.starts_with("acos_")),
    }
}

/// MaterialX's GLSL `splitlr`/`splittb` choose their side with `mx_aastep(center, x)`:
/// `smoothstep(c − a, c + a, x)` with `a = 0.7071 · |(dFdx x, dFdy x)|`, a screen-space
/// anti-aliasing of the edge over about a pixel of the bake, which a point evaluation (and
/// tessera's footprint filtering, whose footprint is not the bake's pixel) does not reproduce.
/// For a bake whose output is such a node, the texels where that smoothstep is strictly
/// between 0 and 1 (within `a` of the edge: one or two per row or column) are compared with
/// MaterialX's formula applied to tessera's own values of the node's inputs (`valuel`, `valuer`
/// or `valuet`, `valueb`, `center`, `texcoord`) and of the pixel derivatives of `texcoord`
/// (GL's fine derivatives: differences within the 2 × 2 pixel quads); every other texel is
/// compared with tessera's node itself. Returns the emulated texels (index, values) or `None`
/// when the output is not a split node.
fn aastep_texels(doc: &Document, element: &str, w: usize, h: usize) -> Option<Vec<(usize, Vec<f32>)>> {
    use graph::{BakeSource, EvalScratch, Footprint, NoOverride, Source};
    let (BakeSource::Output(out), _) = bake::resolve(doc, element).ok()? else { return None };
    let g = doc.graph();
    let Source::Node { node, channel: None } = g.output(out).source else { return None };
    let lr = match g.node_category(node) {
        "splitlr" => true,
        "splittb" => false,
        _ => return None,
    };
    let inputs = g.node_inputs(node);
    let src = |name: &str| inputs.iter().find(|(n, _)| *n == name).map(|(_, s)| (*s).clone());
    let (first, second) = if lr { ("valuel", "valuer") } else { ("valueb", "valuet") };
    let (a, b, c, t) = (src(first)?, src(second)?, src("center")?, src("texcoord")?);
    let n = g.node_type(node).channels();
    let mut scratch = EvalScratch::new(g);
    let mut value = |s: &Source, i: usize, j: usize| -> Option<Vec<f32>> {
        let uv = glam::Vec2::new((i as f32 + 0.5) / w as f32, 1.0 - (j as f32 + 0.5) / h as f32);
        let fp = Footprint::point(uv);
        Some(match s {
            Source::Constant(v) => v.channels().to_vec(),
            Source::Texcoord => vec![uv.x, uv.y],
            Source::Node { node, channel } => {
                let f = g.eval_node_direct(*node, &fp, &mut scratch, &NoOverride);
                match channel {
                    Some(k) => vec![f.ch[*k as usize].mean],
                    None => f.ch[..f.ty.channels()].iter().map(|m| m.mean).collect(),
                }
            }
            Source::Geometry(_) => return None,
        })
    };
    let axis = if lr { 0 } else { 1 };
    let mut x = vec![0.0f32; w * h];
    for j in 0..h {
        for i in 0..w {
            x[j * w + i] = value(&t, i, j)?[axis];
        }
    }
    let mut texels = Vec::new();
    for j in 0..h {
        for i in 0..w {
            // Fine derivatives within the 2 × 2 quad (rows pair up from the bottom: GL's y).
            let dx = x[j * w + (i | 1).min(w - 1)] - x[j * w + (i & !1)];
            let r = h - 1 - j;
            let row = |r: usize| h - 1 - r.min(h - 1);
            let dy = x[row(r | 1) * w + i] - x[row(r & !1) * w + i];
            let afwidth = (dx * dx + dy * dy).sqrt() * std::f32::consts::FRAC_1_SQRT_2;
            let centre = value(&c, i, j)?[0];
            let (e0, e1) = (centre - afwidth, centre + afwidth);
            if e1 <= e0 {
                continue;
            }
            let s = ((x[j * w + i] - e0) / (e1 - e0)).clamp(0.0, 1.0);
            if s <= 0.0 || s >= 1.0 {
                continue;
            }
            let s = s * s * (3.0 - 2.0 * s);
            let (va, vb) = (value(&a, i, j)?, value(&b, i, j)?);
            let at = |v: &[f32], k: usize| if v.len() == 1 { v[0] } else { v[k] };
            texels.push((j * w + i, (0..n).map(|k| at(&va, k) + (at(&vb, k) - at(&va, k)) * s).collect()));
        }
    }
    Some(texels)
}

/// Bakes that pass today: a regression floor on top of the per-bake check against the table.
const MIN_PASS: usize = 267;
/// The same floor for tessera's own references (`tests/mtlx-refs`).
const MIN_OWN_PASS: usize = 684;

/// Explanations of known differences, appended to failures: (document suffix, element prefix,
/// note).
const NOTES: &[(&str, &str, &str)] = &[(
    "convolution/heighttonormal.mtlx",
    "",
    "MaterialX differentiates the minified image across one pixel of its bake (dFdx/dFdy), so its normals \
         depend on the bake resolution; ours are the slope of the filtered height",
)];

/// Explanations of known differences from tessera's own references (`tests/mtlx-refs`).
const OWN_NOTES: &[(&str, &str, &str)] = &[
    (
        "docs/hextilednormalmap.mtlx",
        "",
        "against the bake without anisotropic filtering (the bake with it differs from that by up to 0.067, mean \
         0.0008) 9 of 1728 values are beyond 0.2 R, where R (0.051) is this output's small \
         range; the mean error (0.0007) is half its bound. The difference is where each side filters a nonlinear node: \
         MaterialX filters each of the three lookups (trilinear) before rotating, blending and normalising the \
         normals, tessera filters the node's output. MaterialX's own shader supersampled (192 pixels per unit, \
         without anisotropy, averaged with a Gaussian of half a bake texel) is as far from its 24² bake (mean 0.0022, \
         max 0.041) as from tessera (mean 0.0019, max 0.038); the unfiltered node matches a transcription of \
         MaterialX's GLSL to 1e-4 (crates/graph/tests/verify/hextile.rs)",
    ),
    (
        "docs/image.mtlx",
        "image_float_vaddressmode_mirror",
        "MaterialX's mirror seam in v lies half an image texel (1/1280) below v = 0: below it each of its rows equals \
         tessera's one bake row higher, which mirrors at v = 0 exactly (the u mirror agrees; the error is within \
         tolerance at every texel, the mean is not)",
    ),
];

#[derive(Clone, Debug)]
enum Outcome {
    /// Passed, with the largest error and, where a stated rule applied, what it did.
    Pass {
        max_err: f32,
        note: Option<String>,
    },
    Fail(String),
    Unsupported(String),
}

struct Row {
    element: String,
    outcome: Outcome,
}

fn table_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/materialx-conformance.md")
}

/// Elements the committed table lists as passing, per document.
fn previous_passes(text: &str) -> Vec<(String, String)> {
    let mut doc = String::new();
    let mut v = Vec::new();
    for line in text.lines() {
        if let Some(d) = line.strip_prefix("### ") {
            doc = d.trim().trim_matches('`').to_string();
        } else if line.starts_with("| `") {
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            if cells.len() > 2 && cells[2] == "pass" {
                v.push((doc.clone(), cells[1].trim_matches('`').to_string()));
            }
        }
    }
    v
}

/// Compares a bake with the reference EXR.
fn compare(baked: &graph::BakedImage, reference: &common::Exr, names: &[String], textured: bool) -> Outcome {
    compare_with(baked, reference, names, textured, ANALYTIC_TOL)
}

/// [`compare`], analytic bakes with absolute tolerance `abs_tol` (relative beyond magnitude 1).
fn compare_with(
    baked: &graph::BakedImage,
    reference: &common::Exr,
    names: &[String],
    textured: bool,
    abs_tol: f32,
) -> Outcome {
    let (w, h) = (baked.width as usize, baked.height as usize);
    if reference.width != w || reference.height != h {
        return Outcome::Fail(format!("reference is {}x{}, bake {w}x{h}", reference.width, reference.height));
    }
    let mut range = 0.0f32;
    for name in names {
        let Some(r) = reference.channel(name) else {
            return Outcome::Fail(format!("reference has no channel {name}"));
        };
        let finite = r.iter().copied().filter(|x| x.is_finite());
        let (lo, hi) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
        range = range.max(hi - lo);
    }
    let range = range.max(0.05);
    let mut worst = (0.0f32, 0usize, 0usize, 0usize, 0.0f32, 0.0f32);
    let (mut count, mut off, mut sum) = (0usize, 0usize, 0.0f64);
    let (mut cols, mut rows) = ((usize::MAX, 0usize), (usize::MAX, 0usize));
    for (k, name) in names.iter().enumerate() {
        let r = reference.channel(name).unwrap_or_default();
        for j in 0..h {
            for i in 0..w {
                let want = r[j * w + i];
                if !want.is_finite() {
                    continue;
                }
                let got = baked.texel(i as u32, j as u32).get(k).copied().unwrap_or(0.0);
                let e = if got.is_finite() { (got - want).abs() } else { f32::INFINITY };
                count += 1;
                sum += e as f64;
                let tol = if textured { IMAGE_MAX * range } else { abs_tol * want.abs().max(1.0) };
                if e > tol {
                    off += 1;
                    cols = (cols.0.min(i), cols.1.max(i));
                    rows = (rows.0.min(j), rows.1.max(j));
                }
                if e > worst.0 {
                    worst = (e, i, j, k, got, want);
                }
            }
        }
    }
    if count == 0 {
        return Outcome::Fail("the reference has no finite texel".into());
    }
    let mean = (sum / count as f64) as f32;
    let ok =
        if textured { off as f32 <= IMAGE_OUTLIERS * count as f32 && mean <= IMAGE_MEAN * range } else { off == 0 };
    if ok {
        return Outcome::Pass { max_err: worst.0, note: None };
    }
    let (e, i, j, k, got, want) = worst;
    let mut s = format!(
        "max error {e:.3e} at texel ({i}, {j}) {} (ours {got:.6}, MaterialX {want:.6}); {off} of {count} values beyond tolerance",
        names[k]
    );
    if off > 0 {
        let span = |(a, b): (usize, usize), what: &str| {
            if a == b {
                format!("{what} {a}")
            } else {
                format!("{what}s {a}–{b}")
            }
        };
        let _ = write!(s, " (in {}, {})", span(cols, "column"), span(rows, "row"));
    }
    if textured {
        let _ = write!(s, "; mean error {mean:.4} (bound {:.4}, range {range:.3})", IMAGE_MEAN * range);
    }
    Outcome::Fail(s)
}

/// One reference set: a manifest of bakes in the format of `shared/mtlx-suite/manifest.json`.
struct RefSet {
    /// Folder of the manifest; documents and bakes are relative to it.
    root: PathBuf,
    /// How documents are named in the table: this prefix, then the manifest's path.
    prefix: &'static str,
    /// Image search path.
    images: PathBuf,
    /// Known differences: (document suffix, element prefix, note).
    notes: &'static [(&'static str, &'static str, &'static str)],
}

/// What comparing a reference set found.
struct Run {
    /// Rows per document, named with the set's prefix.
    rows: BTreeMap<String, Vec<Row>>,
    /// Entries whose image bound would not reject a v-flipped bake.
    weak: Vec<String>,
    /// The nodedef of each (document, element), where the manifest names one.
    nodedefs: BTreeMap<(String, String), String>,
}

/// Bakes and compares every entry of a reference set.
fn run(set: &RefSet) -> Run {
    let root = &set.root;
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("manifest.json")).unwrap()).unwrap();
    let root_prefix = format!("{}/", root.display());
    let mut docs: BTreeMap<(String, Option<u32>), Result<Document, String>> = BTreeMap::new();
    let mut rows: BTreeMap<String, Vec<Row>> = BTreeMap::new();
    let mut nodedefs = BTreeMap::new();
    let mut weak = Vec::new();
    for b in manifest["bakes"].as_array().unwrap() {
        let doc_path = b["document"].as_str().unwrap().to_string();
        let element = b["element"].as_str().unwrap().to_string();
        let name = format!("{}{doc_path}", set.prefix);
        if let Some(nd) = b["nodedef"].as_str() {
            nodedefs.insert((name.clone(), element.clone()), nd.to_string());
        }
        // The frame the baker's shader saw: its `u_frame`, or frame 0 where its `u_time` is 0
        // (tessera's time is frame / fps). TextureBaker binds neither: they keep their GLSL
        // initializers, recorded per entry.
        let private = &b["shader_private_uniforms"];
        let frame =
            private["u_frame"].as_f64().or_else(|| private["u_time"].as_f64().filter(|t| *t == 0.0)).map(|f| f as f32);
        let opts = LoadOptions { search_paths: vec![set.images.clone()], lenient: true, frame };
        let doc = docs.entry((doc_path.clone(), frame.map(f32::to_bits))).or_insert_with(|| {
            Document::load_with(root.join(&doc_path), &opts).map_err(|e| e.to_string().replace(&root_prefix, ""))
        });
        let outcome = match doc {
            Err(e) => Outcome::Fail(format!("document does not load: {e}")),
            Ok(doc) => {
                // Where the baker's quad lacks what the shader reads, a variant supplies it: the
                // flat frame, or its uv stream as the geometric property `uv`. Where the shader
                // passes explicit gradients, the variant is the same bake without anisotropic
                // filtering, which llvmpipe computes from the quad instead of those gradients.
                let isotropic = b["isotropic_variant"]["bake"].as_str();
                let variant = b["flat_plane_variant"]["bake"]
                    .as_str()
                    .or(b["uv_geomprop_variant"]["bake"].as_str())
                    .or(isotropic);
                let reference = variant.unwrap_or_else(|| b["bake"].as_str().unwrap());
                let img = common::read_exr(&root.join(reference));
                let textured = b.get("texture_files").is_some_and(|v| v.as_array().is_some_and(|a| !a.is_empty()));
                let settings = BakeSettings {
                    filter: if textured { BakeFilter::Texel } else { BakeFilter::Point },
                    orientation: Orientation::MaterialX,
                    ..BakeSettings::new(img.width as u32, img.height as u32)
                };
                let names: Vec<String> =
                    b["channels"].as_array().unwrap().iter().map(|c| c.as_str().unwrap().to_string()).collect();
                match bake::bake_element(doc, &element, &settings) {
                    Ok(baked) => {
                        let trig = inverse_trig(b["nodedef"].as_str(), &doc_path, &element);
                        let tol = if trig { GPU_ASIN_ABS } else { ANALYTIC_TOL };
                        let aa = if textured { None } else { aastep_texels(doc, &element, img.width, img.height) };
                        let mut outcome = match &aa {
                            Some(texels) => {
                                let mut emulated = baked.clone();
                                let n = emulated.channels();
                                for (t, v) in texels {
                                    for (k, x) in v.iter().enumerate().take(n) {
                                        emulated.data[t * n + k] = *x;
                                    }
                                }
                                compare_with(&emulated, &img, &names, textured, tol)
                            }
                            None => compare_with(&baked, &img, &names, textured, tol),
                        };
                        if let (Some(texels), Outcome::Pass { note, .. }) = (&aa, &mut outcome) {
                            *note = Some(format!("{} edge texels compared with MaterialX's aastep", texels.len()));
                        }
                        if let (Some(_), Outcome::Pass { note, .. }) = (isotropic, &mut outcome) {
                            *note = Some("compared with the bake without anisotropic filtering".to_string());
                        }
                        if textured && matches!(outcome, Outcome::Pass { .. }) {
                            // The bound must still tell a v-flipped bake from the right one,
                            // unless the reference itself is nearly symmetric in v.
                            let mut mirrored = baked.clone();
                            let n = baked.channels();
                            for j in 0..img.height {
                                for i in 0..img.width {
                                    for (k, name) in names.iter().enumerate() {
                                        let r = img.channel(name).unwrap();
                                        mirrored.data[(j * img.width + i) * n + k] =
                                            r[(img.height - 1 - j) * img.width + i];
                                    }
                                }
                            }
                            let symmetric = matches!(compare(&mirrored, &img, &names, true), Outcome::Pass { .. });
                            let flipped = bake::bake_element(
                                doc,
                                &element,
                                &BakeSettings { orientation: Orientation::Mitsuba, ..settings },
                            )
                            .unwrap();
                            if !symmetric && matches!(compare(&flipped, &img, &names, true), Outcome::Pass { .. }) {
                                weak.push(format!("{name} {element}"));
                            }
                        }
                        outcome
                    }
                    Err(graph::BakeError::Unavailable { reason, .. }) => {
                        Outcome::Unsupported(reason.replace(&root_prefix, ""))
                    }
                    Err(e) => Outcome::Fail(e.to_string()),
                }
            }
        };
        let outcome = match outcome {
            Outcome::Fail(mut s) => {
                for (d, e, note) in set.notes {
                    if doc_path.ends_with(d) && element.starts_with(e) {
                        let _ = write!(s, ". Known difference: {note}");
                    }
                }
                Outcome::Fail(s)
            }
            o => o,
        };
        rows.entry(name).or_default().push(Row { element, outcome });
    }
    Run { rows, weak, nodedefs }
}

/// Pass, fail and unsupported counts of some rows.
fn counts<'a>(rows: impl Iterator<Item = &'a Row>) -> [usize; 4] {
    let mut c = [0; 4];
    for r in rows {
        c[0] += 1;
        match r.outcome {
            Outcome::Pass { .. } => c[1] += 1,
            Outcome::Fail(_) => c[2] += 1,
            Outcome::Unsupported(_) => c[3] += 1,
        }
    }
    c
}

/// The summary table of a section (`groups`: group name → rows), then its per-document rows.
fn section(md: &mut String, what: &str, groups: &BTreeMap<String, [usize; 4]>, rows: &BTreeMap<String, Vec<Row>>) {
    let _ = writeln!(md, "| {what} | bakes | pass | fail | unsupported |\n|---|---|---|---|---|");
    for (f, c) in groups {
        let _ = writeln!(md, "| {f} | {} | {} | {} | {} |", c[0], c[1], c[2], c[3]);
    }
    for (d, rs) in rows {
        let _ = writeln!(md, "\n### `{d}`\n\n| element | result | detail |\n|---|---|---|");
        for r in rs {
            let (what, detail) = match &r.outcome {
                Outcome::Pass { max_err, note: None } => ("pass", format!("max error {max_err:.1e}")),
                Outcome::Pass { max_err, note: Some(n) } => ("pass", format!("max error {max_err:.1e} ({n})")),
                Outcome::Fail(s) => ("fail", s.clone()),
                Outcome::Unsupported(s) => ("unsupported", s.clone()),
            };
            let _ = writeln!(md, "| `{}` | {what} | {} |", r.element, detail.replace('|', "\\|"));
        }
    }
}

#[test]
fn materialx_conformance() {
    let images = common::shared().join("mtlx-suite/images");
    let suite = RefSet { root: common::shared().join("mtlx-suite"), prefix: "", images: images.clone(), notes: NOTES };
    let own = RefSet {
        root: Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mtlx-refs"),
        prefix: "mtlx-refs/",
        images,
        notes: OWN_NOTES,
    };
    let Run { rows, mut weak, .. } = run(&suite);
    let Run { rows: own_rows, weak: own_weak, nodedefs: own_nodedefs } = run(&own);
    let own_manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(own.root.join("manifest.json")).unwrap()).unwrap();
    let own_resolution = own_manifest["resolution"][0].as_u64().unwrap_or(0);
    weak.extend(own_weak);

    // The table.
    let [total, passed, failed, unsupported] = counts(rows.values().flatten());
    let [own_total, own_passed, own_failed, own_unsupported] = counts(own_rows.values().flatten());
    let mut md = String::new();
    let _ = writeln!(md, "# MaterialX conformance\n");
    let _ = writeln!(
        md,
        "Generated by `cargo test --release -p graph --test verify suite::` (do not edit by hand, except to remove a \
         row whose loss is intended). Every bake of `../shared/mtlx-suite/manifest.json` (MaterialX 1.39.5's \
         own GLSL bakes of its test suite, 128 × 128 over uv [0, 1]², row 0 = v = 1) and of \
         `crates/graph/tests/mtlx-refs/manifest.json` (tessera's own references below) is made with \
         `graph::bake` — what `tessera bake` runs — and compared texel by texel.\n"
    );
    let _ = writeln!(
        md,
        "Tolerances: analytic outputs `|ours − MaterialX| ≤ {ANALYTIC_TOL:e} · max(1, |MaterialX|)` at every \
         texel (point evaluation at texel centres); image-based outputs (texel filter) relative to the reference's \
         range R (at least 0.05): mean error at most {IMAGE_MEAN} R, and at most a fraction {IMAGE_OUTLIERS} of \
         the values beyond {IMAGE_MAX} R (GL's trilinear mip-mapping against exact Gaussian filtering; the \
         same bound rejects v-flipped bakes). Texels MaterialX leaves undefined (NaN) are skipped.\n"
    );
    let _ = writeln!(
        md,
        "One stated exception: bakes whose output is an `asin` or `acos` node (nodedefs `ND_asin_*`, `ND_acos_*`; \
         the shared suite's `asin_*`/`acos_*` graphs of `math/trig.mtlx`) are compared with the absolute tolerance \
         {GPU_ASIN_ABS:e} in place of {ANALYTIC_TOL:e}: Mesa's documented worst-case absolute error of the GLSL \
         `asin` it compiles for llvmpipe (a polynomial in √(1 − |x|): 0.00039, Mesa commit \"glsl: improve the \
         accuracy of the asin() builtin function\"; its NIR `build_asin` keeps the polynomial, and `acos` is π/2 \
         minus one of the same form). GLSL's and Vulkan 1.0's precision \
         tables leave the inverse trigonometric functions undefined; no other function is given more than \
         {ANALYTIC_TOL:e}.\n"
    );
    let _ = writeln!(
        md,
        "A second: `splitlr` and `splittb` in MaterialX's GLSL anti-alias their edge in screen space \
         (`mx_aastep`: `smoothstep(c − a, c + a, x)`, `a` = 0.7071 × the length of the pixel derivatives of the \
         coordinate), about one pixel of the bake wide, which no point evaluation reproduces. For a bake whose \
         output is such a node, the texels where that smoothstep is strictly between 0 and 1 are compared with \
         MaterialX's formula applied to tessera's own values of the node's inputs and of the coordinate's \
         derivatives within GL's 2 × 2 pixel quads; all other texels with tessera's node itself, both within \
         {ANALYTIC_TOL:e}. The table says how many texels each such bake had at its edge.\n"
    );
    let _ = writeln!(
        md,
        "A third concerns the reference: MaterialX binds images with 16× anisotropic filtering, and Mesa's \
         llvmpipe takes that filter's footprint from the lookup coordinate's differences inside each 2 × 2 pixel \
         quad, not from the gradients a shader passes to `textureGrad` (measured: with 16×, `textureGrad` with zero \
         gradients still averages wherever the coordinate jumps inside a quad; with anisotropy 1 it is the level-0 \
         bilinear lookup to 3.6e-3). The hex-tiling shaders pass such gradients and their coordinates jump \
         between tiles inside quads, so their bakes are also made with anisotropy 1 (`isotropic_variant`, \
         `scripts/gl-anisotropy-shim.c`) and compared with that; the table marks them. With 16×, `hextiledimage` \
         differed from tessera by a mean of 0.066 (129 values beyond 0.2 R); without it, by 0.0067 (none).\n"
    );
    let _ = writeln!(
        md,
        "- MaterialX's test suite: **{total} bakes: {passed} pass, {failed} fail, {unsupported} unsupported.**\n\
         - Own references: **{own_total} bakes: {own_passed} pass, {own_failed} fail, {own_unsupported} \
         unsupported** ({:.1} % pass; {:.1} % of the bakes tessera supports).\n",
        100.0 * own_passed as f64 / own_total.max(1) as f64,
        100.0 * own_passed as f64 / (own_passed + own_failed).max(1) as f64
    );
    let _ = writeln!(md, "## MaterialX's test suite\n");
    let mut folders: BTreeMap<String, [usize; 4]> = BTreeMap::new();
    for (d, rs) in &rows {
        let c = counts(rs.iter());
        let f = folders.entry(d.split('/').nth(1).unwrap_or("?").to_string()).or_default();
        for k in 0..4 {
            f[k] += c[k];
        }
    }
    section(&mut md, "folder", &folders, &rows);
    let _ = writeln!(
        md,
        "\n## Own references\n\n\
         `crates/graph/tests/mtlx-refs`: one graph per nodedef of MaterialX 1.39.5's standard library whose output \
         is a value (not a shader, material, matrix, string or filename), every numeric input driven by its own \
         ramp over u or v (`scripts/mtlx-gen-refs.py`), baked {}² by MaterialX's GLSL TextureBaker under Xvfb with \
         Mesa's llvmpipe (`scripts/mtlx-bake-refs.sh`).\n",
        own_resolution
    );
    let group_of: BTreeMap<String, String> =
        crate::coverage::nodedefs().into_iter().map(|nd| (nd.name, nd.nodegroup)).collect();
    let mut groups: BTreeMap<String, [usize; 4]> = BTreeMap::new();
    for (d, rs) in &own_rows {
        for r in rs {
            let nd = own_nodedefs.get(&(d.clone(), r.element.clone()));
            let g = nd.and_then(|n| group_of.get(n)).cloned().unwrap_or_else(|| "?".into());
            let c = counts(std::iter::once(r));
            let f = groups.entry(g).or_default();
            for k in 0..4 {
                f[k] += c[k];
            }
        }
    }
    // The failures by cause: each known difference with the bakes it explains.
    let _ = writeln!(md, "Failures by cause (every failing bake below carries its note):\n");
    for (d, e, note) in OWN_NOTES {
        let n = own_rows
            .iter()
            .filter(|(doc, _)| doc.ends_with(d))
            .flat_map(|(_, rs)| rs)
            .filter(|r| r.element.starts_with(e) && matches!(r.outcome, Outcome::Fail(_)))
            .count();
        if n > 0 {
            let what = if e.is_empty() { format!("`{d}`") } else { format!("`{d}` `{e}`") };
            let _ = writeln!(md, "- {what} ({n}): {note}.");
        }
    }
    let _ = writeln!(md, "\nBy node group:\n");
    section(&mut md, "node group", &groups, &own_rows);
    print!("{md}");

    // Regressions against the committed table.
    let path = table_path();
    let previous = std::fs::read_to_string(&path).unwrap_or_default();
    let mut regressions = Vec::new();
    for (d, e) in previous_passes(&previous) {
        let now = rows
            .get(&d)
            .or_else(|| own_rows.get(&d))
            .and_then(|rs| rs.iter().find(|r| r.element == e))
            .map(|r| &r.outcome);
        if !matches!(now, Some(Outcome::Pass { .. })) {
            regressions.push(format!("{d} {e}: {now:?}"));
        }
    }
    if regressions.is_empty() {
        std::fs::write(&path, &md).unwrap();
    } else {
        let aside = Path::new(env!("CARGO_TARGET_TMPDIR")).join("materialx-conformance.md");
        std::fs::write(&aside, &md).unwrap();
        panic!(
            "bakes that passed no longer do (new table written to {}):\n{}",
            aside.display(),
            regressions.join("\n")
        );
    }
    assert!(weak.is_empty(), "the image bound does not reject v-flipped bakes of: {weak:?}");
    assert!(passed >= MIN_PASS, "only {passed} bakes pass (at least {MIN_PASS} did)");
    assert!(own_passed >= MIN_OWN_PASS, "only {own_passed} own references pass (at least {MIN_OWN_PASS} did)");
}
