//! ns per evaluation of every output of each demo scene's graph, unfiltered (Σ = 0) and filtered
//! at isotropic footprints from 1e-4 to 10 uv units, over a fixed set of uv points; and the
//! cost of the per-node instrumentation (evaluation counts, one timed evaluation in 64): the same
//! evaluations with it on and off, interleaved in one run, printed as a ratio per document.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::Vec2;
use graph::{Document, EvalScratch, Filtered, Footprint, NoOverride, Value};
use std::path::PathBuf;

fn demo_graphs(c: &mut Criterion) {
    let names = demo_documents();
    let uvs: Vec<Vec2> = (0..64).map(|i| Vec2::new((i as f32 * 0.618034) % 1.0, (i as f32 * 0.754878) % 1.0)).collect();
    let mut group = c.benchmark_group("graph_eval");
    group.sample_size(20).measurement_time(std::time::Duration::from_secs(2));
    group.throughput(Throughput::Elements(uvs.len() as u64));
    for path in names {
        let doc = Document::load(&path).expect("demo graph loads");
        let g = doc.graph();
        let outputs: Vec<_> = (0..g.outputs().len()).map(|i| graph::OutputId(i as u32)).collect();
        let plan = g.eval_order(&outputs);
        let mut scratch = EvalScratch::new(g);
        let mut out = vec![Filtered::constant(Value::float(0.0)); outputs.len()];
        let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
        for sigma in [0.0f32, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0] {
            group.bench_with_input(BenchmarkId::new(stem.clone(), format!("sigma={sigma:e}")), &sigma, |b, &sigma| {
                b.iter(|| {
                    for uv in &uvs {
                        let fp = if sigma == 0.0 { Footprint::point(*uv) } else { Footprint::isotropic(*uv, sigma) };
                        g.eval(&plan, &fp, &mut scratch, &NoOverride, &mut out);
                    }
                    std::hint::black_box(&out);
                })
            });
        }
    }
    group.finish();
}

/// Instrumentation on against off, per demo document and footprint: rounds alternate the two
/// (so drift and frequency changes hit both alike), and the minimum over rounds of each is
/// compared. Printed, not asserted.
fn instrumentation_overhead(_: &mut Criterion) {
    let uvs: Vec<Vec2> =
        (0..256).map(|i| Vec2::new((i as f32 * 0.618034) % 1.0, (i as f32 * 0.754878) % 1.0)).collect();
    println!("instrumentation overhead (evaluation counts + sampled timing), min of 15 interleaved rounds:");
    for path in demo_documents() {
        let doc = Document::load(&path).expect("demo graph loads");
        let g = doc.graph();
        let outputs: Vec<_> = (0..g.outputs().len()).map(|i| graph::OutputId(i as u32)).collect();
        let plan = g.eval_order(&outputs);
        let mut out = vec![Filtered::constant(Value::float(0.0)); outputs.len()];
        let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
        for sigma in [0.0f32, 1e-3] {
            let mut best = [f64::INFINITY; 2];
            for round in 0..30 {
                let on = round % 2 == 0;
                let mut scratch = EvalScratch::new(g);
                scratch.set_instrumented(on);
                let t = std::time::Instant::now();
                for _ in 0..8 {
                    for uv in &uvs {
                        let fp = if sigma == 0.0 { Footprint::point(*uv) } else { Footprint::isotropic(*uv, sigma) };
                        g.eval(&plan, &fp, &mut scratch, &NoOverride, &mut out);
                    }
                }
                std::hint::black_box(&out);
                let ns = t.elapsed().as_nanos() as f64 / (8 * uvs.len()) as f64;
                let k = on as usize;
                best[k] = best[k].min(ns);
            }
            println!(
                "  {stem:<14} sigma={sigma:<6e} off {:>8.0} ns/eval, on {:>8.0} ns/eval: overhead {:+.1} %",
                best[0],
                best[1],
                (best[1] / best[0] - 1.0) * 100.0
            );
        }
    }
}

fn demo_documents() -> Vec<PathBuf> {
    let scenes = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let mut names: Vec<PathBuf> = std::fs::read_dir(&scenes)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "mtlx"))
        .collect();
    names.sort();
    names
}

criterion_group!(benches, instrumentation_overhead, demo_graphs);
criterion_main!(benches);
