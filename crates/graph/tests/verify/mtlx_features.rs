//! MaterialX document features: custom nodedefs implemented by node graphs, interfaces through
//! any depth, version upgrades, includes, file prefixes, colour spaces, uniform and enum inputs;
//! and the errors bad documents give (each naming its file and line).

use crate::common;
use glam::Vec2;
use graph::{Document, EvalScratch, Footprint, LoadError, LoadErrorKind, LoadOptions, MaterialSource};
use std::path::{Path, PathBuf};

/// A fresh folder for one test's files, removed when the test is done.
fn dir(name: &str) -> crate::common::TestDir {
    crate::common::TestDir::new(&format!("features-{name}"))
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// A document of `version` around `body`.
fn doc(version: &str, body: &str) -> String {
    format!("<?xml version=\"1.0\"?>\n<materialx version=\"{version}\" xmlns:xi=\"http://www.w3.org/2001/XInclude\">\n{body}\n</materialx>\n")
}

/// Output `name` of `doc` evaluated unfiltered at `uv`.
fn eval(doc: &Document, name: &str, uv: Vec2) -> Vec<f32> {
    eval_at(doc, name, &Footprint::point(uv))
}

/// The filtered mean of output `name` of `doc` over footprint `fp`, per channel.
fn eval_at(doc: &Document, name: &str, fp: &Footprint) -> Vec<f32> {
    let g = doc.graph();
    let out = g.output_id(name).unwrap_or_else(|| {
        let names: Vec<&str> = g.outputs().iter().map(|o| o.name.as_str()).collect();
        panic!("no output {name}; have {names:?}; skipped {:?}", doc.skipped())
    });
    let mut scratch = EvalScratch::new(g);
    let v = g.eval_output(out, fp, &mut scratch);
    (0..g.output(out).ty.channels()).map(|k| v.ch[k].mean).collect()
}

fn close(a: &[f32], b: &[f32], tol: f32) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

/// The 1-based line of the first line of `path` containing `needle`.
fn line_of(path: &Path, needle: &str) -> u32 {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines().position(|l| l.contains(needle)).expect(needle) as u32 + 1
}

fn expect_error(path: &Path, line: u32) -> LoadError {
    let e = Document::load(path).expect_err("the document should not load");
    assert_eq!(e.location.file, path, "{e}");
    assert_eq!(e.location.line, line, "{e}");
    assert!(e.to_string().starts_with(&format!("{}:{line}:", path.display())), "{e}");
    println!("{e}");
    e
}

const SCALE_DEFS: &str = r#"
  <nodedef name="ND_scaleoffset_float" node="scaleoffset" nodegroup="math">
    <input name="in" type="float" value="0.0" />
    <input name="scale" type="float" value="2.0" />
    <input name="offset" type="float" value="0.25" />
    <output name="out" type="float" />
  </nodedef>
  <nodegraph name="NG_scaleoffset_float" nodedef="ND_scaleoffset_float">
    <multiply name="m" type="float">
      <input name="in1" type="float" interfacename="in" />
      <input name="in2" type="float" interfacename="scale" />
    </multiply>
    <add name="a" type="float">
      <input name="in1" type="float" nodename="m" />
      <input name="in2" type="float" interfacename="offset" />
    </add>
    <output name="out" type="float" nodename="a" />
  </nodegraph>
  <nodedef name="ND_uvsplit" node="uvsplit">
    <input name="coord" type="vector2" defaultgeomprop="UV0" />
    <input name="gain" type="float" value="1.0" />
    <output name="u" type="float" />
    <output name="v" type="float" />
  </nodedef>
  <nodegraph name="NG_uvsplit" nodedef="ND_uvsplit">
    <separate2 name="sep" type="multioutput">
      <input name="in" type="vector2" interfacename="coord" />
    </separate2>
    <scaleoffset name="su" type="float">
      <input name="in" type="float" nodename="sep" output="outx" />
      <input name="scale" type="float" interfacename="gain" />
      <input name="offset" type="float" value="0.0" />
    </scaleoffset>
    <scaleoffset name="sv" type="float">
      <input name="in" type="float" nodename="sep" output="outy" />
      <input name="scale" type="float" interfacename="gain" />
      <input name="offset" type="float" value="0.0" />
    </scaleoffset>
    <output name="u" type="float" nodename="su" />
    <output name="v" type="float" nodename="sv" />
  </nodegraph>
"#;

#[test]
fn custom_nodedefs_expand_nested_and_multi_output() {
    let d = dir("custom");
    let body = format!(
        r#"{SCALE_DEFS}
  <input name="doc_gain" type="float" value="3.0" />
  <nodegraph name="g">
    <input name="gain" type="float" interfacename="doc_gain" />
    <scaleoffset name="defaults" type="float">
      <input name="in" type="float" value="1.0" />
    </scaleoffset>
    <scaleoffset name="set" type="float">
      <input name="in" type="float" value="1.0" />
      <input name="scale" type="float" value="-1.0" />
      <input name="offset" type="float" nodename="defaults" />
    </scaleoffset>
    <uvsplit name="split" type="multioutput">
      <input name="gain" type="float" interfacename="gain" />
    </uvsplit>
    <output name="defaults" type="float" nodename="defaults" />
    <output name="set" type="float" nodename="set" />
    <output name="u" type="float" nodename="split" output="u" />
    <output name="v" type="float" nodename="split" output="v" />
  </nodegraph>"#
    );
    let p = write(&d, "custom.mtlx", &doc("1.39", &body));
    let doc = Document::load(&p).unwrap();
    let uv = Vec2::new(0.3, 0.7);
    // Defaults from the nodedef: 1 · 2 + 0.25.
    assert!(close(&eval(&doc, "g/defaults", uv), &[2.25], 1e-6));
    // Set inputs, one connected to another instance: 1 · −1 + 2.25.
    assert!(close(&eval(&doc, "g/set", uv), &[1.25], 1e-6));
    // Multi-output, nested definition, defaultgeomprop UV0, gain through three interfaces
    // (instance → graph input → top-level input).
    assert!(close(&eval(&doc, "g/u", uv), &[0.9], 1e-6));
    assert!(close(&eval(&doc, "g/v", uv), &[2.1], 1e-5));
    // The implementation graphs are content of their own, with the nodedef's defaults.
    assert!(close(&eval(&doc, "NG_scaleoffset_float/out", uv), &[0.25], 1e-6));
    assert!(close(&eval(&doc, "NG_uvsplit/v", uv), &[0.7], 1e-6));
    // Instance nodes are named after their instance.
    assert!(doc.graph().node_id("g/split/su/m").is_some());
}

#[test]
fn versions_1_36_to_1_38_are_upgraded() {
    let d = dir("versions");
    let v136 = doc(
        "1.36",
        r#"  <nodegraph name="g">
    <combine name="c" type="vector3">
      <parameter name="in1" type="float" value="0.1" />
      <parameter name="in2" type="float" value="0.2" />
      <parameter name="in3" type="float" value="0.3" />
    </combine>
    <atan2 name="t" type="float">
      <input name="in1" type="float" value="1.0" />
      <input name="in2" type="float" value="2.0" />
    </atan2>
    <constant name="k" type="color2">
      <input name="value" type="color2" value="0.25, 0.75" />
    </constant>
    <output name="c" type="vector3" nodename="c" />
    <output name="t" type="float" nodename="t" />
    <output name="k" type="vector2" nodename="k" />
    <constant name="cc" type="color3">
      <parameter name="value" type="color3" value="0.1, 0.2, 0.3" />
    </constant>
    <output name="col" type="color3" nodename="cc" />
  </nodegraph>
  <material name="M">
    <shaderref name="SR" node="standard_surface">
      <bindinput name="base_color" type="color3" nodegraph="g" output="col" />
      <bindparam name="metalness" type="float" value="0.5" />
    </shaderref>
  </material>"#,
    );
    let p = write(&d, "v136.mtlx", &v136);
    let doc136 = Document::load(&p).unwrap();
    let uv = Vec2::new(0.5, 0.5);
    assert!(close(&eval(&doc136, "g/c", uv), &[0.1, 0.2, 0.3], 1e-6));
    // 1.36/1.37's atan2(in1, in2) became atan2(iny = in2, inx = in1).
    assert!(close(&eval(&doc136, "g/t", uv), &[2.0f32.atan2(1.0)], 1e-6));
    assert!(close(&eval(&doc136, "g/k", uv), &[0.25, 0.75], 1e-6));
    // A `<material>` with a `<shaderref>` is a material bound to a standard_surface.
    let m = doc136.material("M").expect("material M");
    assert_eq!(m.shader, "SR");
    assert_eq!(m.get("base_color"), Some(&MaterialSource::Output(doc136.graph().output_id("g/col").unwrap())));
    assert!(matches!(m.get("metalness"), Some(MaterialSource::Constant(v)) if v.v[0] == 0.5));

    let v138 = doc(
        "1.38",
        r#"  <nodegraph name="g">
    <constant name="c" type="color4">
      <input name="value" type="color4" value="0.1, 0.2, 0.3, 0.4" />
    </constant>
    <texcoord name="tc" type="vector2" />
    <swizzle name="s" type="color3">
      <input name="in" type="color4" nodename="c" />
      <input name="channels" type="string" value="ab1" />
    </swizzle>
    <add name="a" type="float">
      <input name="in1" type="float" nodename="tc" channels="y" />
      <input name="in2" type="float" value="1.0" />
    </add>
    <atan2 name="t" type="float">
      <input name="in1" type="float" value="1.0" />
      <input name="in2" type="float" value="2.0" />
    </atan2>
    <output name="s" type="color3" nodename="s" />
    <output name="a" type="float" nodename="a" />
    <output name="t" type="float" nodename="t" />
    <output name="sw" type="vector3" nodename="tc" channels="yx0" />
  </nodegraph>"#,
    );
    let p = write(&d, "v138.mtlx", &v138);
    let doc138 = Document::load(&p).unwrap();
    let uv = Vec2::new(0.25, 0.625);
    assert!(close(&eval(&doc138, "g/s", uv), &[0.4, 0.3, 1.0], 1e-6));
    assert!(close(&eval(&doc138, "g/a", uv), &[1.625], 1e-6));
    // 1.38's atan2(in1, in2) is atan2(iny = in1, inx = in2).
    assert!(close(&eval(&doc138, "g/t", uv), &[1.0f32.atan2(2.0)], 1e-6));
    assert!(close(&eval(&doc138, "g/sw", uv), &[0.625, 0.25, 0.0], 1e-6));

    // Normal maps: object space becomes normalize(2·in − 1); a tangent-space map's unbound frame
    // literals give way to the geometric frame (here the flat quad's: T = +x, B = +y, N = +z).
    let nm = doc(
        "1.38",
        r#"  <nodegraph name="g">
    <normalmap name="obj" type="vector3">
      <input name="in" type="vector3" value="0.9, 0.3, 0.6" />
      <input name="space" type="string" value="object" />
    </normalmap>
    <normalmap name="tan" type="vector3">
      <input name="in" type="vector3" value="0.9, 0.3, 0.6" />
      <input name="space" type="string" value="tangent" />
      <input name="tangent" type="vector3" value="0, 1, 0" />
      <input name="bitangent" type="vector3" value="1, 0, 0" />
    </normalmap>
    <output name="obj" type="vector3" nodename="obj" />
    <output name="tan" type="vector3" nodename="tan" />
  </nodegraph>"#,
    );
    let p = write(&d, "normalmap138.mtlx", &nm);
    let docnm = Document::load(&p).unwrap();
    let v = [0.8f32, -0.4, 0.2];
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let want: Vec<f32> = v.iter().map(|x| x / len).collect();
    assert!(close(&eval(&docnm, "g/obj", uv), &want, 1e-5), "{:?}", eval(&docnm, "g/obj", uv));
    // Same components: the swapped literal tangent and bitangent were dropped.
    assert!(close(&eval(&docnm, "g/tan", uv), &want, 1e-5), "{:?}", eval(&docnm, "g/tan", uv));
}

#[test]
fn includes_are_read_recursively_once() {
    let d = dir("include");
    write(&d, "defs.mtlx", &doc("1.39", &format!("  <xi:include href=\"more.mtlx\" />\n{SCALE_DEFS}")));
    write(
        &d,
        "more.mtlx",
        &doc(
            "1.38",
            r#"  <nodegraph name="lib_graph">
    <constant name="k" type="float"><input name="value" type="float" value="0.5" /></constant>
    <output name="out" type="float" nodename="k" />
  </nodegraph>"#,
        ),
    );
    let main = write(
        &d,
        "main.mtlx",
        &doc(
            "1.39",
            r#"  <xi:include href="defs.mtlx" />
  <xi:include href="more.mtlx" />
  <nodegraph name="g">
    <scaleoffset name="s" type="float">
      <input name="in" type="float" nodegraph="lib_graph" output="out" />
    </scaleoffset>
    <output name="out" type="float" nodename="s" />
  </nodegraph>"#,
        ),
    );
    let doc = Document::load(&main).unwrap();
    assert_eq!(doc.files().len(), 3, "{:?}", doc.files());
    assert!(close(&eval(&doc, "g/out", Vec2::ZERO), &[1.25], 1e-6));
}

#[test]
fn file_prefixes_and_colour_spaces() {
    let images = common::shared().join("mtlx-suite/images");
    let d = dir("colour");
    let body = r#"  <nodegraph name="g" fileprefix="resources/Images/">
    <image name="raw" type="color3"><input name="file" type="filename" value="grid.png" /></image>
    <image name="srgb" type="color3"><input name="file" type="filename" value="grid.png" colorspace="srgb_texture" /></image>
    <image name="g22" type="color3"><input name="file" type="filename" value="grid.png" colorspace="g22_rec709" /></image>
    <image name="ap1" type="color3"><input name="file" type="filename" value="grid.png" colorspace="acescg" /></image>
    <image name="grey" type="float"><input name="file" type="filename" value="grid.png" colorspace="srgb_texture" /></image>
    <constant name="k" type="color3"><input name="value" type="color3" value="0.5, 0.25, 1.0" colorspace="srgb_texture" /></constant>
    <output name="raw" type="color3" nodename="raw" />
    <output name="srgb" type="color3" nodename="srgb" />
    <output name="g22" type="color3" nodename="g22" />
    <output name="ap1" type="color3" nodename="ap1" />
    <output name="grey" type="float" nodename="grey" />
    <output name="k" type="color3" nodename="k" />
  </nodegraph>"#;
    let opts = LoadOptions { search_paths: vec![images.clone()], ..LoadOptions::default() };
    let p = write(&d, "colour.mtlx", &doc("1.39", body));
    let lin = Document::load_with(&p, &opts).unwrap();
    let srgb = |x: f32| if x <= 0.04045 { x / 12.92 } else { ((x + 0.055) / 1.055).powf(2.4) };
    // AP1 → Rec.709 (MaterialX's colour management), rows.
    let m = [[1.705051f32, -0.621792, -0.083259], [-0.130256, 1.140805, -0.010548], [-0.024003, -0.128969, 1.152972]];
    // Texel centres of the 640² image: the bilinear lookup returns the texel itself.
    for (i, j) in [(3, 5), (100, 321), (320, 320), (639, 0)] {
        let uv = Vec2::new((i as f32 + 0.5) / 640.0, (j as f32 + 0.5) / 640.0);
        let raw = eval(&lin, "g/raw", uv);
        let want: Vec<f32> = raw.iter().map(|x| srgb(*x)).collect();
        assert!(close(&eval(&lin, "g/srgb", uv), &want, 1e-4));
        let want: Vec<f32> = raw.iter().map(|x| x.max(0.0).powf(2.2)).collect();
        assert!(close(&eval(&lin, "g/g22", uv), &want, 1e-4));
        let want: Vec<f32> = m.iter().map(|r| r[0] * raw[0] + r[1] * raw[1] + r[2] * raw[2]).collect();
        assert!(close(&eval(&lin, "g/ap1", uv), &want, 1e-4));
        // Only colour images are colour managed.
        assert!(close(&eval(&lin, "g/grey", uv), &raw[..1], 1e-6));
    }
    let k = eval(&lin, "g/k", Vec2::ZERO);
    assert!(close(&k, &[srgb(0.5), srgb(0.25), 1.0], 1e-6), "{k:?}");

    // An ACEScg working space: Rec.709 values are converted into it, AP1 ones are not.
    let body_ap1 = r#"  <nodegraph name="g">
    <constant name="a" type="color3"><input name="value" type="color3" value="0.2, 0.4, 0.6" colorspace="lin_rec709" /></constant>
    <constant name="b" type="color3"><input name="value" type="color3" value="0.2, 0.4, 0.6" /></constant>
    <output name="a" type="color3" nodename="a" />
    <output name="b" type="color3" nodename="b" />
  </nodegraph>"#;
    let p = write(
        &d,
        "acescg.mtlx",
        &doc("1.39", body_ap1).replace("version=\"1.39\"", "version=\"1.39\" colorspace=\"acescg\""),
    );
    let ap1 = Document::load(&p).unwrap();
    let a = eval(&ap1, "g/a", Vec2::ZERO);
    let back: Vec<f32> = m.iter().map(|r| r[0] * a[0] + r[1] * a[1] + r[2] * a[2]).collect();
    assert!(close(&back, &[0.2, 0.4, 0.6], 1e-4), "{a:?} → {back:?}");
    assert!(close(&eval(&ap1, "g/b", Vec2::ZERO), &[0.2, 0.4, 0.6], 1e-7));

    // A wrong prefix is a missing file, named with the line of the element giving the value.
    let p = write(&d, "prefix.mtlx", &doc("1.39", &body.replace("resources/Images/", "nowhere/")));
    let e = Document::load_with(&p, &opts).expect_err("missing file");
    assert!(matches!(&e.kind, LoadErrorKind::MissingFile(f) if f.ends_with("nowhere/grid.png")), "{e}");
    assert_eq!(e.location.line, line_of(&p, "name=\"raw\""), "{e}");
    // An unknown colour space is an error naming it.
    let p = write(&d, "unknown_cs.mtlx", &doc("1.39", &body.replace("g22_rec709", "g23_rec709")));
    let e = Document::load_with(&p, &opts).expect_err("unknown colour space");
    assert_eq!(e.location.line, line_of(&p, "g23_rec709"), "{e}");
    assert!(e.to_string().contains("g23_rec709") && e.to_string().contains("srgb_texture"), "{e}");
}

#[test]
fn uniform_and_enum_inputs() {
    let d = dir("uniform");
    let defs = r#"  <nodedef name="ND_pick" node="pick">
    <input name="which" type="integer" value="0" uniform="true" enum="low,mid,high" enumvalues="1,2,3" />
    <output name="out" type="float" />
  </nodedef>
  <nodegraph name="NG_pick" nodedef="ND_pick">
    <convert name="c" type="float"><input name="in" type="integer" interfacename="which" /></convert>
    <output name="out" type="float" nodename="c" />
  </nodegraph>"#;
    let ok = format!(
        "{defs}\n  <nodegraph name=\"g\">\n    <pick name=\"p\" type=\"float\"><input name=\"which\" type=\"integer\" value=\"high\" /></pick>\n    <output name=\"out\" type=\"float\" nodename=\"p\" />\n  </nodegraph>"
    );
    let p = write(&d, "enum.mtlx", &doc("1.39", &ok));
    let doc_ok = Document::load(&p).unwrap();
    assert!(close(&eval(&doc_ok, "g/out", Vec2::ZERO), &[3.0], 0.0));
    let bad = format!(
        "{defs}\n  <nodegraph name=\"g\">\n    <constant name=\"k\" type=\"integer\"><input name=\"value\" type=\"integer\" value=\"2\" /></constant>\n    <pick name=\"p\" type=\"float\">\n      <input name=\"which\" type=\"integer\" nodename=\"k\" uniform=\"true\" />\n    </pick>\n    <output name=\"out\" type=\"float\" nodename=\"p\" />\n  </nodegraph>"
    );
    let p = write(&d, "uniform.mtlx", &doc("1.39", &bad));
    let e = expect_error(&p, line_of(&p, "uniform=\"true\" />"));
    assert!(e.to_string().contains("uniform"), "{e}");
}

#[test]
fn unsupported_nodes_are_reported_together() {
    let d = dir("unsupported");
    let p = write(
        &d,
        "many.mtlx",
        &doc(
            "1.39",
            r#"  <nodegraph name="a">
    <frobnicate name="f" type="float" />
    <output name="out" type="float" nodename="f" />
  </nodegraph>
  <nodegraph name="b">
    <constant name="k" type="float" />
    <twiddle name="t" type="color3" />
    <output name="out" type="float" nodename="k" />
  </nodegraph>
  <wibble name="w" type="float" />"#,
        ),
    );
    let e = expect_error(&p, 4);
    let LoadErrorKind::Unsupported { items, .. } = &e.kind else { panic!("{e}") };
    let found: Vec<(&str, u32)> = items.iter().map(|u| (u.category.as_str(), u.location.line)).collect();
    assert_eq!(found, vec![("frobnicate", 4), ("twiddle", 9), ("wibble", 12)], "{e}");
    // Leniently, only the outputs that need them are left out.
    let lenient = Document::load_with(&p, &LoadOptions { lenient: true, ..Default::default() }).unwrap();
    assert!(lenient.graph().output_id("b/out").is_some());
    let (_, why) = lenient.skipped().iter().find(|(n, _)| n == "a/out").unwrap();
    assert!(why.contains("frobnicate") && why.contains("many.mtlx:4:"), "{why}");
    assert_eq!(lenient.unsupported().len(), 3);
}

#[test]
fn unresolvable_nodedefs_are_errors() {
    let d = dir("nodedef");
    let p = write(
        &d,
        "missing_def.mtlx",
        &doc("1.39", "  <nodegraph name=\"g\">\n    <gizmo name=\"x\" type=\"float\" nodedef=\"ND_gizmo_float\" />\n  </nodegraph>"),
    );
    let e = expect_error(&p, 4);
    assert!(e.to_string().contains("ND_gizmo_float"), "{e}");
    // A nodedef exists for the node, but not for its type.
    let p = write(
        &d,
        "no_match.mtlx",
        &doc("1.39", &format!("{SCALE_DEFS}\n  <nodegraph name=\"g\">\n    <scaleoffset name=\"x\" type=\"color3\" />\n  </nodegraph>")),
    );
    let e = expect_error(&p, line_of(&p, "type=\"color3\" />"));
    assert!(e.to_string().contains("ND_scaleoffset_float"), "{e}");
    // A definition that instantiates itself.
    let p = write(
        &d,
        "recursive.mtlx",
        &doc(
            "1.39",
            r#"  <nodedef name="ND_loop" node="loop"><output name="out" type="float" /></nodedef>
  <nodegraph name="NG_loop" nodedef="ND_loop">
    <loop name="inner" type="float" />
    <output name="out" type="float" nodename="inner" />
  </nodegraph>"#,
        ),
    );
    let e = expect_error(&p, 5);
    assert!(e.to_string().contains("recursive"), "{e}");
}

#[test]
fn interface_cycles_are_errors() {
    let d = dir("cycle");
    let p = write(
        &d,
        "iface.mtlx",
        &doc(
            "1.39",
            r#"  <input name="a" type="float" interfacename="b" />
  <input name="b" type="float" interfacename="a" />
  <nodegraph name="g">
    <input name="x" type="float" interfacename="a" />
    <add name="s" type="float"><input name="in1" type="float" interfacename="x" /></add>
    <output name="out" type="float" nodename="s" />
  </nodegraph>"#,
        ),
    );
    let e = expect_error(&p, 4);
    assert!(e.to_string().contains("interface cycle"), "{e}");
    // An instance whose input reads its own output.
    let p = write(
        &d,
        "instance.mtlx",
        &doc(
            "1.39",
            &format!(
                "{SCALE_DEFS}\n  <nodegraph name=\"g\">\n    <scaleoffset name=\"s\" type=\"float\">\n      <input name=\"in\" type=\"float\" nodename=\"s\" />\n    </scaleoffset>\n    <output name=\"out\" type=\"float\" nodename=\"s\" />\n  </nodegraph>"
            ),
        ),
    );
    let e = Document::load(&p).expect_err("cycle");
    assert!(matches!(e.kind, LoadErrorKind::Cycle(_)), "{e}");
    assert_eq!(e.location.file, p);
}

#[test]
fn missing_includes_and_versions_are_errors() {
    let d = dir("include-errors");
    let p =
        write(&d, "missing.mtlx", &doc("1.39", "  <nodegraph name=\"g\" />\n  <xi:include href=\"nowhere.mtlx\" />"));
    let e = expect_error(&p, 4);
    assert!(matches!(&e.kind, LoadErrorKind::MissingFile(f) if f.ends_with("nowhere.mtlx")), "{e}");
    // An error inside an included file names that file and line.
    write(
        &d,
        "broken.mtlx",
        &doc("1.39", "  <nodegraph name=\"h\">\n    <add name=\"a\" type=\"float\">\n  </nodegraph>"),
    );
    let p = write(&d, "includes_broken.mtlx", &doc("1.39", "  <xi:include href=\"broken.mtlx\" />"));
    let e = Document::load(&p).expect_err("broken include");
    assert_eq!(e.location.file, d.join("broken.mtlx"), "{e}");
    assert!(e.location.line >= 5, "{e}");
    // Include cycles.
    write(&d, "c1.mtlx", &doc("1.39", "  <xi:include href=\"c2.mtlx\" />"));
    write(&d, "c2.mtlx", &doc("1.39", "  <xi:include href=\"c1.mtlx\" />"));
    let e = Document::load(d.join("c1.mtlx")).expect_err("include cycle");
    assert!(e.to_string().contains("include cycle"), "{e}");
    // Versions from the future, and from before 1.36.
    let p = write(&d, "future.mtlx", &doc("1.40", "  <nodegraph name=\"g\" />"));
    let e = expect_error(&p, 2);
    assert!(e.to_string().contains("1.40"), "{e}");
    let p = write(&d, "past.mtlx", &doc("1.35", "  <nodegraph name=\"g\" />"));
    let e = expect_error(&p, 2);
    assert!(e.to_string().contains("1.35"), "{e}");
}

#[test]
fn default_geometric_properties() {
    let d = dir("geomprop");
    let p = write(
        &d,
        "geomprop.mtlx",
        &doc(
            "1.39",
            r#"  <nodedef name="ND_where" node="where">
    <input name="p" type="vector3" defaultgeomprop="Pobject" />
    <input name="t" type="vector2" defaultgeomprop="UV0" />
    <output name="p" type="vector3" />
    <output name="t" type="vector2" />
  </nodedef>
  <nodegraph name="NG_where" nodedef="ND_where">
    <dot name="dp" type="vector3"><input name="in" type="vector3" interfacename="p" /></dot>
    <dot name="dt" type="vector2"><input name="in" type="vector2" interfacename="t" /></dot>
    <output name="p" type="vector3" nodename="dp" />
    <output name="t" type="vector2" nodename="dt" />
  </nodegraph>
  <nodegraph name="g">
    <where name="w" type="multioutput" />
    <output name="p" type="vector3" nodename="w" output="p" />
    <output name="t" type="vector2" nodename="w" output="t" />
  </nodegraph>"#,
        ),
    );
    let doc = Document::load(&p).unwrap();
    let uv = Vec2::new(0.25, 0.75);
    // The baker's quad: position (2u − 1, 2v − 1, 0).
    assert!(close(&eval(&doc, "g/p", uv), &[-0.5, 0.5, 0.0], 1e-6));
    assert!(close(&eval(&doc, "g/t", uv), &[0.25, 0.75], 1e-7));
}

/// `v · M` for a row-major matrix written as MaterialX writes it, computed here independently.
fn row_times(v: &[f64], m: &[f64], n: usize) -> Vec<f64> {
    (0..n).map(|k| (0..n).map(|j| v[j] * m[j * n + k]).sum()).collect()
}

#[test]
fn matrices_fold_at_load_and_transform_vectors() {
    let d = dir("matrix");
    // A general 3×3 and 4×4 (not symmetric, not orthogonal), their inverses, products and rows.
    let m3 = [2.0, 0.5, -1.0, 0.25, 1.5, 0.75, -0.5, 1.0, 3.0];
    let m4 = [1.5, 0.2, 0.0, 0.0, -0.3, 0.8, 0.1, 0.0, 0.0, 0.4, 2.0, 0.0, 0.7, -0.2, 0.3, 1.0];
    let s3 = m3.map(|x: f64| x.to_string()).join(", ");
    let s4 = m4.map(|x: f64| x.to_string()).join(", ");
    let p = write(
        &d,
        "matrix.mtlx",
        &doc(
            "1.39",
            &format!(
                r#"  <nodegraph name="g">
    <texcoord name="uv" type="vector2"/>
    <transformmatrix name="t2" type="vector2">
      <input name="in" type="vector2" nodename="uv"/>
      <input name="mat" type="matrix33" value="{s3}"/>
    </transformmatrix>
    <position name="p" type="vector3"/>
    <transformmatrix name="t3" type="vector3">
      <input name="in" type="vector3" nodename="p"/>
      <input name="mat" type="matrix44" value="{s4}"/>
    </transformmatrix>
    <invertmatrix name="inv" type="matrix44"><input name="in" type="matrix44" value="{s4}"/></invertmatrix>
    <transformmatrix name="back" type="vector3">
      <input name="in" type="vector3" nodename="t3"/>
      <input name="mat" type="matrix44" nodename="inv"/>
    </transformmatrix>
    <transpose name="tr" type="matrix33"><input name="in" type="matrix33" value="{s3}"/></transpose>
    <multiply name="mm" type="matrix33">
      <input name="in1" type="matrix33" nodename="tr"/>
      <input name="in2" type="matrix33" value="{s3}"/>
    </multiply>
    <extract name="row2" type="vector3">
      <input name="in" type="matrix33" nodename="mm"/>
      <input name="index" type="integer" value="2"/>
    </extract>
    <determinant name="det" type="float"><input name="in" type="matrix33" value="{s3}"/></determinant>
    <creatematrix name="cm" type="matrix44">
      <input name="in1" type="vector3" value="1, 0, 0"/>
      <input name="in2" type="vector3" value="0, 2, 0"/>
      <input name="in3" type="vector3" value="0, 0, 4"/>
      <input name="in4" type="vector3" value="0.5, 0.25, 0.125"/>
    </creatematrix>
    <transformmatrix name="moved" type="vector3">
      <input name="in" type="vector3" value="1, 1, 1"/>
      <input name="mat" type="matrix44" nodename="cm"/>
    </transformmatrix>
    <output name="t2" type="vector2" nodename="t2"/>
    <output name="t3" type="vector3" nodename="t3"/>
    <output name="back" type="vector3" nodename="back"/>
    <output name="row2" type="vector3" nodename="row2"/>
    <output name="det" type="float" nodename="det"/>
    <output name="moved" type="vector3" nodename="moved"/>
  </nodegraph>"#
            ),
        ),
    );
    let doc = Document::load(&p).unwrap();
    let uv = Vec2::new(0.3, 0.8);
    // vector2 with a matrix33: (u, v, 1) · M.
    let want = row_times(&[0.3, 0.8, 1.0], &m3, 3);
    assert!(close(&eval(&doc, "g/t2", uv), &[want[0] as f32, want[1] as f32], 1e-5));
    // vector3 with a matrix44: (P, 1) · M on the baking quad's P = (2u − 1, 2v − 1, 0).
    let pos = [2.0 * 0.3 - 1.0, 2.0 * 0.8 - 1.0, 0.0, 1.0];
    let want = row_times(&pos, &m4, 4);
    assert!(close(&eval(&doc, "g/t3", uv), &[want[0] as f32, want[1] as f32, want[2] as f32], 1e-5));
    // The inverse undoes it (the matrix is affine: its last column is (0, 0, 0, 1)).
    assert!(close(&eval(&doc, "g/back", uv), &[pos[0] as f32, pos[1] as f32, pos[2] as f32], 1e-5));
    // Row 2 of Mᵀ·M is column 2 of M dotted with each column of M.
    let col = |c: usize| [m3[c], m3[3 + c], m3[6 + c]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let want: Vec<f32> = (0..3).map(|c| dot(col(2), col(c)) as f32).collect();
    assert!(close(&eval(&doc, "g/row2", uv), &want, 1e-5), "{:?} vs {want:?}", eval(&doc, "g/row2", uv));
    // Rule of Sarrus.
    let det = m3[0] * (m3[4] * m3[8] - m3[5] * m3[7]) - m3[1] * (m3[3] * m3[8] - m3[5] * m3[6])
        + m3[2] * (m3[3] * m3[7] - m3[4] * m3[6]);
    assert!(close(&eval(&doc, "g/det", uv), &[det as f32], 1e-5));
    // creatematrix of vector3 rows: a scale by (1, 2, 4) and a translation in the last row.
    assert!(close(&eval(&doc, "g/moved", uv), &[1.5, 2.25, 4.125], 1e-6));
    // No matrix node is left in the graph: they were folded.
    let g = doc.graph();
    assert!(g.node_ids().all(|id| !["invertmatrix", "transpose", "creatematrix"].contains(&g.node_category(id))));

    // Filtered: a linear map of the footprint, so its variance is exactly J Σ Jᵀ per channel.
    let out = g.output_id("g/t2").unwrap();
    let cov = glam::Mat2::from_cols(Vec2::new(4e-4, 1e-4), Vec2::new(1e-4, 9e-4));
    let mut scratch = EvalScratch::new(g);
    let f = g.eval_output(out, &Footprint::new(uv, cov), &mut scratch);
    for k in 0..2 {
        let j = Vec2::new(m3[k] as f32, m3[3 + k] as f32);
        let want = j.dot(cov * j);
        assert!((f.ch[k].var - want).abs() < 1e-6 * want.max(1e-3), "channel {k}: {} vs {want}", f.ch[k].var);
    }
}

#[test]
fn bad_matrices_are_clear_errors() {
    let d = dir("badmatrix");
    let graph = |body: &str| doc("1.39", &format!("  <nodegraph name=\"g\">\n{body}\n  </nodegraph>"));
    // A singular matrix cannot be inverted.
    let p = write(
        &d,
        "singular.mtlx",
        &graph(
            r#"    <invertmatrix name="inv" type="matrix33"><input name="in" type="matrix33" value="1,2,3, 2,4,6, 0,0,1"/></invertmatrix>
    <transformmatrix name="t" type="vector3"><input name="mat" type="matrix33" nodename="inv"/></transformmatrix>
    <output name="out" type="vector3" nodename="t"/>"#,
        ),
    );
    let e = expect_error(&p, line_of(&p, "<invertmatrix"));
    assert!(e.to_string().contains("singular"), "{e}");
    // The wrong number of entries.
    let p = write(
        &d,
        "short.mtlx",
        &graph(
            r#"    <transformmatrix name="t" type="vector3">
      <input name="mat" type="matrix44" value="1, 0, 0, 0, 1, 0, 0, 0, 1"/>
    </transformmatrix>
    <output name="out" type="vector3" nodename="t"/>"#,
        ),
    );
    let e = expect_error(&p, line_of(&p, "name=\"mat\""));
    assert!(e.to_string().contains("matrix44"), "{e}");
    // A row index beyond the matrix.
    let p = write(
        &d,
        "index.mtlx",
        &graph(
            r#"    <extract name="x" type="vector3">
      <input name="in" type="matrix33" value="1,0,0, 0,1,0, 0,0,1"/>
      <input name="index" type="integer" value="3"/>
    </extract>
    <output name="out" type="vector3" nodename="x"/>"#,
        ),
    );
    let e = expect_error(&p, line_of(&p, "<extract"));
    assert!(e.to_string().contains("index 3"), "{e}");
    // A vector4 cannot be transformed by a matrix33.
    let p = write(
        &d,
        "size.mtlx",
        &graph(
            r#"    <transformmatrix name="t" type="vector4">
      <input name="mat" type="matrix33" value="1,0,0, 0,1,0, 0,0,1"/>
    </transformmatrix>
    <output name="out" type="vector4" nodename="t"/>"#,
        ),
    );
    let e = expect_error(&p, line_of(&p, "<transformmatrix"));
    assert!(e.to_string().contains("vector4"), "{e}");
    // A matrix built from a varying vector is reported unsupported, naming the input.
    let p = write(
        &d,
        "varying.mtlx",
        &graph(
            r#"    <position name="p" type="vector3"/>
    <creatematrix name="cm" type="matrix33"><input name="in1" type="vector3" nodename="p"/></creatematrix>
    <transformmatrix name="t" type="vector3"><input name="mat" type="matrix33" nodename="cm"/></transformmatrix>
    <output name="out" type="vector3" nodename="t"/>"#,
        ),
    );
    let e = expect_error(&p, line_of(&p, "name=\"in1\""));
    let LoadErrorKind::Unsupported { items, .. } = &e.kind else { panic!("{e}") };
    assert!(items[0].detail.contains("`in1` varies over the surface"), "{e}");
}

/// MaterialX's own signatures: an image node whose `file` is empty gives its `default` (with a
/// warning naming the node) instead of failing the document, and colour noise takes a vector
/// amplitude of as many channels (`ND_noise3d_color3`, `ND_noise2d_color4`, `ND_fractal2d_color3`),
/// which scales each channel as a colour amplitude of the same values does.
#[test]
fn empty_image_files_and_vector_amplitudes_follow_materialx() {
    let text = doc(
        "1.39",
        r#"<nodegraph name="g">
  <image name="i" type="color3">
    <input name="file" type="filename" value=""/>
    <input name="default" type="color3" value="0.2, 0.4, 0.6"/>
  </image>
  <output name="img" type="color3" nodename="i"/>
  <texcoord name="t" type="vector2"/>
  <multiply name="s" type="vector2"><input name="in1" type="vector2" nodename="t"/><input name="in2" type="vector2" value="5, 5"/></multiply>
  <noise2d name="nv" type="color4"><input name="texcoord" type="vector2" nodename="s"/><input name="amplitude" type="vector4" value="1, 0.5, 0.25, 2"/></noise2d>
  <noise2d name="nc" type="color4"><input name="texcoord" type="vector2" nodename="s"/><input name="amplitude" type="color4" value="1, 0.5, 0.25, 2"/></noise2d>
  <output name="nv" type="color4" nodename="nv"/>
  <output name="nc" type="color4" nodename="nc"/>
  <fractal2d name="fv" type="color3"><input name="texcoord" type="vector2" nodename="s"/><input name="amplitude" type="vector3" value="1, 0.5, 0.25"/></fractal2d>
  <fractal2d name="f1" type="color3"><input name="texcoord" type="vector2" nodename="s"/></fractal2d>
  <output name="fv" type="color3" nodename="fv"/>
  <output name="f1" type="color3" nodename="f1"/>
  <noise3d name="n3" type="color3"><input name="amplitude" type="vector3" value="1, 0.5, 0.25"/></noise3d>
  <output name="n3" type="color3" nodename="n3"/>
</nodegraph>"#,
    );
    let d = Document::parse(&text, Path::new("sig.mtlx"), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let w = d.graph().warnings();
    assert!(w.iter().any(|w| w.contains("`g/i`") && w.contains("`file` is empty")), "{w:?}");
    for uv in [Vec2::new(0.13, 0.71), Vec2::new(0.52, 0.08), Vec2::new(0.9, 0.44)] {
        assert_eq!(eval(&d, "g/img", uv), vec![0.2, 0.4, 0.6]);
        assert_eq!(eval(&d, "g/nv", uv), eval(&d, "g/nc", uv));
        let (fv, f1) = (eval(&d, "g/fv", uv), eval(&d, "g/f1", uv));
        for (k, a) in [1.0f32, 0.5, 0.25].iter().enumerate() {
            assert!((fv[k] - a * f1[k]).abs() < 1e-6, "channel {k}: {} vs {} × {}", fv[k], a, f1[k]);
        }
        assert_eq!(eval(&d, "g/n3", uv).len(), 3);
    }
}

/// `frame` and `time` read the frame of the load options (1 by default), `time` as
/// `frame / fps` also where `fps` is connected; `geomcolor` is 0 with a warning naming it; a
/// `frame` of another type is an error at its line.
#[test]
fn frame_time_and_vertex_colours() {
    let text = doc(
        "1.39",
        r#"<nodegraph name="g">
  <frame name="f" type="float"/>
  <output name="frame" type="float" nodename="f"/>
  <time name="t0" type="float"/>
  <output name="time24" type="float" nodename="t0"/>
  <time name="t1" type="float"><input name="fps" type="float" value="30"/></time>
  <output name="time30" type="float" nodename="t1"/>
  <texcoord name="uv" type="vector2"/>
  <separate2 name="s" type="multioutput"><input name="in" type="vector2" nodename="uv"/></separate2>
  <add name="rate" type="float"><input name="in1" type="float" nodename="s" output="outx"/><input name="in2" type="float" value="1"/></add>
  <time name="t2" type="float"><input name="fps" type="float" nodename="rate"/></time>
  <output name="timev" type="float" nodename="t2"/>
  <geomcolor name="c" type="color3"/>
  <output name="col" type="color3" nodename="c"/>
</nodegraph>"#,
    );
    let uv = Vec2::new(0.25, 0.5);
    let d = Document::parse(&text, Path::new("frame.mtlx"), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(eval(&d, "g/frame", uv), vec![1.0]);
    assert_eq!(eval(&d, "g/time24", uv), vec![1.0 / 24.0]);
    assert_eq!(eval(&d, "g/time30", uv), vec![1.0 / 30.0]);
    assert!(close(&eval(&d, "g/timev", uv), &[1.0 / 1.25], 1e-6));
    assert_eq!(eval(&d, "g/col", uv), vec![0.0, 0.0, 0.0]);
    let w = d.graph().warnings();
    assert!(w.iter().any(|w| w.contains("`g/c`") && w.contains("vertex colour")), "{w:?}");
    let opts = LoadOptions { frame: Some(48.0), ..LoadOptions::default() };
    let d = Document::parse(&text, Path::new("frame.mtlx"), &opts).unwrap();
    assert_eq!(eval(&d, "g/frame", uv), vec![48.0]);
    assert_eq!(eval(&d, "g/time24", uv), vec![2.0]);
    assert!(close(&eval(&d, "g/timev", uv), &[48.0 / 1.25], 1e-5));

    let dir = dir("frame");
    let bad = write(
        &dir,
        "bad.mtlx",
        &doc(
            "1.39",
            r#"<nodegraph name="g">
  <frame name="f" type="color3"/>
  <output name="o" type="color3" nodename="f"/>
</nodegraph>"#,
        ),
    );
    let e = expect_error(&bad, line_of(&bad, "<frame"));
    assert!(e.to_string().contains("is a float"), "{e}");
}

/// `colorcorrect`, `ramp_gradient`, `bump` and `blur` equal the MaterialX graphs that define
/// them, written out here from their nodes, at points and over footprints.
#[test]
fn composed_nodes_equal_their_definitions() {
    let text = doc(
        "1.39",
        r#"<nodegraph name="g">
  <texcoord name="t" type="vector2"/>
  <multiply name="s" type="vector2"><input name="in1" type="vector2" nodename="t"/><input name="in2" type="vector2" value="4, 4"/></multiply>
  <noise2d name="c" type="color3"><input name="texcoord" type="vector2" nodename="s"/><input name="amplitude" type="vector3" value="0.5, 0.5, 0.5"/><input name="pivot" type="float" value="0.5"/></noise2d>
  <noise2d name="k" type="float"><input name="texcoord" type="vector2" nodename="s"/><input name="amplitude" type="float" value="0.5"/><input name="pivot" type="float" value="0.5"/></noise2d>
  <colorcorrect name="cc" type="color3">
    <input name="in" type="color3" nodename="c"/><input name="hue" type="float" value="0.1"/><input name="saturation" type="float" value="1.3"/>
    <input name="gamma" type="float" value="1.5"/><input name="lift" type="float" value="0.05"/><input name="gain" type="float" value="0.9"/>
    <input name="contrast" type="float" value="1.2"/><input name="contrastpivot" type="float" value="0.4"/><input name="exposure" type="float" value="0.5"/>
  </colorcorrect>
  <output name="cc" type="color3" nodename="cc"/>
  <hsvadjust name="h" type="color3"><input name="in" type="color3" nodename="c"/><input name="amount" type="vector3" value="0.1, 1, 1"/></hsvadjust>
  <saturate name="sa" type="color3"><input name="in" type="color3" nodename="h"/><input name="amount" type="float" value="1.3"/></saturate>
  <range name="ga" type="color3"><input name="in" type="color3" nodename="sa"/><input name="gamma" type="float" value="1.5"/></range>
  <multiply name="l1" type="color3"><input name="in1" type="color3" nodename="ga"/><input name="in2" type="float" value="0.95"/></multiply>
  <add name="l2" type="color3"><input name="in1" type="color3" nodename="l1"/><input name="in2" type="float" value="0.05"/></add>
  <multiply name="gn" type="color3"><input name="in1" type="color3" nodename="l2"/><input name="in2" type="float" value="0.9"/></multiply>
  <contrast name="co" type="color3"><input name="in" type="color3" nodename="gn"/><input name="amount" type="float" value="1.2"/><input name="pivot" type="float" value="0.4"/></contrast>
  <multiply name="ex" type="color3"><input name="in1" type="color3" nodename="co"/><input name="in2" type="float" value="1.41421356"/></multiply>
  <output name="cc_graph" type="color3" nodename="ex"/>
  <ramp_gradient name="rg" type="color4">
    <input name="x" type="float" nodename="k"/><input name="interval1" type="float" value="0.3"/><input name="interval2" type="float" value="0.7"/>
    <input name="color1" type="color4" value="0.1, 0.2, 0.3, 1"/><input name="color2" type="color4" value="0.9, 0.5, 0.1, 0.5"/>
    <input name="prev_color" type="color4" value="0, 0, 1, 1"/><input name="interpolation" type="integer" value="0"/>
  </ramp_gradient>
  <output name="rg" type="color4" nodename="rg"/>
  <clamp name="rc" type="float"><input name="in" type="float" nodename="k"/><input name="low" type="float" value="0.3"/><input name="high" type="float" value="0.7"/></clamp>
  <remap name="rr" type="float"><input name="in" type="float" nodename="rc"/><input name="inlow" type="float" value="0.3"/><input name="inhigh" type="float" value="0.7"/></remap>
  <mix name="rm" type="color4"><input name="fg" type="color4" value="0.9, 0.5, 0.1, 0.5"/><input name="bg" type="color4" value="0.1, 0.2, 0.3, 1"/><input name="mix" type="float" nodename="rr"/></mix>
  <ifgreater name="ri" type="color4"><input name="value1" type="float" nodename="k"/><input name="value2" type="float" value="0.3"/><input name="in1" type="color4" nodename="rm"/><input name="in2" type="color4" value="0, 0, 1, 1"/></ifgreater>
  <output name="rg_graph" type="color4" nodename="ri"/>
  <bump name="b" type="vector3"><input name="height" type="float" nodename="k"/><input name="scale" type="float" value="0.7"/></bump>
  <output name="bump" type="vector3" nodename="b"/>
  <heighttonormal name="hn" type="vector3"><input name="in" type="float" nodename="k"/></heighttonormal>
  <normalmap name="nm" type="vector3"><input name="in" type="vector3" nodename="hn"/><input name="scale" type="float" value="0.7"/></normalmap>
  <output name="bump_graph" type="vector3" nodename="nm"/>
  <blur name="bl" type="color3"><input name="in" type="color3" nodename="c"/><input name="size" type="float" value="0.2"/></blur>
  <output name="blur" type="color3" nodename="bl"/>
  <output name="c" type="color3" nodename="c"/>
</nodegraph>"#,
    );
    let d =
        Document::parse(&text, Path::new("composed.mtlx"), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let w = d.graph().warnings();
    assert!(w.iter().any(|w| w.contains("`g/bl`") && w.contains("unblurred")), "{w:?}");
    let at = |name: &str, fp: &Footprint| eval_at(&d, name, fp);
    for uv in [Vec2::new(0.13, 0.71), Vec2::new(0.52, 0.08), Vec2::new(0.9, 0.44), Vec2::new(0.31, 0.27)] {
        for fp in [Footprint::point(uv), Footprint::isotropic(uv, 0.004), Footprint::isotropic(uv, 0.05)] {
            for (node, graph, tol) in [
                ("g/cc", "g/cc_graph", 2e-5),
                ("g/rg", "g/rg_graph", 2e-6),
                ("g/bump", "g/bump_graph", 1e-6),
                ("g/blur", "g/c", 0.0),
            ] {
                let (a, b) = (at(node, &fp), at(graph, &fp));
                assert!(close(&a, &b, tol), "{node} at {uv} σ² {:?}: {a:?} vs {b:?}", fp.cov);
            }
        }
    }
}

/// `latlongimage` equals MaterialX's graph for it written out node by node (at points and over
/// footprints), also across its seam; `triplanarprojection` on the flat quad reads the z
/// lookup only, and with a diagonal normal the mean of its three lookups; empty files give the
/// default.
#[test]
fn latlong_and_triplanar_images() {
    let img = common::shared().join("mtlx-suite/images/resources/Images/grid.png");
    let f = img.display();
    let text = doc(
        "1.39",
        &format!(
            r#"<nodegraph name="g">
  <texcoord name="t" type="vector2"/>
  <separate2 name="s" type="multioutput"><input name="in" type="vector2" nodename="t"/></separate2>
  <combine3 name="d0" type="vector3"><input name="in1" type="float" nodename="s" output="outx"/><input name="in2" type="float" nodename="s" output="outy"/><input name="in3" type="float" value="-0.3"/></combine3>
  <subtract name="d1" type="vector3"><input name="in1" type="vector3" nodename="d0"/><input name="in2" type="vector3" value="0.5, 0.5, 0"/></subtract>
  <normalize name="d" type="vector3"><input name="in" type="vector3" nodename="d1"/></normalize>
  <latlongimage name="ll" type="color3"><input name="file" type="filename" value="{f}"/><input name="viewdir" type="vector3" nodename="d"/><input name="rotation" type="float" value="30"/></latlongimage>
  <output name="ll" type="color3" nodename="ll"/>
  <separate3 name="dc" type="multioutput"><input name="in" type="vector3" nodename="d"/></separate3>
  <atan2 name="a" type="float"><input name="iny" type="float" nodename="dc" output="outx"/><input name="inx" type="float" nodename="dc" output="outz"/></atan2>
  <multiply name="a1" type="float"><input name="in1" type="float" nodename="a"/><input name="in2" type="float" value="-0.15915494"/></multiply>
  <add name="a2" type="float"><input name="in1" type="float" nodename="a1"/><input name="in2" type="float" value="0.5"/></add>
  <add name="a3" type="float"><input name="in1" type="float" nodename="a2"/><input name="in2" type="float" value="0.0833333"/></add>
  <asin name="b" type="float"><input name="in" type="float" nodename="dc" output="outy"/></asin>
  <multiply name="b1" type="float"><input name="in1" type="float" nodename="b"/><input name="in2" type="float" value="0.31830989"/></multiply>
  <add name="b2" type="float"><input name="in1" type="float" nodename="b1"/><input name="in2" type="float" value="0.5"/></add>
  <combine2 name="uv" type="vector2"><input name="in1" type="float" nodename="a3"/><input name="in2" type="float" nodename="b2"/></combine2>
  <image name="env" type="color3"><input name="file" type="filename" value="{f}"/><input name="texcoord" type="vector2" nodename="uv"/><input name="uaddressmode" type="string" value="periodic"/><input name="vaddressmode" type="string" value="mirror"/></image>
  <output name="ll_graph" type="color3" nodename="env"/>
  <triplanarprojection name="tp" type="color3"><input name="filex" type="filename" value=""/><input name="filey" type="filename" value="{f}"/><input name="filez" type="filename" value="{f}"/><input name="default" type="color3" value="0.1, 0.2, 0.3"/></triplanarprojection>
  <output name="tp" type="color3" nodename="tp"/>
  <position name="p" type="vector3"/>
  <separate3 name="pc" type="multioutput"><input name="in" type="vector3" nodename="p"/></separate3>
  <combine2 name="xy" type="vector2"><input name="in1" type="float" nodename="pc" output="outx"/><input name="in2" type="float" nodename="pc" output="outy"/></combine2>
  <image name="iz" type="color3"><input name="file" type="filename" value="{f}"/><input name="texcoord" type="vector2" nodename="xy"/></image>
  <output name="tp_graph" type="color3" nodename="iz"/>
  <triplanarprojection name="tq" type="color3"><input name="filex" type="filename" value=""/><input name="filey" type="filename" value="{f}"/><input name="filez" type="filename" value="{f}"/><input name="default" type="color3" value="0.1, 0.2, 0.3"/><input name="normal" type="vector3" value="1, -1, 1"/></triplanarprojection>
  <output name="tq" type="color3" nodename="tq"/>
  <combine2 name="xz" type="vector2"><input name="in1" type="float" nodename="pc" output="outx"/><input name="in2" type="float" nodename="pc" output="outz"/></combine2>
  <image name="iy" type="color3"><input name="file" type="filename" value="{f}"/><input name="texcoord" type="vector2" nodename="xz"/></image>
  <add name="sum" type="color3"><input name="in1" type="color3" nodename="iy"/><input name="in2" type="color3" nodename="iz"/></add>
  <add name="sum2" type="color3"><input name="in1" type="color3" nodename="sum"/><input name="in2" type="color3" value="0.1, 0.2, 0.3"/></add>
  <multiply name="mean" type="color3"><input name="in1" type="color3" nodename="sum2"/><input name="in2" type="float" value="0.33333333"/></multiply>
  <output name="tq_graph" type="color3" nodename="mean"/>
  <latlongimage name="le" type="color3"><input name="file" type="filename" value=""/><input name="default" type="color3" value="0.5, 0.6, 0.7"/></latlongimage>
  <output name="le" type="color3" nodename="le"/>
</nodegraph>"#
        ),
    );
    let d = Document::parse(&text, Path::new("images.mtlx"), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let at = |name: &str, fp: &Footprint| eval_at(&d, name, fp);
    // The seam (d.x = 0 behind the viewer) runs along u = 0.5 for v < 0.5.
    for uv in
        [Vec2::new(0.13, 0.71), Vec2::new(0.52, 0.08), Vec2::new(0.5, 0.2), Vec2::new(0.31, 0.27), Vec2::new(0.77, 0.9)]
    {
        let p = Footprint::point(uv);
        assert!(close(&at("g/ll", &p), &at("g/ll_graph", &p), 1e-4), "latlong at {uv}");
        assert!(close(&at("g/tp", &p), &at("g/tp_graph", &p), 1e-5), "triplanar at {uv}");
        assert!(close(&at("g/tq", &p), &at("g/tq_graph", &p), 1e-5), "triplanar blend at {uv}");
        assert_eq!(at("g/le", &p), vec![0.5, 0.6, 0.7]);
        for s in [0.002f32, 0.02] {
            let fp = Footprint::isotropic(uv, s);
            // Away from the seam, where the written-out graph's cubature sees no wrap.
            if (uv.x - 0.5).abs() > 0.1 {
                assert!(close(&at("g/ll", &fp), &at("g/ll_graph", &fp), 0.02), "latlong at {uv} σ {s}");
            }
            assert!(close(&at("g/tp", &fp), &at("g/tp_graph", &fp), 1e-5), "triplanar at {uv} σ {s}");
            assert!(at("g/ll", &fp).iter().all(|x| x.is_finite()));
        }
    }
}
