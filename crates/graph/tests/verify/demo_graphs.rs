//! The demo scenes' MaterialX graphs (`scenes/*.mtlx`): each loads strictly, every node graph has
//! at least 15 nodes and several octaves of noise, every output evaluates to finite values in its
//! physical range at points and at footprints from sub-texel to whole-object, the patterns are
//! not degenerate, and the scenes (`scenes/*.xml`) only name materials and outputs that exist.
//!
//! Two diagnostics are `#[ignore]`d (run them with `cargo test --release -p graph --test verify
//! -- --ignored --nocapture demo_graphs::NAME`):
//! - `preview` writes PPM swatches of the outputs (left half point-sampled, right half filtered)
//!   and a view of the wood floor through wood_floor.xml's camera, point-sampled and filtered to
//!   each pixel's ray-differential footprint, to `target/demo_previews/`;
//! - `filter_accuracy` prints, for every node, the largest difference between its filtered mean
//!   and a Monte Carlo average of its point values over the same footprint (`DEMO_FILE=x.mtlx`
//!   restricts it to one document).

// Channel loops index several per-channel arrays at once.
#![allow(clippy::needless_range_loop)]

use crate::common;
use glam::{Mat2, Vec2, Vec3};
use graph::{Document, EvalScratch, Filtered, Footprint, Graph, MaterialSource, OutputId, Source, ValueType};
use std::path::{Path, PathBuf};

fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

/// A demo document: its node graphs and materials.
struct Demo {
    file: &'static str,
    graphs: &'static [&'static str],
    materials: &'static [&'static str],
    /// Written here with the filters in mind (thin lines as pulse trains, see `scenes/README.md`).
    /// The untuned ones are built the way graphs are built elsewhere (grout by fract, absval and
    /// smoothstep): every rule holds for them but the filter-accuracy bounds, whose errors are
    /// measured and written to `docs/filtering/demo-graphs.md` without being asserted (a known
    /// gap: moments of a fract taken as Gaussian).
    tuned: bool,
}

const DEMOS: &[Demo] = &[
    Demo { file: "wood_floor.mtlx", graphs: &["NG_wood"], materials: &["M_wood"], tuned: true },
    Demo { file: "marble.mtlx", graphs: &["NG_marble", "NG_marble_tiles"], materials: &["M_marble"], tuned: true },
    Demo { file: "brick_moss.mtlx", graphs: &["NG_brick", "NG_flagstone"], materials: &["M_flagstone"], tuned: true },
    Demo { file: "rusted_metal.mtlx", graphs: &["NG_rust"], materials: &["M_rust"], tuned: true },
    Demo { file: "plane_ramp.mtlx", graphs: &["NG_plane"], materials: &["M_plane"], tuned: false },
    Demo {
        file: "tiles_planks.mtlx",
        graphs: &["NG_tiles", "NG_planks"],
        materials: &["M_tiles", "M_planks"],
        tuned: false,
    },
    Demo { file: "poster_wall.mtlx", graphs: &["NG_poster"], materials: &["M_poster"], tuned: true },
];

/// The scenes and the documents they use.
const SCENES: &[(&str, &str)] = &[
    ("wood_floor.xml", "wood_floor.mtlx"),
    ("marble.xml", "marble.mtlx"),
    ("brick_moss.xml", "brick_moss.mtlx"),
    ("rusted_metal.xml", "rusted_metal.mtlx"),
    ("plane_ramp.xml", "plane_ramp.mtlx"),
    ("tiles_planks.xml", "tiles_planks.mtlx"),
    ("poster_wall.xml", "poster_wall.mtlx"),
];

fn load(file: &str) -> Document {
    let path = scenes_dir().join(file);
    Document::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Nodes of nodegraph `g`.
fn graph_nodes<'a>(g: &'a Graph, name: &'a str) -> impl Iterator<Item = graph::NodeId> + 'a {
    let prefix = format!("{name}/");
    g.node_ids().filter(move |id| g.node_name(*id).starts_with(&prefix))
}

fn constant_input(g: &Graph, id: graph::NodeId, input: &str) -> Option<f32> {
    g.node_inputs(id).into_iter().find(|(n, _)| *n == input).and_then(|(_, s)| match s {
        Source::Constant(v) => Some(v.v[0]),
        _ => None,
    })
}

/// Footprints from a point to several times the whole uv square, including grazing ones
/// (long along one axis, short along the other, rotated).
fn footprints(uv: Vec2) -> Vec<Footprint> {
    let mut v = vec![Footprint::point(uv)];
    for sigma in [1e-5, 1e-4, 1e-3, 4e-3, 0.02, 0.1, 0.5, 3.0] {
        v.push(Footprint::isotropic(uv, sigma));
    }
    for (long, short, angle) in [(0.05f32, 1e-4f32, 0.3f32), (0.4, 2e-3, 1.2), (2e-3, 1e-5, 2.5), (1.5, 0.01, -0.7)] {
        let r = Mat2::from_angle(angle);
        let d = Mat2::from_diagonal(Vec2::new(long * long, short * short));
        v.push(Footprint::new(uv, r * d * r.transpose()));
    }
    v
}

fn uv_points() -> Vec<Vec2> {
    let mut v = vec![Vec2::ZERO, Vec2::ONE, Vec2::new(0.5, 0.5), Vec2::new(1e-4, 0.9999), Vec2::new(0.999, 0.001)];
    let mut x = 0.1234f32;
    for _ in 0..12 {
        // Deterministic scatter (a Weyl sequence).
        x = (x + 0.618_034).fract();
        let y = (x * 7.31 + 0.17).fract();
        v.push(Vec2::new(x, y));
    }
    v
}

fn check_finite(name: &str, fp: &Footprint, f: &Filtered) {
    for c in 0..f.n() {
        let m = f.ch[c];
        assert!(
            m.mean.is_finite() && m.grad.is_finite() && m.var.is_finite(),
            "{name} channel {c} at uv {:?}, cov {:?}: non-finite {m:?}",
            fp.uv,
            fp.cov
        );
        assert!(m.var >= -1e-6, "{name} channel {c} at uv {:?}, cov {:?}: negative variance {m:?}", fp.uv, fp.cov);
    }
}

#[test]
fn demo_documents_load_strictly_with_at_least_15_nodes_per_graph() {
    for d in DEMOS {
        let doc = load(d.file);
        assert!(doc.skipped().is_empty(), "{}: skipped outputs {:?}", d.file, doc.skipped());
        let g = doc.graph();
        let listed: usize = d.graphs.iter().map(|name| graph_nodes(g, name).count()).sum();
        assert_eq!(listed, g.node_count(), "{}: nodes outside the listed node graphs", d.file);
        for name in d.graphs {
            let n = graph_nodes(g, name).count();
            println!("{}: {name}: {n} nodes", d.file);
            assert!(n >= 15, "{}: {name} has only {n} nodes", d.file);
            assert!(g.outputs().iter().any(|o| o.name.starts_with(&format!("{name}/"))), "{name} has no outputs");
        }
    }
}

#[test]
fn demo_graphs_use_several_octaves_of_noise() {
    for d in DEMOS {
        let doc = load(d.file);
        let g = doc.graph();
        for name in d.graphs {
            let mut fractals = 0;
            for id in graph_nodes(g, name) {
                match g.node_category(id) {
                    "fractal2d" => {
                        let octaves = constant_input(g, id, "octaves").expect("constant octaves");
                        assert!(octaves >= 4.0, "{}: {} has {octaves} octaves", d.file, g.node_name(id));
                        fractals += 1;
                    }
                    "noise2d" => panic!("{}: use fractal2d, not single-octave noise2d ({})", d.file, g.node_name(id)),
                    _ => {}
                }
            }
            assert!(fractals >= 2, "{}: {name} has {fractals} fractal2d nodes", d.file);
        }
    }
}

#[test]
fn demo_outputs_are_finite_and_in_range_at_every_footprint() {
    for d in DEMOS {
        let doc = load(d.file);
        let g = doc.graph();
        let mut scratch = EvalScratch::new(g);
        for o in g.outputs() {
            let id = g.output_id(&o.name).unwrap();
            // Colours are reflectances; the float outputs are weights, roughnesses, masks.
            let (lo, hi) = (0.0, 1.0);
            for uv in uv_points() {
                for fp in footprints(uv) {
                    let f = g.eval_output(id, &fp, &mut scratch);
                    assert_eq!(f.n(), o.ty.channels(), "{}", o.name);
                    check_finite(&o.name, &fp, &f);
                    for c in 0..f.n() {
                        let m = f.ch[c].mean;
                        assert!(
                            m >= lo - 2e-3 && m <= hi + 2e-3,
                            "{}: {} channel {c} = {m} outside [{lo}, {hi}] at uv {:?}, cov {:?}",
                            d.file,
                            o.name,
                            fp.uv,
                            fp.cov
                        );
                    }
                }
            }
        }
    }
}

/// A deterministic xorshift stream of uniform and normal variates.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 40) as f32 + 0.5) / (1u64 << 24) as f32
    }
    fn normal2(&mut self) -> Vec2 {
        let (a, b) = (self.uniform(), self.uniform());
        let r = (-2.0 * a.ln()).sqrt();
        let t = std::f32::consts::TAU * b;
        Vec2::new(r * t.cos(), r * t.sin())
    }
}

/// Mean and standard deviation of channel `c` of point values at `n` uv points drawn by `draw`.
fn point_stats(
    g: &Graph,
    out: OutputId,
    c: usize,
    n: usize,
    scratch: &mut EvalScratch,
    mut draw: impl FnMut() -> Vec2,
) -> (f64, f64) {
    let (mut s, mut s2) = (0.0f64, 0.0f64);
    for _ in 0..n {
        let v = g.eval_output(out, &Footprint::point(draw()), scratch).ch[c].mean as f64;
        s += v;
        s2 += v * v;
    }
    let k = n as f64;
    (s / k, (s2 / k - (s / k).powi(2)).max(0.0).sqrt())
}

/// Every output varies over the surface (random points, not a grid, which would alias with the
/// patterns' periods), and a footprint much wider than the surface filters it to the average of
/// point values over that same Gaussian footprint (Monte Carlo).
#[test]
fn demo_patterns_vary_and_blur_towards_their_average() {
    for d in DEMOS {
        let doc = load(d.file);
        let g = doc.graph();
        let mut scratch = EvalScratch::new(g);
        for o in g.outputs() {
            let id = g.output_id(&o.name).unwrap();
            for c in 0..o.ty.channels() {
                let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
                let (_, sd) = point_stats(g, id, c, 20_000, &mut scratch, || Vec2::new(rng.uniform(), rng.uniform()));
                let centre = Vec2::new(0.5, 0.5);
                let sigma = 3.0;
                let wide = g.eval_output(id, &Footprint::isotropic(centre, sigma), &mut scratch).ch[c];
                let mut rng = Rng(0x2545_f491_4f6c_dd1d);
                let (mc, mc_sd) = point_stats(g, id, c, 40_000, &mut scratch, || centre + rng.normal2() * sigma);
                println!(
                    "{:<30} ch{c}: sd over the surface {sd:.3}; sigma {sigma}: filtered {:.3} (sd {:.3}), points {mc:.3} (sd {mc_sd:.3})",
                    o.name,
                    wide.mean,
                    wide.sigma()
                );
                assert!(sd > 0.01, "{}: {} channel {c} hardly varies (sd {sd})", d.file, o.name);
                assert!(
                    !d.tuned || (wide.mean as f64 - mc).abs() < 0.05,
                    "{}: {} channel {c}: filtered over a wide footprint {} but its points average {mc}",
                    d.file,
                    o.name,
                    wide.mean
                );
            }
        }
    }
}

/// Every output of every demo graph, filtered, against brute-force Gaussian supersampling (2048
/// unfiltered values per footprint, 12 random anisotropic footprints per σ, centres on the
/// surface's uv square), σ from 1e-6 to 10 uv units; the table goes to
/// `docs/filtering/demo-graphs.md`. Asserted: at σ = 1e-6 the filtered value is the unfiltered
/// one (mean error below 2e-3; the wood's grain is fine enough that 1e-4 uv already blurs it);
/// wherever point sampling errs by more than 0.01 the filtered error is at most `RATIO` of its
/// error, and at most `COARSE_RATIO` at σ ≥ 0.3 uv, where every pattern repeats many times
/// within the footprint. Measured: worst 0.48 (flagstone roughness at σ 0.1, where
/// bright wet patches are thresholded from noise) and 0.16 at σ ≥ 0.3.
#[test]
fn demo_graphs_filtered_match_supersampling() {
    const RATIO: f64 = 0.5;
    const COARSE_RATIO: f64 = 0.2;
    let mut failures = Vec::new();
    let mut sweeps = Vec::new();
    println!("{}", common::sweep_header());
    for (di, d) in DEMOS.iter().enumerate() {
        let doc = load(d.file);
        let g = doc.graph();
        for (oi, o) in g.outputs().iter().enumerate() {
            let id = g.output_id(&o.name).unwrap();
            let seed = 0x5eed_0000 ^ ((di as u64) << 8) ^ oi as u64;
            let rows = common::sweep(g, id, &common::SWEEP_SIGMAS, seed, 12, 2048, |rng| {
                Vec2::new(rng.uniform() as f32, rng.uniform() as f32)
            });
            let name = format!("{} {}", d.file.trim_end_matches(".mtlx"), o.name);
            for r in &rows {
                println!("{}", common::sweep_line(&name, r));
                if r.sigma <= 1e-6 && r.filtered > 2e-3 {
                    failures
                        .push(format!("{name} σ={}: filtered error {:.2e} at a tiny footprint", r.sigma, r.filtered));
                }
                let bound = if r.sigma >= 0.3 { COARSE_RATIO } else { RATIO };
                if d.tuned && r.point > 0.01 && r.ratio() > bound {
                    failures.push(format!("{name} σ={}: error ratio {:.3} > {bound}", r.sigma, r.ratio()));
                }
            }
            let label = if d.tuned { "" } else { " (untuned: not asserted)" };
            sweeps.push((format!("{} `{}`{label}", d.file, o.name), rows));
        }
    }
    common::write_doc(
        "filtering/demo-graphs.md",
        &format!(
            "# The demo graphs filtered against supersampling\n\n\
             Written by `crates/graph/tests/verify/demo_graphs.rs` (`demo_graphs_filtered_match_supersampling`): \
             every output of the demo scenes' documents (`scenes/*.mtlx`). Each cell: mean absolute \
             error of the filtered value / of point sampling (the unfiltered value at the centre), both \
             against the mean of 2048 unfiltered values over the Gaussian footprint, over 12 random \
             centres in the surface's uv square [0, 1]² and all channels; in brackets their ratio. \
             Footprints are anisotropic (aspect 0.25–1, random angle); σ is the long axis in uv \
             units (the wood floor's uv square is 600 planks across, so its grain is already \
             blurred at 1e-4). Asserted: at σ = 1e-6 the filtered error is below 2e-3; wherever \
             point sampling errs by more than 0.01 the ratio is at most {RATIO}, and at most \
             {COARSE_RATIO} at σ ≥ 0.3, for the scenes written for the filters. The untuned scenes \
             (`plane_ramp`, `tiles_planks`, built the way graphs are built elsewhere) are measured \
             the same way, and only their tiny-footprint error is asserted: their grout, a fract \
             through absval and smoothstep, is filtered as if the fract's output were Gaussian, \
             which at wide footprints misjudges how much of the floor is grout.\n\n{}",
            common::sweep_markdown(&sweeps)
        ),
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn demo_materials_bind_graph_outputs() {
    for d in DEMOS {
        let doc = load(d.file);
        for m in d.materials {
            let b = doc.material(m).unwrap_or_else(|| panic!("{}: no material {m}", d.file));
            assert!(b.warnings.is_empty(), "{}: {m}: {:?}", d.file, b.warnings);
            for input in ["base_color", "specular_roughness"] {
                assert!(
                    matches!(b.get(input), Some(MaterialSource::Output(_))),
                    "{}: {m}.{input} is not a graph output: {:?}",
                    d.file,
                    b.get(input)
                );
            }
            for (input, src) in &b.inputs {
                if let MaterialSource::Output(o) = src {
                    let ty = doc.graph().output(*o).ty;
                    let want = if *input == "base_color" || *input == "specular_color" {
                        ValueType::Color3
                    } else {
                        ValueType::Float
                    };
                    assert_eq!(ty, want, "{}: {m}.{input}", d.file);
                }
            }
        }
    }
}

fn attr<'a>(n: roxmltree::Node<'a, '_>, child: &str) -> Option<&'a str> {
    n.children().find(|c| c.is_element() && c.attribute("name") == Some(child)).and_then(|c| c.attribute("value"))
}

#[test]
fn demo_scenes_follow_the_rules_and_name_existing_materials() {
    let allowed_shapes = ["rectangle", "sphere", "cube", "disk"];
    for (scene, mtlx) in SCENES {
        let path = scenes_dir().join(scene);
        let text = std::fs::read_to_string(&path).unwrap();
        let xml = roxmltree::Document::parse(&text).unwrap_or_else(|e| panic!("{scene}: {e}"));
        let root = xml.root_element();
        let default = |name: &str| {
            root.children()
                .find(|c| c.has_tag_name("default") && c.attribute("name") == Some(name))
                .and_then(|c| c.attribute("value"))
        };
        assert_eq!(default("spp"), Some("16"), "{scene}");
        assert_eq!(default("res"), Some("256"), "{scene}");
        let mut uses = 0;
        for n in root.descendants().filter(|n| n.is_element()) {
            let ty = n.attribute("type").unwrap_or("");
            match n.tag_name().name() {
                "shape" => assert!(allowed_shapes.contains(&ty), "{scene}: shape {ty}"),
                "emitter" => assert!(ty == "area" || ty == "constant", "{scene}: emitter {ty}"),
                "texture" => assert_eq!(ty, "mtlx", "{scene}: texture {ty}"),
                "integrator" => {
                    assert_eq!(ty, "path");
                    assert_eq!(attr(n, "max_depth"), Some("8"), "{scene}");
                }
                "sampler" => assert_eq!(attr(n, "sample_count"), Some("$spp"), "{scene}"),
                "film" => {
                    assert_eq!(attr(n, "width"), Some("$res"), "{scene}");
                    assert_eq!(attr(n, "height"), Some("$res"), "{scene}");
                }
                "rfilter" => assert!(ty == "box" || ty == "gaussian", "{scene}: rfilter {ty}"),
                _ => {}
            }
            if !(n.has_tag_name("bsdf") || n.has_tag_name("texture")) || ty != "mtlx" {
                continue;
            }
            uses += 1;
            let file = attr(n, "filename").unwrap_or_else(|| panic!("{scene}: mtlx without filename"));
            assert_eq!(file, *mtlx, "{scene}");
            let doc = load(file);
            if n.has_tag_name("bsdf") {
                let m = attr(n, "material").unwrap_or_else(|| panic!("{scene}: mtlx bsdf without material"));
                assert!(doc.material(m).is_some(), "{scene}: {file} has no material {m}");
            } else {
                let out = attr(n, "output").unwrap_or_else(|| panic!("{scene}: mtlx texture without output"));
                let id = doc.graph().output_id(out).unwrap_or_else(|| panic!("{scene}: {file} has no output {out}"));
                let want = match n.attribute("name") {
                    Some("reflectance") => ValueType::Color3,
                    _ => ValueType::Float,
                };
                assert_eq!(doc.graph().output(id).ty, want, "{scene}: {out}");
            }
        }
        assert!(uses > 0, "{scene} uses no MaterialX material");
        for bad in ["bitmap", ".exr", ".png", ".obj", ".ply", "envmap"] {
            assert!(!text.contains(bad), "{scene} mentions {bad}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Previews (ignored by default).

fn write_ppm(path: &Path, w: usize, h: usize, rgb: &[Vec3]) {
    let mut bytes = format!("P6\n{w} {h}\n255\n").into_bytes();
    for c in rgb {
        for x in c.to_array() {
            let x = x.clamp(0.0, 1.0);
            let s = if x <= 0.0031308 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 };
            bytes.push((s * 255.0 + 0.5) as u8);
        }
    }
    std::fs::write(path, bytes).unwrap();
}

fn rgb(f: &Filtered) -> Vec3 {
    if f.n() == 1 {
        Vec3::splat(f.ch[0].mean)
    } else {
        Vec3::new(f.ch[0].mean, f.ch[1].mean, f.ch[2].mean)
    }
}

/// Swatch windows: (output, uv origin, uv size) — about 2 m of each surface, or all of it.
const SWATCHES: &[(&str, &str, [f32; 2], f32)] = &[
    ("wood_floor.mtlx", "NG_wood/out_color", [0.5, 0.5], 2.0 / 120.0),
    ("wood_floor.mtlx", "NG_wood/out_roughness", [0.5, 0.5], 2.0 / 120.0),
    ("marble.mtlx", "NG_marble/out_color", [0.0, 0.0], 1.0),
    ("marble.mtlx", "NG_marble_tiles/out_color", [0.25, 0.25], 0.25),
    ("brick_moss.mtlx", "NG_brick/out_color", [0.0, 0.0], 1.0),
    ("brick_moss.mtlx", "NG_brick/out_color", [0.3, 0.0], 0.25),
    ("brick_moss.mtlx", "NG_flagstone/out_color", [0.0, 0.0], 1.0),
    ("brick_moss.mtlx", "NG_flagstone/out_roughness", [0.0, 0.0], 1.0),
    ("rusted_metal.mtlx", "NG_rust/out_color", [0.0, 0.0], 1.0),
    ("rusted_metal.mtlx", "NG_rust/out_roughness", [0.0, 0.0], 1.0),
    ("rusted_metal.mtlx", "NG_rust/out_metalness", [0.0, 0.0], 1.0),
];

#[test]
#[ignore]
fn preview() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/demo_previews");
    std::fs::create_dir_all(&dir).unwrap();
    let n = 256;
    for (file, out, origin, size) in SWATCHES {
        let doc = load(file);
        let g = doc.graph();
        let id = g.output_id(out).unwrap();
        let mut scratch = EvalScratch::new(g);
        // Left half point-sampled, right half filtered to a 4-pixel Gaussian.
        let px = size / n as f32;
        let mut img = vec![Vec3::ZERO; n * n];
        for y in 0..n {
            for x in 0..n {
                let uv = Vec2::new(
                    origin[0] + (x as f32 + 0.5) * px,
                    origin[1] + (1.0 - (y as f32 + 0.5) / n as f32) * size,
                );
                let fp = if x < n / 2 { Footprint::point(uv) } else { Footprint::isotropic(uv, 4.0 * px) };
                img[y * n + x] = rgb(&g.eval_output(id, &fp, &mut scratch));
            }
        }
        let name = format!("{}_{}", out.replace('/', "_"), (size * 1000.0) as u32);
        write_ppm(&dir.join(format!("{name}.ppm")), n, n, &img);
    }
    // The wood floor as wood_floor.xml's camera sees it (no lighting): point-sampled with one
    // ray per pixel, and filtered to each pixel's ray-differential footprint.
    let doc = load("wood_floor.mtlx");
    let g = doc.graph();
    let id = g.output_id("NG_wood/out_color").unwrap();
    let mut scratch = EvalScratch::new(g);
    let origin = Vec3::new(0.0, 0.45, 57.0);
    let fwd = (Vec3::new(-0.1977, 0.1410, 56.0697) - origin).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let tan_half = (45.0f32.to_radians() / 2.0).tan();
    let hit = |sx: f32, sy: f32| -> Option<Vec2> {
        let d = fwd + right * (sx * tan_half) + up * (sy * tan_half);
        if d.y >= 0.0 {
            return None;
        }
        let t = -origin.y / d.y;
        let p = origin + d * t;
        // Rectangle scaled by 60, rotated -90 about x: local (x, y) = (p.x, -p.z) / 60.
        let uv = Vec2::new((p.x / 60.0 + 1.0) / 2.0, (-p.z / 60.0 + 1.0) / 2.0);
        (uv.x.abs() <= 1.0 && uv.y.abs() <= 1.0).then_some(uv)
    };
    for filtered in [false, true] {
        let mut img = vec![Vec3::new(0.35, 0.45, 0.65); n * n];
        for y in 0..n {
            for x in 0..n {
                let s = |x: f32, y: f32| (2.0 * x / n as f32 - 1.0, 1.0 - 2.0 * y / n as f32);
                let (sx, sy) = s(x as f32 + 0.5, y as f32 + 0.5);
                let Some(uv) = hit(sx, sy) else { continue };
                let fp = if filtered {
                    let (ax, ay) = s(x as f32 + 1.5, y as f32 + 0.5);
                    let (bx, by) = s(x as f32 + 0.5, y as f32 + 1.5);
                    let (Some(ux), Some(uy)) = (hit(ax, ay), hit(bx, by)) else { continue };
                    // Pixel footprint: a Gaussian of 0.5 pixel standard deviation.
                    let j = Mat2::from_cols(ux - uv, uy - uv) * 0.5;
                    Footprint::new(uv, j * j.transpose())
                } else {
                    Footprint::point(uv)
                };
                img[y * n + x] = rgb(&g.eval_output(id, &fp, &mut scratch));
            }
        }
        let name = if filtered { "wood_view_filtered" } else { "wood_view_point" };
        write_ppm(&dir.join(format!("{name}.ppm")), n, n, &img);
    }
}

/// Per node (channel 0): the largest difference, over four footprint centres, between the
/// filtered mean and the Monte Carlo average of point values over the same isotropic footprint,
/// for footprints of 3e-4 to 0.3 uv units, and the σ the node reports against the points'
/// spread (averaged over the centres). A diagnostic of the filter on real graphs.
#[test]
#[ignore]
fn filter_accuracy() {
    use graph::NoOverride;
    let only = std::env::var("DEMO_FILE").ok();
    for d in DEMOS {
        if only.as_deref().is_some_and(|f| f != d.file) {
            continue;
        }
        let doc = load(d.file);
        let g = doc.graph();
        let mut scratch = EvalScratch::new(g);
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        for id in g.node_ids() {
            let mut line = format!("{:<36} {:<13}", g.node_name(id), g.node_category(id));
            for sigma in [3e-4f32, 3e-3, 0.03, 0.3] {
                let (mut worst, mut pair) = (0.0f64, (0.0, 0.0));
                let (mut sd_node, mut sd_mc) = (0.0f64, 0.0f64);
                for k in 0..4 {
                    let uv = Vec2::new(0.31 + 0.17 * k as f32, 0.43 + 0.11 * k as f32);
                    let f = g.eval_node_direct(id, &Footprint::isotropic(uv, sigma), &mut scratch, &NoOverride);
                    let n = 3000;
                    let (mut s, mut s2) = (0.0f64, 0.0f64);
                    for _ in 0..n {
                        let p = Footprint::point(uv + rng.normal2() * sigma);
                        let v = g.eval_node_direct(id, &p, &mut scratch, &NoOverride).ch[0].mean as f64;
                        s += v;
                        s2 += v * v;
                    }
                    let mc = s / n as f64;
                    sd_mc += (s2 / n as f64 - mc * mc).max(0.0).sqrt() / 4.0;
                    sd_node += f.ch[0].sigma() as f64 / 4.0;
                    let f = f.ch[0].mean as f64;
                    if (f - mc).abs() >= worst {
                        (worst, pair) = ((f - mc).abs(), (f, mc));
                    }
                }
                line +=
                    &format!(" | {sigma:.0e}: {worst:.3} ({:.3} vs {:.3}) σ {sd_node:.3}/{sd_mc:.3}", pair.0, pair.1);
            }
            println!("{line}");
        }
    }
}
