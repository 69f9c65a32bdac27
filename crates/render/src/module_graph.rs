//! Checks of the crate's architecture, read from its own source: the modules' imports form no
//! circle, and the integrator and the shading seam know neither the tile cache nor the profiler
//! (they reach the integrator through [`crate::shading::GraphSource`], not the other way round).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Per top-level module (a file `src/m.rs` or a folder `src/m/`), the other top-level modules
/// its code (comments left out) names as `crate::m` or inside `crate::{...}`.
fn module_imports() -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut modules: BTreeMap<String, Vec<std::path::PathBuf>> = BTreeMap::new();
    for entry in std::fs::read_dir(&src).expect("src is readable") {
        let path = entry.expect("a directory entry").path();
        let name = path.file_stem().and_then(|s| s.to_str()).expect("a UTF-8 name").to_string();
        if path.is_dir() {
            let files = std::fs::read_dir(&path)
                .expect("a module folder is readable")
                .map(|e| e.expect("a directory entry").path())
                .filter(|p| p.extension().is_some_and(|e| e == "rs"))
                .collect();
            modules.insert(name, files);
        } else if path.extension().is_some_and(|e| e == "rs") && name != "lib" {
            modules.entry(name).or_default().push(path);
        }
    }
    let names: BTreeSet<String> = modules.keys().cloned().collect();
    let mut graph = BTreeMap::new();
    for (module, files) in &modules {
        let mut uses = BTreeSet::new();
        for file in files {
            let text = std::fs::read_to_string(file).expect("a source file is readable");
            let code: String = text.lines().map(|l| l.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n");
            for name in crate_paths(&code) {
                if names.contains(&name) && name != *module {
                    uses.insert(name);
                }
            }
        }
        graph.insert(module.clone(), uses);
    }
    graph
}

/// The first segment of every `crate::` path in `code`, and of every path in a
/// `crate::{...}` group (at the group's top level).
fn crate_paths(code: &str) -> Vec<String> {
    let ident =
        |s: &str| -> String { s.trim_start().chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect() };
    let mut out = Vec::new();
    for (i, _) in code.match_indices("crate::") {
        let rest = &code[i + "crate::".len()..];
        let Some(group) = rest.strip_prefix('{') else {
            out.push(ident(rest));
            continue;
        };
        let (mut depth, mut start) = (0usize, 0usize);
        for (k, c) in group.char_indices() {
            match c {
                '{' => depth += 1,
                '}' if depth == 0 => {
                    out.push(ident(&group[start..k]));
                    break;
                }
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    out.push(ident(&group[start..k]));
                    start = k + 1;
                }
                _ => {}
            }
        }
    }
    out
}

/// A circle of imports, if there is one.
fn find_circle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        New,
        Open,
        Done,
    }
    fn visit(
        m: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        marks: &mut BTreeMap<String, Mark>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        marks.insert(m.to_string(), Mark::Open);
        stack.push(m.to_string());
        for next in graph.get(m).into_iter().flatten() {
            match marks.get(next.as_str()).copied().unwrap_or(Mark::New) {
                Mark::Open => {
                    let start = stack.iter().position(|s| s == next).expect("an open module is on the stack");
                    let mut circle = stack[start..].to_vec();
                    circle.push(next.clone());
                    return Some(circle);
                }
                Mark::New => {
                    if let Some(c) = visit(next, graph, marks, stack) {
                        return Some(c);
                    }
                }
                Mark::Done => {}
            }
        }
        stack.pop();
        marks.insert(m.to_string(), Mark::Done);
        None
    }
    let mut marks = BTreeMap::new();
    for m in graph.keys() {
        if marks.get(m.as_str()).copied().unwrap_or(Mark::New) == Mark::New {
            if let Some(c) = visit(m, graph, &mut marks, &mut Vec::new()) {
                return Some(c);
            }
        }
    }
    None
}

fn describe(graph: &BTreeMap<String, BTreeSet<String>>) -> String {
    graph
        .iter()
        .map(|(m, uses)| format!("{m} -> {}", uses.iter().cloned().collect::<Vec<_>>().join(", ")))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn no_module_imports_another_that_imports_it_back() {
    let graph = module_imports();
    // The scan sees the modules it should: a broken scan would pass vacuously.
    for m in ["integrator", "shading", "caching", "profiling", "bsdf", "material"] {
        assert!(graph.contains_key(m), "module {m} not found:\n{}", describe(&graph));
    }
    assert!(graph["integrator"].contains("shading") && graph["caching"].contains("integrator"));
    if let Some(circle) = find_circle(&graph) {
        panic!("the modules import each other in a circle: {}\n{}", circle.join(" -> "), describe(&graph));
    }
}

#[test]
fn the_integrator_and_the_shading_seam_know_neither_the_cache_nor_the_profiler() {
    let graph = module_imports();
    for m in ["integrator", "shading", "material", "pathfootprint", "scene", "loader"] {
        for strategy in ["caching", "profiling"] {
            assert!(!graph[m].contains(strategy), "{m} imports {strategy}:\n{}", describe(&graph));
        }
    }
}

#[test]
fn crate_paths_are_read_from_plain_paths_and_groups() {
    let code = "use crate::a::X;\nuse crate::{b::{Y, Z}, c,\n d::W};\nlet v = crate::e::f();";
    assert_eq!(crate_paths(code), ["a", "b", "c", "d", "e"]);
}

#[test]
fn the_circle_finder_finds_circles() {
    let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let edge = |g: &mut BTreeMap<String, BTreeSet<String>>, a: &str, b: &str| {
        g.entry(a.into()).or_default().insert(b.into());
        g.entry(b.into()).or_default();
    };
    edge(&mut g, "a", "b");
    edge(&mut g, "b", "c");
    edge(&mut g, "a", "c");
    assert_eq!(find_circle(&g), None);
    edge(&mut g, "c", "a");
    let circle = find_circle(&g).expect("a -> b -> c -> a");
    assert_eq!(circle.first(), circle.last());
    assert!(circle.len() >= 3, "{circle:?}");
}
