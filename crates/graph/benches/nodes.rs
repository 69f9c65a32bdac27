//! ns per evaluation of single nodes, by node type: each node reads `texcoord × 8` (or a noise of
//! it, for the math nodes), unfiltered and filtered at σ = 1e-5 to 10 uv units. The cost of the
//! texcoord and scale nodes is included in every row (measure `multiply` for it alone).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::Vec2;
use graph::{Document, EvalScratch, Footprint, LoadOptions};

/// (category, output type, the node's XML body after its opening tag's attributes).
const NODES: &[(&str, &str, &str)] = &[
    (
        "multiply",
        "vector2",
        r#"<input name="in1" type="vector2" nodename="t"/><input name="in2" type="vector2" value="8, 8"/>"#,
    ),
    ("noise2d", "float", r#"<input name="texcoord" type="vector2" nodename="s"/>"#),
    (
        "fractal2d",
        "float",
        r#"<input name="texcoord" type="vector2" nodename="s"/><input name="octaves" type="integer" value="6"/>"#,
    ),
    ("cellnoise2d", "float", r#"<input name="texcoord" type="vector2" nodename="s"/>"#),
    ("worleynoise2d", "float", r#"<input name="texcoord" type="vector2" nodename="s"/>"#),
    ("checkerboard", "color3", r#"<input name="texcoord" type="vector2" nodename="s"/>"#),
    ("floor", "float", r#"<input name="in" type="float" nodename="n"/>"#),
    (
        "smoothstep",
        "float",
        r#"<input name="in" type="float" nodename="n"/><input name="low" type="float" value="-0.2"/><input name="high" type="float" value="0.3"/>"#,
    ),
    ("sin", "float", r#"<input name="in" type="float" nodename="n"/>"#),
    ("power", "float", r#"<input name="in1" type="float" nodename="n"/><input name="in2" type="float" value="3"/>"#),
    (
        "mix",
        "float",
        r#"<input name="fg" type="float" nodename="n"/><input name="bg" type="float" value="0.5"/><input name="mix" type="float" nodename="n"/>"#,
    ),
];

fn nodes(c: &mut Criterion) {
    let uvs: Vec<Vec2> = (0..64).map(|i| Vec2::new((i as f32 * 0.618034) % 1.0, (i as f32 * 0.754878) % 1.0)).collect();
    let mut group = c.benchmark_group("node_eval");
    group
        .sample_size(20)
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(1));
    group.throughput(Throughput::Elements(uvs.len() as u64));
    for &(category, ty, body) in NODES {
        let text = format!(
            r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">
<texcoord name="t" type="vector2"/>
<multiply name="s" type="vector2"><input name="in1" type="vector2" nodename="t"/><input name="in2" type="vector2" value="8, 8"/></multiply>
<noise2d name="n" type="float"><input name="texcoord" type="vector2" nodename="s"/></noise2d>
<{category} name="x" type="{ty}">{body}</{category}>
<output name="out" type="{ty}" nodename="x"/></nodegraph></materialx>"#
        );
        let doc = Document::parse(&text, "bench.mtlx".as_ref(), &LoadOptions::default()).expect("bench graph loads");
        let g = doc.graph();
        let out = g.output_id("out").or_else(|| g.output_id("g/out")).expect("output");
        let mut scratch = EvalScratch::new(g);
        for sigma in [0.0f32, 1e-5, 1e-3, 1e-2, 1e-1, 1.0, 10.0] {
            group.bench_with_input(BenchmarkId::new(category, format!("sigma={sigma:e}")), &sigma, |b, &sigma| {
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

criterion_group!(benches, nodes);
criterion_main!(benches);
