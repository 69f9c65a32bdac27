//! ns per evaluation of one node of every category of MaterialX's standard library that tessera
//! evaluates, unfiltered and filtered, for the issue's rule that a node's filtered evaluation
//! costs at most twice its point evaluation.
//!
//! For each category, one nodedef of the checked-in signature table
//! (`tests/data/stdlib_nodedefs.json`) is taken (float output first, then color3, vector2,
//! vector3, the rest). One input is driven: its `texcoord` where it has one, by `texcoord × 8`;
//! none where it reads a `position` (the geometry's, by default); else its first numeric input, a
//! `vector2` by `texcoord × 8` and any other type by a `noise2d` of that type over it. Every other
//! input keeps its default. Each
//! category is timed over 64 points at σ = 0 (a point), 1e-3, 1e-1 and 10 uv, and so is each
//! driver alone (`upstream_<type>`), so that the table can subtract the
//! driver. Nodedefs with file inputs, several outputs or a non-numeric output are left out; so is
//! every category tessera does not load.
//!
//! `cargo bench -p graph --bench node_costs` measures and then writes the table
//! `docs/benchmarks/node-costs.md` from criterion's estimates; with `NODE_COSTS_TABLE_ONLY=1` it
//! only rewrites the table from the estimates already in `target/criterion/node_costs`.

use criterion::{criterion_group, BenchmarkId, Criterion, Throughput};
use glam::Vec2;
use graph::{Document, EvalScratch, Footprint, LoadOptions};
use serde_json::Value as Json;
use std::collections::BTreeMap;
use std::fmt::Write as _;

const NUMERIC: &[&str] = &["float", "color3", "vector2", "vector3", "color4", "vector4", "integer", "boolean"];
const DRIVEN: &[&str] = &["float", "vector2", "vector3", "vector4", "color3", "color4"];
const SIGMAS: [f32; 4] = [0.0, 1e-3, 1e-1, 10.0];

/// One bench graph: what the node reads and the node itself.
struct Case {
    name: String,
    ty: String,
    body: String,
    /// The node the graph outputs.
    out: &'static str,
    /// The type of the driven input, whose driver is `upstream_<type>` (`none`: nothing driven).
    driven: String,
}

/// The driver of an input of type `ty` (`s` for vector2, else a noise of that type over `s`) and
/// its node name.
fn driver(ty: &str) -> (String, &'static str) {
    match ty {
        "vector2" => (String::new(), "s"),
        _ => (
            format!(
                r#"<noise2d name="src" type="{ty}"><input name="texcoord" type="vector2" nodename="s"/></noise2d>"#
            ),
            "src",
        ),
    }
}

/// The bench document: `texcoord`, `s = texcoord × 8`, `body`, and the output of node `out`.
fn document(ty: &str, body: &str, out: &str) -> String {
    format!(
        r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">
<texcoord name="t" type="vector2"/>
<multiply name="s" type="vector2"><input name="in1" type="vector2" nodename="t"/><input name="in2" type="vector2" value="8, 8"/></multiply>
{body}
<output name="out" type="{ty}" nodename="{out}"/></nodegraph></materialx>"#
    )
}

/// One case per category, from the signature table.
fn cases() -> Vec<Case> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/stdlib_nodedefs.json");
    let table: Json = serde_json::from_str(&std::fs::read_to_string(path).expect("the signature table")).unwrap();
    let mut by_category: BTreeMap<String, Vec<&Json>> = BTreeMap::new();
    for nd in table["nodedefs"].as_array().unwrap() {
        let outs = nd["outputs"].as_array().unwrap();
        let inputs = nd["inputs"].as_array().unwrap();
        let files = inputs.iter().any(|i| i["type"] == "filename");
        if outs.len() == 1 && NUMERIC.contains(&outs[0]["type"].as_str().unwrap()) && !files {
            by_category.entry(nd["node"].as_str().unwrap().to_string()).or_default().push(nd);
        }
    }
    let rank = |nd: &Json| NUMERIC.iter().position(|t| nd["outputs"][0]["type"] == *t).unwrap();
    by_category
        .into_iter()
        .map(|(category, defs)| {
            let nd = defs.into_iter().min_by_key(|nd| rank(nd)).unwrap();
            let ty = nd["outputs"][0]["type"].as_str().unwrap().to_string();
            let inputs = nd["inputs"].as_array().unwrap();
            let named = |n: &str| inputs.iter().find(|i| i["name"] == n);
            // The coordinate where the node has one (a `position` keeps its default: the geometry's,
            // as documents use it); else the first numeric input.
            let first = match (named("texcoord"), named("position")) {
                (Some(t), _) if t["type"] == "vector2" => Some(t),
                (_, Some(_)) => None,
                _ => inputs.iter().find(|i| DRIVEN.contains(&i["type"].as_str().unwrap())),
            };
            let (pre, input) = match first {
                Some(i) => {
                    let ity = i["type"].as_str().unwrap();
                    let (pre, src) = driver(ity);
                    (pre, format!(r#"<input name="{}" type="{ity}" nodename="{src}"/>"#, i["name"].as_str().unwrap()))
                }
                None => (String::new(), String::new()),
            };
            let body = format!(r#"{pre}<{category} name="x" type="{ty}">{input}</{category}>"#);
            let driven = first.map_or("none", |i| i["type"].as_str().unwrap()).to_string();
            Case { name: format!("{category}_{ty}"), ty, body, out: "x", driven }
        })
        .collect()
}

fn node_costs(c: &mut Criterion) {
    let uvs: Vec<Vec2> = (0..64).map(|i| Vec2::new((i as f32 * 0.618034) % 1.0, (i as f32 * 0.754878) % 1.0)).collect();
    let mut group = c.benchmark_group("node_costs");
    group
        .sample_size(10)
        .warm_up_time(std::time::Duration::from_millis(200))
        .measurement_time(std::time::Duration::from_millis(400));
    group.throughput(Throughput::Elements(uvs.len() as u64));
    // A driver alone is the graph whose output is the driver itself.
    let upstream = DRIVEN.iter().map(|ty| {
        let (pre, src) = driver(ty);
        Case { name: format!("upstream_{ty}"), ty: ty.to_string(), body: pre, out: src, driven: ty.to_string() }
    });
    for case in upstream.collect::<Vec<_>>().into_iter().chain(cases()) {
        let text = document(&case.ty, &case.body, case.out);
        let doc = match Document::parse(&text, "node_costs.mtlx".as_ref(), &LoadOptions::default()) {
            Ok(d) => d,
            Err(e) => {
                eprintln!("skipped {}: {}", case.name, e.to_string().lines().next().unwrap_or(""));
                continue;
            }
        };
        let g = doc.graph();
        let Some(out) = g.output_id("out").or_else(|| g.output_id("g/out")) else {
            eprintln!("skipped {}: no output", case.name);
            continue;
        };
        let mut scratch = EvalScratch::new(g);
        for sigma in SIGMAS {
            group.bench_with_input(BenchmarkId::new(&case.name, format!("sigma={sigma:e}")), &sigma, |b, &sigma| {
                b.iter(|| {
                    for uv in &uvs {
                        let fp = if sigma == 0.0 { Footprint::point(*uv) } else { Footprint::isotropic(*uv, sigma) };
                        std::hint::black_box(g.eval_output(out, &fp, &mut scratch));
                    }
                })
            });
        }
    }
    group.finish();
}

/// ns per evaluation of `case` at `sigma` from criterion's estimate (the mean over 64 points).
fn estimate(dir: &std::path::Path, case: &str, sigma: f32) -> Option<f64> {
    let path = dir.join(case).join(format!("sigma={sigma:e}")).join("new/estimates.json");
    let j: Json = serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
    Some(j["mean"]["point_estimate"].as_f64()? / 64.0)
}

/// Writes `docs/benchmarks/node-costs.md` from the estimates of the last run.
fn write_table() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let target = std::env::var_os("CARGO_TARGET_DIR").map_or(root.join("target"), std::path::PathBuf::from);
    let dir = target.join("criterion/node_costs");
    let up: BTreeMap<&str, [Option<f64>; 4]> =
        DRIVEN.iter().map(|ty| (*ty, SIGMAS.map(|s| estimate(&dir, &format!("upstream_{ty}"), s)))).collect();
    let mut md = String::from(
        "# Node costs, point and filtered\n\n\
         Written by `cargo bench -p graph --bench node_costs` (`crates/graph/benches/node_costs.rs` says how each \
         node is driven). One run on one machine, one thread: compare rows of this table with each other, not \
         with another run (this host varies up to 2× between runs).\n\n\
         Each row: one nodedef per category with one input driven (its `texcoord` by `texcoord × 8`; none where \
         it reads a `position`, which is then the geometry's; else its first numeric input, by `texcoord × 8` or \
         a `noise2d` of its type), ns per evaluation of the whole graph at σ = 0 (a point), 1e-3, 1e-1 and \
         10 uv; then the node alone (the graph less its driver alone, at the same σ; `<1` where the difference is \
         below a nanosecond) and the largest ratio of the node's filtered to its point cost, the issue's rule \
         being at most 2.\n\n\
         | node | driven input | graph: point | 1e-3 | 1e-1 | 10 | node: point | 1e-3 | 1e-1 | 10 | filtered / point |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let fmt =
        |x: Option<f64>| x.map_or("—".to_string(), |v| if v < 1.0 { "<1".to_string() } else { format!("{v:.0}") });
    let mut rows = 0;
    for case in cases() {
        let total = SIGMAS.map(|s| estimate(&dir, &case.name, s));
        if total.iter().all(Option::is_none) {
            continue;
        }
        let driven = case.driven;
        let base = up.get(driven.as_str()).copied().unwrap_or([Some(0.0); 4]);
        let alone: Vec<Option<f64>> =
            total.iter().zip(base).map(|(t, b)| Some((t.as_ref()? - b.unwrap_or(0.0)).max(0.0))).collect();
        let ratio = match alone[0] {
            Some(p) if p >= 1.0 => alone[1..]
                .iter()
                .flatten()
                .map(|f| f / p)
                .fold(None, |m: Option<f64>, r| Some(m.map_or(r, |m| m.max(r)))),
            _ => None,
        };
        let cells: Vec<String> = total.iter().map(|x| fmt(*x)).chain(alone.iter().map(|x| fmt(*x))).collect();
        let ratio = ratio.map_or("—".to_string(), |r| format!("{r:.1}"));
        md.push_str(&format!("| `{}` | {} | {} | {ratio} |\n", case.name, driven, cells.join(" | ")));
        rows += 1;
    }
    let _ = writeln!(md, "\n{rows} nodes. Drivers alone (ns per evaluation, σ = 0, 1e-3, 1e-1, 10):\n");
    for (ty, v) in &up {
        let _ = writeln!(md, "- `{ty}`: {}", v.map(fmt).join(", "));
    }
    let out = root.join("docs/benchmarks/node-costs.md");
    std::fs::write(&out, md).expect("docs/benchmarks is writable");
    eprintln!("wrote {}", out.display());
}

criterion_group!(benches, node_costs);

fn main() {
    if std::env::var_os("NODE_COSTS_TABLE_ONLY").is_none() {
        benches();
        Criterion::default().configure_from_args().final_summary();
    }
    write_table();
}
