//! Bad MaterialX input: every error names the file and the line of the offending element.

use graph::{BuildError, Document, LoadError, LoadErrorKind};
use std::path::PathBuf;

fn load(name: &str, body: &str) -> (PathBuf, LoadError) {
    let dir = std::env::temp_dir().join(format!("graph-errors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
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
