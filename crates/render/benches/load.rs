//! Scene loading time against scene size: scenes of 10³, 10⁴ and 10⁵ shapes, each placed by a
//! `to_world` of four operations (translate, rotate, scale, a 4×4 matrix), parsed and built into
//! a renderable scene (BVH included). Reported per shape and per byte, so linear loading shows
//! as the same time per shape at every size.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use std::path::Path;

/// A scene of `n` small spheres and rectangles on a grid, each with its own transform.
fn scene(n: usize) -> String {
    let mut s = String::with_capacity(n * 420 + 1024);
    s.push_str(
        "<scene version=\"3.0.0\">\n<integrator type=\"path\"/>\n\
         <sensor type=\"perspective\"><float name=\"fov\" value=\"40\"/>\
         <transform name=\"to_world\"><lookat origin=\"0, 0, 400\" target=\"0, 0, 0\" up=\"0, 1, 0\"/></transform>\
         <film type=\"hdrfilm\"><integer name=\"width\" value=\"16\"/><integer name=\"height\" value=\"16\"/></film></sensor>\n\
         <emitter type=\"constant\"/>\n<bsdf type=\"diffuse\" id=\"grey\"/>\n",
    );
    let side = (n as f64).sqrt().ceil() as usize;
    for i in 0..n {
        let (x, y) = ((i % side) as f64 - side as f64 / 2.0, (i / side) as f64 - side as f64 / 2.0);
        let kind = if i % 2 == 0 { "sphere" } else { "rectangle" };
        s.push_str(&format!(
            "<shape type=\"{kind}\"><ref id=\"grey\"/><transform name=\"to_world\">\
             <translate x=\"{x}\" y=\"{y}\" z=\"0\"/><rotate y=\"1\" angle=\"{a}\"/><scale value=\"0.4\"/>\
             <matrix value=\"1 0 0 0.01 0 1 0 0 0 0 1 0 0 0 0 1\"/></transform></shape>\n",
            a = i % 360
        ));
    }
    s.push_str("</scene>\n");
    s
}

fn load(c: &mut Criterion) {
    let mut group = c.benchmark_group("load");
    group.sample_size(10).warm_up_time(std::time::Duration::from_millis(200));
    for n in [1_000usize, 10_000, 100_000] {
        let text = scene(n);
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::new("shapes", n), &text, |b, text| {
            b.iter(|| {
                let scene = render::loader::load_str(text, Path::new("bench.xml"), Path::new("."), &[]).expect("loads");
                std::hint::black_box(scene);
            })
        });
        println!("load/shapes/{n}: {} bytes", text.len());
    }
    group.finish();
}

criterion_group!(benches, load);
criterion_main!(benches);
