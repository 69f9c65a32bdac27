//! The evaluator API the renderer and the tile cache rely on: overrides, direct node
//! evaluation, plans, statistics, material bindings.

use crate::common;
use glam::{Mat2, Vec2};
use graph::{
    Document, EvalScratch, EvalStats, Filtered, Footprint, Graph, LoadOptions, MaterialSource, NoOverride, NodeId,
    NodeOverride, Value, ValueType,
};

const TEXT: &str = r#"<?xml version="1.0"?>
<materialx version="1.39">
  <nodegraph name="g">
    <texcoord name="t" type="vector2"/>
    <multiply name="s" type="vector2"><input name="in1" type="vector2" nodename="t"/><input name="in2" type="vector2" value="4, 4"/></multiply>
    <fractal2d name="n" type="float"><input name="texcoord" type="vector2" nodename="s"/></fractal2d>
    <add name="a" type="float"><input name="in1" type="float" nodename="n"/><input name="in2" type="float" value="0.5"/></add>
    <convert name="c" type="color3"><input name="in" type="float" nodename="a"/></convert>
    <output name="out" type="color3" nodename="c"/>
    <output name="height" type="float" nodename="n"/>
  </nodegraph>
  <standard_surface name="SR" type="surfaceshader">
    <input name="base_color" type="color3" nodegraph="g" output="out"/>
    <input name="specular_roughness" type="float" value="0.4"/>
    <input name="coat" type="float" value="0.5"/>
  </standard_surface>
  <surfacematerial name="M" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SR"/></surfacematerial>
</materialx>"#;

fn doc() -> Document {
    Document::parse(TEXT, "api.mtlx".as_ref(), &LoadOptions::default()).unwrap()
}

struct Fixed(NodeId);

impl NodeOverride for Fixed {
    fn lookup(&self, node: NodeId, _: &Footprint) -> Option<Filtered> {
        (node == self.0).then(|| Filtered::constant(Value::float(0.25)))
    }
}

#[test]
fn graph_is_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<Graph>();
    check::<Document>();
}

#[test]
fn override_replaces_a_node_and_cuts_its_upstream() {
    let d = doc();
    let g = d.graph();
    let n = g.node_id("g/n").unwrap();
    let out = g.output_id("g/out").unwrap();
    let mut scratch = EvalScratch::new(g);
    let fp = Footprint::new(Vec2::new(0.3, 0.6), Mat2::from_diagonal(Vec2::splat(1e-4)));
    let v = g.eval_output_with(out, &fp, &mut scratch, &Fixed(n));
    assert!((v.ch[0].mean - 0.75).abs() < 1e-6);
    assert_eq!(scratch.lookups()[n.0 as usize], 1);
    for name in ["g/t", "g/s", "g/n"] {
        assert_eq!(scratch.evaluations()[g.node_id(name).unwrap().0 as usize], 0, "{name} evaluated");
    }
    // eval_node_direct evaluates the node itself even when the override would answer it.
    let direct = g.eval_node_direct(n, &fp, &mut scratch, &Fixed(n));
    let plain = g.eval_output(g.output_id("g/height").unwrap(), &fp, &mut scratch);
    assert_eq!(direct.ch[0].mean, plain.ch[0].mean);
}

#[test]
fn plans_evaluate_several_outputs() {
    let d = doc();
    let g = d.graph();
    let outs = [g.output_id("g/out").unwrap(), g.output_id("g/height").unwrap()];
    let plan = g.eval_order(&outs);
    assert_eq!(plan.nodes().len(), 5);
    let mut scratch = EvalScratch::new(g);
    let mut vals = [Filtered::zero(ValueType::Float); 2];
    let fp = Footprint::point(Vec2::new(0.1, 0.2));
    g.eval(&plan, &fp, &mut scratch, &NoOverride, &mut vals);
    assert!((vals[0].ch[0].mean - (vals[1].ch[0].mean + 0.5)).abs() < 1e-6);
    assert_eq!(vals[0].ty, ValueType::Color3);
    let mut stats = EvalStats::default();
    scratch.merge_stats_into(&mut stats);
    assert!(stats.evaluations.iter().all(|&c| c == 1));
    assert_eq!(stats.work.octaves, 3);
}

/// Instrumentation (counts, sampled timings) only observes: turned off, every value is
/// bit-identical and the counters stay zero; on, every node counts each evaluation and one in
/// `TIMING_PERIOD` is timed.
#[test]
fn instrumentation_only_observes() {
    let d = doc();
    let g = d.graph();
    let out = g.output_id("g/out").unwrap();
    let (mut on, mut off) = (EvalScratch::new(g), EvalScratch::new(g));
    off.set_instrumented(false);
    let n = 200u64;
    for i in 0..n {
        let fp = Footprint::isotropic(Vec2::new(0.013 * i as f32, 0.4), if i % 2 == 0 { 0.0 } else { 1e-3 });
        let (a, b) = (g.eval_output(out, &fp, &mut on), g.eval_output(out, &fp, &mut off));
        for c in 0..3 {
            assert_eq!(a.ch[c].mean.to_bits(), b.ch[c].mean.to_bits());
            assert_eq!(a.ch[c].var.to_bits(), b.ch[c].var.to_bits());
        }
    }
    let (mut s_on, mut s_off) = (EvalStats::default(), EvalStats::default());
    on.merge_stats_into(&mut s_on);
    off.merge_stats_into(&mut s_off);
    assert!(s_off.evaluations.iter().all(|&c| c == 0) && s_off.timed.iter().all(|&c| c == 0));
    assert_eq!(s_on.work, s_off.work);
    assert_eq!(s_on.evaluations, vec![n; g.node_count()]);
    assert!(s_on.timed.iter().zip(&s_on.evaluations).all(|(&t, &e)| t == e.div_ceil(graph::TIMING_PERIOD)));
}

#[test]
fn material_binding_exposes_constants_outputs_and_warnings() {
    let d = doc();
    let m = d.material("M").unwrap();
    assert_eq!(m.shader, "SR");
    let out = d.graph().output_id("g/out").unwrap();
    assert_eq!(m.get("base_color"), Some(&MaterialSource::Output(out)));
    assert_eq!(m.get("specular_roughness"), Some(&MaterialSource::Constant(Value::float(0.4))));
    assert_eq!(m.get("base"), Some(&MaterialSource::Constant(Value::float(1.0))));
    assert_eq!(m.get("normal"), Some(&MaterialSource::Geometric));
    assert_eq!(m.warnings.len(), 1, "{:?}", m.warnings);
    assert!(m.warnings[0].contains("coat"));
    // The reference patterns bind their graphs to base_color.
    let pat = Document::load(common::shared().join("refs/materialx/patterns.mtlx")).unwrap();
    let b = pat.material("M_checkerboard").unwrap();
    assert!(matches!(b.get("base_color"), Some(MaterialSource::Output(_))));
    assert!(b.warnings.is_empty());
}
