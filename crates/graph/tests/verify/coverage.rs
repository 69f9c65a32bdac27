//! Coverage of MaterialX 1.39's standard library: every nodedef of `stdlib_defs.mtlx` (the
//! signature table `tests/data/stdlib_nodedefs.json`, written by `scripts/mtlx-nodedefs.py` from
//! the `materialx` package) is either implemented or listed, with a reason, in the README's table
//! "MaterialX nodes tessera rejects".
//!
//! A nodedef counts as implemented when a document holding one node of it — every input set to a
//! value of the declared type, the output of the declared type — loads strictly through
//! [`Document::parse`] and gives an output of that type. Outputs that cannot be graph outputs are
//! read through a consumer: a matrix through `transformmatrix`, a filename through an `image`'s
//! `file`, a string through an `image`'s `uaddressmode`, a shader through a `surfacematerial`
//! (which must then bind as a material), and a material must itself bind.
//!
//! The README table is the single list: the test fails on a nodedef that neither loads nor is
//! listed, and on a listed one that loads (a stale row).

use graph::{Document, LoadOptions};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// One input of a nodedef.
pub struct Input {
    pub name: String,
    pub ty: String,
    pub value: Option<String>,
    pub enumeration: Vec<String>,
}

/// One nodedef of the signature table.
pub struct NodeDef {
    pub name: String,
    pub node: String,
    pub nodegroup: String,
    pub outputs: Vec<(String, String)>,
    pub inputs: Vec<Input>,
}

/// The signature table of MaterialX's standard library.
pub fn nodedefs() -> Vec<NodeDef> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/stdlib_nodedefs.json");
    let table: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let s = |v: &serde_json::Value| v.as_str().unwrap_or_default().to_string();
    table["nodedefs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|nd| NodeDef {
            name: s(&nd["name"]),
            node: s(&nd["node"]),
            nodegroup: s(&nd["nodegroup"]),
            outputs: nd["outputs"].as_array().unwrap().iter().map(|o| (s(&o["name"]), s(&o["type"]))).collect(),
            inputs: nd["inputs"]
                .as_array()
                .unwrap()
                .iter()
                .map(|i| Input {
                    name: s(&i["name"]),
                    ty: s(&i["type"]),
                    value: i["value"].as_str().map(str::to_string),
                    enumeration: i["enum"]
                        .as_array()
                        .map(|a| a.iter().map(|e| s(e).trim().to_string()).collect())
                        .unwrap_or_default(),
                })
                .collect(),
        })
        .collect()
}

/// A value of MaterialX type `ty` for an input that has no default.
fn typed_value(ty: &str) -> &'static str {
    match ty {
        "float" => "0.5",
        "integer" => "1",
        "boolean" => "false",
        "vector2" => "0.5, 0.5",
        "vector3" | "color3" => "0.5, 0.5, 0.5",
        "vector4" | "color4" => "0.5, 0.5, 0.5, 0.5",
        "matrix33" => "1, 0, 0, 0, 1, 0, 0, 0, 1",
        "matrix44" => "1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1",
        _ => "",
    }
}

/// Whether `ty` can be an output of a tessera graph.
fn graph_type(ty: &str) -> bool {
    graph::ValueType::from_name(ty).is_some()
}

/// `<input>` elements giving every input of `nd` a value of its declared type.
fn inputs_xml(nd: &NodeDef) -> String {
    let mut s = String::new();
    for i in &nd.inputs {
        if matches!(i.ty.as_str(), "surfaceshader" | "displacementshader" | "volumeshader" | "lightshader") {
            continue;
        }
        let value = match &i.value {
            Some(v) if !v.is_empty() => v.clone(),
            _ => i.enumeration.first().cloned().unwrap_or_else(|| typed_value(&i.ty).to_string()),
        };
        let _ = writeln!(s, "    <input name=\"{}\" type=\"{}\" value=\"{}\"/>", i.name, i.ty, value);
    }
    s
}

/// What loading one nodedef's document found: `Ok` when implemented, else why not.
fn load(nd: &NodeDef) -> Result<(), String> {
    let multi = nd.outputs.len() > 1;
    let node_type = if multi { "multioutput".to_string() } else { nd.outputs[0].1.clone() };
    let node = format!("  <{} name=\"n\" type=\"{node_type}\">\n{}  </{}>\n", nd.node, inputs_xml(nd), nd.node);
    let mut graph_outputs = String::new();
    let mut top = String::new();
    let mut expect: Vec<(String, String)> = Vec::new();
    let mut material = false;
    for (name, ty) in &nd.outputs {
        let sel = if multi { format!(" output=\"{name}\"") } else { String::new() };
        let consumer = |category: &str, ty_out: &str, input: &str, input_ty: &str| {
            format!(
                "  <{category} name=\"c_{name}\" type=\"{ty_out}\">\n    <input name=\"{input}\" type=\"{input_ty}\" \
                 nodename=\"n\"{sel}/>\n  </{category}>\n  <output name=\"{name}\" type=\"{ty_out}\" \
                 nodename=\"c_{name}\"/>\n"
            )
        };
        match ty.as_str() {
            t if graph_type(t) => {
                let _ = writeln!(graph_outputs, "  <output name=\"{name}\" type=\"{t}\" nodename=\"n\"{sel}/>");
                expect.push((name.clone(), t.to_string()));
            }
            "matrix33" => {
                graph_outputs += &consumer("transformmatrix", "vector3", "mat", "matrix33");
                expect.push((name.clone(), "vector3".into()));
            }
            "matrix44" => {
                graph_outputs += &consumer("transformmatrix", "vector4", "mat", "matrix44");
                expect.push((name.clone(), "vector4".into()));
            }
            "filename" => {
                graph_outputs += &consumer("image", "color3", "file", "filename");
                expect.push((name.clone(), "color3".into()));
            }
            "string" => {
                graph_outputs += &consumer("image", "color3", "uaddressmode", "string").replacen(
                    "\n",
                    "\n    <input name=\"file\" type=\"filename\" value=\"\"/>\n",
                    1,
                );
                expect.push((name.clone(), "color3".into()));
            }
            "surfaceshader" => {
                top = format!(
                    "{}<surfacematerial name=\"m\" type=\"material\">\n  <input name=\"surfaceshader\" \
                     type=\"surfaceshader\" nodename=\"n\"/>\n</surfacematerial>\n",
                    node.replace("\n  ", "\n")
                );
                material = true;
            }
            "material" => {
                // The node itself is the material, its shader a standard_surface.
                let shader_inputs: String = nd
                    .inputs
                    .iter()
                    .filter(|i| i.ty == "surfaceshader")
                    .map(|i| format!("  <input name=\"{}\" type=\"surfaceshader\" nodename=\"s\"/>\n", i.name))
                    .collect();
                top = format!(
                    "<standard_surface name=\"s\" type=\"surfaceshader\"/>\n<{0} name=\"m\" \
                     type=\"material\">\n{shader_inputs}{1}</{0}>\n",
                    nd.node,
                    inputs_xml(nd).replace("\n    ", "\n  ")
                );
                material = true;
            }
            t => return Err(format!("output type `{t}` has no consumer in this test")),
        }
    }
    let body = if material { top } else { format!("<nodegraph name=\"g\">\n{node}{graph_outputs}</nodegraph>\n") };
    let text = format!("<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n{body}</materialx>\n");
    let doc = Document::parse(&text, Path::new("coverage.mtlx"), &LoadOptions::default()).map_err(|e| {
        // The first line, without the list of supported nodes that unsupported ones carry.
        let s = e.to_string();
        let line = s.lines().next().unwrap_or_default();
        line.split("; supported nodes").next().unwrap_or_default().to_string()
    })?;
    if material {
        return match doc.material("m") {
            Some(_) => Ok(()),
            None => Err("the document loads but `m` does not bind as a material".into()),
        };
    }
    let graph = doc.graph();
    for (name, ty) in expect {
        let full = format!("g/{name}");
        let Some(id) = graph.output_id(&full) else {
            return Err(format!("no output `{full}`"));
        };
        let got = graph.output(id).ty.to_string();
        if got != ty {
            return Err(format!("output `{full}` is {got}, declared {ty}"));
        }
    }
    Ok(())
}

/// The rows of the README's table "MaterialX nodes tessera rejects": the names (categories or
/// nodedefs, a trailing `*` matching any suffix) of each row and its reason.
pub fn rejects() -> Vec<(Vec<String>, String)> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut rows = Vec::new();
    let mut inside = false;
    for line in text.lines() {
        if line.starts_with('#') {
            inside = line.contains("MaterialX nodes tessera rejects");
            continue;
        }
        if !inside || !line.starts_with("| `") {
            continue;
        }
        let cells: Vec<&str> = line.trim_matches('|').split(" | ").map(str::trim).collect();
        assert!(cells.len() == 2 && !cells[1].is_empty(), "README rejects row without a reason: {line}");
        let names = cells[0].split(',').map(|n| n.trim().trim_matches('`').to_string()).collect();
        rows.push((names, cells[1].to_string()));
    }
    assert!(!rows.is_empty(), "README has no table under a heading \"MaterialX nodes tessera rejects\"");
    rows
}

/// Whether a reject-table name covers nodedef `nd`.
pub fn covers(name: &str, nd: &NodeDef) -> bool {
    match name.strip_suffix('*') {
        Some(prefix) => nd.name.starts_with(prefix),
        None => name == nd.name || name == nd.node,
    }
}

#[test]
fn every_stdlib_nodedef_is_implemented_or_rejected() {
    let defs = nodedefs();
    assert_eq!(defs.len(), 693, "MaterialX 1.39.5's stdlib has 693 nodedefs");
    let rows = rejects();
    let mut missing = Vec::new();
    let mut stale = Vec::new();
    let mut used: BTreeMap<String, usize> = BTreeMap::new();
    let mut implemented = 0;
    for nd in &defs {
        let listed: Vec<&String> = rows.iter().flat_map(|(n, _)| n).filter(|n| covers(n, nd)).collect();
        for n in &listed {
            *used.entry(n.to_string()).or_default() += 1;
        }
        match (load(nd), listed.is_empty()) {
            (Ok(()), true) => implemented += 1,
            (Ok(()), false) => stale.push(format!("{} ({}) loads but is listed as rejected", nd.name, nd.node)),
            (Err(e), true) => missing.push(format!("| `{}` | {} |", nd.name, e)),
            (Err(_), false) => {}
        }
    }
    for (names, _) in &rows {
        for n in names {
            if !used.contains_key(n) {
                stale.push(format!("`{n}` names no nodedef of the table"));
            }
        }
    }
    println!("{implemented} of {} nodedefs implemented", defs.len());
    assert!(
        missing.is_empty() && stale.is_empty(),
        "nodedefs neither implemented nor listed in README's \"MaterialX nodes tessera rejects\":\n{}\nstale rows:\n{}",
        missing.join("\n"),
        stale.join("\n")
    );
}

/// tessera's own references (`tests/mtlx-refs`) bake every nodedef whose outputs are all values,
/// and skip only the others, each output once at least.
#[test]
fn own_references_cover_every_value_nodedef() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mtlx-refs/manifest.json");
    let manifest: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let mut baked: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for b in manifest["bakes"].as_array().unwrap() {
        let element = b["element"].as_str().unwrap();
        let output = element.rsplit('/').next().unwrap().to_string();
        baked.entry(b["nodedef"].as_str().unwrap().to_string()).or_default().push(output);
    }
    let skipped: Vec<&str> =
        manifest["skipped"].as_array().unwrap().iter().map(|s| s["nodedef"].as_str().unwrap()).collect();
    let mut problems = Vec::new();
    for nd in nodedefs() {
        let value = nd.outputs.iter().all(|(_, ty)| graph_type(ty));
        match (value, baked.get(&nd.name), skipped.contains(&nd.name.as_str())) {
            (true, Some(outs), false) => {
                for (o, _) in &nd.outputs {
                    if !outs.contains(o) {
                        problems.push(format!("{}: output {o} is not baked", nd.name));
                    }
                }
            }
            (true, _, _) => problems.push(format!("{} has value outputs but no bake", nd.name)),
            (false, None, true) => {}
            (false, _, _) => problems.push(format!("{} has a non-value output but is not listed as skipped", nd.name)),
        }
    }
    assert!(problems.is_empty(), "own references out of step with the nodedef table:\n{}", problems.join("\n"));
}
