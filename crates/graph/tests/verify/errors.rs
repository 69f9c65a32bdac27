//! Bad MaterialX input: every error names the file and the line of the offending element.

use graph::{BuildError, Document, LoadError, LoadErrorKind};
use std::path::PathBuf;

/// The folder a test's document `name` is written to (one per document, so that no two tests
/// share one), fresh.
fn folder(name: &str) -> crate::common::TestDir {
    crate::common::TestDir::new(&format!("errors-{name}"))
}

/// Writes `body` as document `name` in a folder of its own and loads it, expecting an error;
/// the folder goes once it is loaded (the error keeps the path).
fn load(name: &str, body: &str) -> (PathBuf, LoadError) {
    load_in(&folder(name), name, body)
}

/// [`load`] in `dir`, which may hold files the document refers to.
fn load_in(dir: &std::path::Path, name: &str, body: &str) -> (PathBuf, LoadError) {
    let path = dir.join(name);
    let text = format!("<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n{body}\n</materialx>\n");
    std::fs::write(&path, text).unwrap();
    let err = Document::load(&path).expect_err("document should not load");
    (path, err)
}

fn check(err: &LoadError, path: &PathBuf, line: u32) {
    assert_eq!(err.location.file, *path);
    assert_eq!(err.location.line, line, "{err}");
    let msg = err.to_string();
    assert!(msg.starts_with(&format!("{}:{line}:", path.display())), "{msg}");
    println!("{msg}");
}

#[test]
fn unknown_node_lists_supported_nodes() {
    let (p, e) = load("unknown.mtlx", "<nodegraph name=\"g\">\n  <blurrify name=\"b\" type=\"float\"/>\n</nodegraph>");
    check(&e, &p, 4);
    match &e.kind {
        LoadErrorKind::Unsupported { items, supported } => {
            assert_eq!(items.len(), 1);
            assert_eq!(items[0].category, "blurrify");
            assert_eq!(items[0].node, "g/b");
            assert!(supported.contains("noise2d") && supported.contains("checkerboard"));
        }
        k => panic!("unexpected {k:?}"),
    }
}

#[test]
fn type_mismatch_of_value_and_of_connection() {
    let (p, e) = load(
        "mismatch.mtlx",
        "<nodegraph name=\"g\">\n  <multiply name=\"m\" type=\"color3\">\n    <input name=\"in1\" type=\"vector2\" value=\"1, 2\"/>\n  </multiply>\n</nodegraph>",
    );
    check(&e, &p, 4);
    assert!(matches!(e.kind, LoadErrorKind::Build(BuildError::TypeMismatch { .. })), "{e}");
    let (p, e) = load(
        "mismatch2.mtlx",
        "<nodegraph name=\"g\">\n  <constant name=\"c\" type=\"float\"/>\n  <add name=\"a\" type=\"color3\">\n    <input name=\"in1\" type=\"color3\" nodename=\"c\"/>\n  </add>\n</nodegraph>",
    );
    check(&e, &p, 6);
    assert!(matches!(e.kind, LoadErrorKind::Build(BuildError::TypeMismatch { .. })), "{e}");
}

#[test]
fn cycle_is_reported() {
    let (p, e) = load(
        "cycle.mtlx",
        "<nodegraph name=\"g\">\n  <add name=\"a\" type=\"float\">\n    <input name=\"in1\" type=\"float\" nodename=\"b\"/>\n  </add>\n  <add name=\"b\" type=\"float\">\n    <input name=\"in1\" type=\"float\" nodename=\"a\"/>\n  </add>\n</nodegraph>",
    );
    check(&e, &p, 4);
    assert!(matches!(e.kind, LoadErrorKind::Cycle(_)), "{e}");
}

#[test]
fn dangling_connection_is_reported() {
    let (p, e) = load(
        "dangling.mtlx",
        "<nodegraph name=\"g\">\n  <add name=\"a\" type=\"float\">\n    <input name=\"in1\" type=\"float\" nodename=\"nowhere\"/>\n  </add>\n</nodegraph>",
    );
    check(&e, &p, 5);
    assert!(matches!(e.kind, LoadErrorKind::Dangling { .. }), "{e}");
}

#[test]
fn malformed_value_is_reported() {
    let (p, e) = load(
        "malformed.mtlx",
        "<nodegraph name=\"g\">\n  <constant name=\"c\" type=\"color3\">\n    <input name=\"value\" type=\"color3\" value=\"0.5, zero, 1\"/>\n  </constant>\n</nodegraph>",
    );
    check(&e, &p, 5);
    assert!(matches!(e.kind, LoadErrorKind::MalformedValue { .. }), "{e}");
}

#[test]
fn missing_file_is_reported() {
    let path = std::env::temp_dir().join("graph-errors-no-such-file.mtlx");
    let e = Document::load(&path).expect_err("missing");
    assert!(matches!(e.kind, LoadErrorKind::MissingFile(_)), "{e}");
    assert!(e.to_string().contains("graph-errors-no-such-file.mtlx"));
}

#[test]
fn malformed_xml_names_line() {
    let (p, e) = load("xml.mtlx", "<nodegraph name=\"g\">\n  <add name=\"a\" type=\"float\">\n</nodegraph>");
    assert_eq!(e.location.file, p);
    assert!(e.location.line >= 5, "{e}");
    assert!(matches!(e.kind, LoadErrorKind::Xml(_)));
}

/// Node graphs that implement nodes by using the previous level ten times, eight levels deep,
/// would flatten to 10⁸ nodes: an error naming the document and where, once the graph passes
/// `graph::MAX_NODES`, instead of gigabytes and minutes. Three levels (a thousand) load.
#[test]
fn node_graphs_multiplying_each_other_are_refused() {
    let doc = |levels: usize| {
        let mut s = String::from(
            "<nodedef name=\"ND_l0\" node=\"l0\"><output name=\"out\" type=\"float\"/></nodedef>\n\
             <nodegraph name=\"NG_l0\" nodedef=\"ND_l0\"><constant name=\"c\" type=\"float\">\
             <input name=\"value\" type=\"float\" value=\"1\"/></constant>\
             <output name=\"out\" type=\"float\" nodename=\"c\"/></nodegraph>\n",
        );
        for l in 1..=levels {
            s += &format!("<nodedef name=\"ND_l{l}\" node=\"l{l}\"><output name=\"out\" type=\"float\"/></nodedef>\n");
            s += &format!("<nodegraph name=\"NG_l{l}\" nodedef=\"ND_l{l}\">");
            for k in 0..10 {
                s += &format!("<l{} name=\"a{k}\" type=\"float\"/>", l - 1);
            }
            let mut prev = "a0".to_string();
            for k in 1..10 {
                s += &format!(
                    "<add name=\"s{k}\" type=\"float\"><input name=\"in1\" type=\"float\" nodename=\"{prev}\"/>\
                     <input name=\"in2\" type=\"float\" nodename=\"a{k}\"/></add>"
                );
                prev = format!("s{k}");
            }
            s += &format!("<output name=\"out\" type=\"float\" nodename=\"{prev}\"/></nodegraph>\n");
        }
        s + &format!(
            "<nodegraph name=\"NG\"><l{levels} name=\"top\" type=\"float\"/>\
             <output name=\"out\" type=\"float\" nodename=\"top\"/></nodegraph>"
        )
    };
    let (p, e) = load("multiply.mtlx", &doc(8));
    assert_eq!(e.location.file, p);
    assert!(e.location.line > 0, "{e}");
    assert!(e.to_string().contains(&format!("more than {} nodes", graph::MAX_NODES)), "{e}");
    let dir = folder("thousand.mtlx");
    let ok = dir.join("thousand.mtlx");
    std::fs::write(&ok, format!("<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n{}\n</materialx>\n", doc(3)))
        .unwrap();
    let d = Document::load(&ok).unwrap_or_else(|e| panic!("{e}"));
    assert!(d.graph().node_count() > 1000, "{}", d.graph().node_count());
}

/// A misspelt input, a misspelt type and a mistyped connection name what is wrong and where:
/// not "unsupported `fractal2d`", and a port that exists (`g/n.texcoord`, the node's input).
#[test]
fn misspellings_and_mismatches_name_the_element_and_the_likely_fix() {
    let node = |tag: &str, ty: &str, input: &str, input_ty: &str| {
        format!(
            "<nodegraph name=\"g\">\n  <texcoord name=\"t\" type=\"vector2\"/>\n  <{tag} name=\"n\" type=\"{ty}\">\n    \
             <input name=\"{input}\" type=\"{input_ty}\" nodename=\"t\"/>\n  </{tag}>\n  \
             <output name=\"out\" type=\"float\" nodename=\"n\"/>\n</nodegraph>"
        )
    };
    let (p, e) = load("input.mtlx", &node("fractal2d", "float", "texcord", "vector2"));
    let m = e.to_string();
    assert!(m.contains(&format!("{}:6:", p.display())), "{m}");
    assert!(m.contains("`fractal2d` has no input `texcord`") && m.contains("did you mean `texcoord`?"), "{m}");
    assert!(!m.contains("unsupported `fractal2d`"), "{m}");
    let (p, e) = load("type.mtlx", &node("noise2d", "flaot", "texcoord", "vector2"));
    let m = e.to_string();
    assert!(m.contains(&format!("{}:5:", p.display())), "{m}");
    assert!(m.contains("`flaot` is not a MaterialX type; did you mean `float`?"), "{m}");
    let (p, e) = load("port.mtlx", &node("noise2d", "float", "texcoord", "vector3"));
    check(&e, &p, 6);
    assert!(e.to_string().contains("type mismatch at `g/n.texcoord`: expected vector3, found vector2"), "{e}");
}

/// A value or a name of megabytes is quoted by an excerpt and its length, never whole.
#[test]
fn huge_values_and_names_are_not_echoed_whole() {
    let big = "7".repeat(5_000_000) + "x";
    let (p, e) = load(
        "bigvalue.mtlx",
        &format!(
            "<nodegraph name=\"g\">\n  <constant name=\"c\" type=\"float\">\n    \
             <input name=\"value\" type=\"float\" value=\"{big}\"/>\n  </constant>\n</nodegraph>"
        ),
    );
    check(&e, &p, 5);
    let m = e.to_string();
    assert!(
        m.len() < 600 && m.contains("(5000001 bytes)") && m.contains("malformed float"),
        "{}",
        &m[..m.len().min(300)]
    );
    let name = "q".repeat(2_000_000);
    let (p, e) = load(
        "bigname.mtlx",
        &format!(
            "<nodegraph name=\"g\">\n  <texcoord name=\"t\" type=\"vector2\"/>\n  <noise2d name=\"n\" type=\"float\">\n    \
             <input name=\"{name}\" type=\"vector2\" nodename=\"t\"/>\n  </noise2d>\n  \
             <output name=\"out\" type=\"float\" nodename=\"n\"/>\n</nodegraph>"
        ),
    );
    let m = e.to_string();
    assert!(m.contains(&format!("{}:6:", p.display())), "{}", &m[..m.len().min(300)]);
    assert!(m.len() < 2000 && m.contains("(2000000 bytes)"), "{}", &m[..m.len().min(300)]);
}

/// An image whose header claims 65536 × 65536 texels is refused at load without allocating it
/// (the image decoder's memory limit), naming the node and the file.
#[test]
fn images_claiming_huge_sizes_are_refused() {
    fn chunk(kind: &[u8], data: &[u8]) -> Vec<u8> {
        let mut c = (data.len() as u32).to_be_bytes().to_vec();
        c.extend_from_slice(kind);
        c.extend_from_slice(data);
        // CRC-32 of kind + data (PNG's polynomial), bit by bit.
        let mut crc = !0u32;
        for &b in kind.iter().chain(data) {
            crc ^= b as u32;
            for _ in 0..8 {
                crc = if crc & 1 != 0 { (crc >> 1) ^ 0xedb8_8320 } else { crc >> 1 };
            }
        }
        c.extend_from_slice(&(!crc).to_be_bytes());
        c
    }
    let dir = folder("hugeimage.mtlx");
    let mut ihdr = 65536u32.to_be_bytes().to_vec();
    ihdr.extend_from_slice(&65536u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(chunk(b"IHDR", &ihdr));
    png.extend(chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]));
    png.extend(chunk(b"IEND", &[]));
    std::fs::write(dir.join("huge.png"), png).unwrap();
    let (p, e) = load_in(
        &dir,
        "hugeimage.mtlx",
        "<nodegraph name=\"g\">\n  <image name=\"i\" type=\"color3\">\n    \
         <input name=\"file\" type=\"filename\" value=\"huge.png\"/>\n  </image>\n  \
         <output name=\"out\" type=\"color3\" nodename=\"i\"/>\n</nodegraph>",
    );
    let m = e.to_string();
    assert!(m.starts_with(&format!("{}:4:", p.display())) && m.contains("huge.png"), "{m}");
    // Refused by the decoder's limit from the header, not after trying to allocate 16 GiB.
    assert!(m.contains("limit"), "{m}");
}

/// Leniently, a node's own error (a malformed value, a missing image, an unknown input) fails
/// only the outputs that need it, each with the reason and the element's line; the others load
/// and evaluate. Strictly, the same document is the error it was. Document-wide errors (a
/// cycle) stay errors either way.
#[test]
fn node_errors_are_scoped_in_lenient_loads() {
    use graph::{Document, LoadErrorKind, LoadOptions};
    let text = r#"<?xml version="1.0"?>
<materialx version="1.39">
  <nodegraph name="bad">
    <constant name="c" type="float"><input name="value" type="float" value="1.2.3"/></constant>
    <output name="out" type="float" nodename="c"/>
  </nodegraph>
  <nodegraph name="img">
    <image name="i" type="color3"><input name="file" type="filename" value="nowhere/none.png"/></image>
    <output name="out" type="color3" nodename="i"/>
  </nodegraph>
  <nodegraph name="good">
    <constant name="c" type="float"><input name="value" type="float" value="0.25"/></constant>
    <output name="out" type="float" nodename="c"/>
  </nodegraph>
</materialx>"#;
    let path = std::path::Path::new("scoped.mtlx");
    let strict = Document::parse(text, path, &LoadOptions::default()).expect_err("strict load fails");
    assert!(matches!(strict.kind, LoadErrorKind::MalformedValue { .. }), "{strict}");
    let opts = LoadOptions { lenient: true, ..LoadOptions::default() };
    let d = Document::parse(text, path, &opts).unwrap_or_else(|e| panic!("{e}"));
    let g = d.graph();
    let out = g.output_id("good/out").expect("the good output loads");
    let mut scratch = graph::EvalScratch::new(g);
    assert_eq!(g.eval_output(out, &graph::Footprint::point(glam::Vec2::ZERO), &mut scratch).ch[0].mean, 0.25);
    for (name, line, what) in [("bad/out", 4, "malformed float value `1.2.3`"), ("img/out", 8, "none.png")] {
        assert!(g.output_id(name).is_none(), "{name} is left out");
        let (_, reason) = d.skipped().iter().find(|(n, _)| n == name).unwrap_or_else(|| panic!("{name} not skipped"));
        assert!(reason.contains(what) && reason.contains(&format!("scoped.mtlx:{line}:")), "{name}: {reason}");
    }
    assert_eq!(d.unsupported().len(), 2, "{:?}", d.unsupported());
    let cycle = r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">
  <add name="a" type="float"><input name="in1" type="float" nodename="b"/></add>
  <add name="b" type="float"><input name="in1" type="float" nodename="a"/></add>
  <output name="out" type="float" nodename="a"/></nodegraph></materialx>"#;
    let e = Document::parse(cycle, path, &opts).expect_err("a cycle is an error of the document");
    assert!(matches!(e.kind, LoadErrorKind::Cycle(_)), "{e}");
}

/// A library whose shader implementation graphs connect to nodes tessera does not keep (BSDF
/// nodes, as MaterialX's `usd_preview_surface.mtlx` has) loads leniently: the broken shader
/// input is scoped to that shader, and the library's texture nodedefs serve the document,
/// without the warnings of its implementation graphs' own nodes.
#[test]
fn libraries_with_unusable_shader_graphs_still_serve_their_nodes() {
    use graph::{Document, LoadOptions};
    let text = r#"<?xml version="1.0"?>
<materialx version="1.39">
  <nodedef name="ND_my_shader" node="my_shader"><input name="c" type="color3" value="1, 1, 1"/><output name="out" type="surfaceshader"/></nodedef>
  <nodegraph name="IMP_my_shader" nodedef="ND_my_shader">
    <oren_nayar_diffuse_bsdf name="diffuse" type="BSDF"><input name="color" type="color3" interfacename="c"/></oren_nayar_diffuse_bsdf>
    <mix name="blend" type="BSDF"><input name="fg" type="BSDF" nodename="diffuse"/><input name="bg" type="BSDF" nodename="missing"/></mix>
    <surface name="surf" type="surfaceshader"><input name="bsdf" type="BSDF" nodename="blend"/></surface>
    <output name="out" type="surfaceshader" nodename="surf"/>
  </nodegraph>
  <nodedef name="ND_my_tex" node="my_tex"><input name="scale" type="float" value="2"/><output name="out" type="float"/></nodedef>
  <nodegraph name="IMP_my_tex" nodedef="ND_my_tex">
    <texcoord name="t" type="vector2"/>
    <extract name="u" type="float"><input name="in" type="vector2" nodename="t"/><input name="index" type="integer" value="0"/></extract>
    <multiply name="m" type="float"><input name="in1" type="float" nodename="u"/><input name="in2" type="float" interfacename="scale"/></multiply>
    <image name="unused" type="float"><input name="file" type="filename" value=""/></image>
    <output name="out" type="float" nodename="m"/>
  </nodegraph>
  <nodegraph name="g">
    <my_tex name="x" type="float"><input name="scale" type="float" value="3"/></my_tex>
    <output name="out" type="float" nodename="x"/>
  </nodegraph>
</materialx>"#;
    let opts = LoadOptions { lenient: true, ..LoadOptions::default() };
    let d = Document::parse(text, std::path::Path::new("lib.mtlx"), &opts).unwrap_or_else(|e| panic!("{e}"));
    let g = d.graph();
    let out = g.output_id("g/out").expect("the texture node loads");
    let mut scratch = graph::EvalScratch::new(g);
    let v = g.eval_output(out, &graph::Footprint::point(glam::Vec2::new(0.25, 0.5)), &mut scratch).ch[0].mean;
    assert!((v - 0.75).abs() < 1e-6, "{v}");
    // The definition graph's own nodes, checked at the defaults, do not warn as the document's.
    assert!(d.graph().warnings().iter().any(|w| w.contains("IMP_my_tex/unused")));
    assert!(!d.warnings().iter().any(|w| w.contains("IMP_my_tex")), "{:?}", d.warnings());
}
