//! `open_pbr_surface` and `gltf_pbr` materials as bindings onto `standard_surface`'s inputs:
//! the mapping, each model's own defaults, glTF's alpha modes (a graph-driven MASK filtered as
//! the probability of reaching the cutoff), one warning naming every input not honoured, and
//! material inputs for `tessera bake`.

use glam::{Mat2, Vec2};
use graph::bake::{bakeable_elements, resolve, BakeSource};
use graph::{Document, Footprint, LoadOptions, MaterialSource, Value, ValueType};

fn parse(body: &str) -> Document {
    let text = format!(
        r#"<?xml version="1.0"?>
<materialx version="1.39">
  <nodegraph name="g">
    <texcoord name="t" type="vector2"/>
    <separate2 name="sep" type="multioutput"><input name="in" type="vector2" nodename="t"/></separate2>
    <convert name="col" type="color3"><input name="in" type="float" nodename="sep" output="outy"/></convert>
    <output name="u" type="float" nodename="sep" output="outx"/>
    <output name="color" type="color3" nodename="col"/>
  </nodegraph>
{body}
</materialx>"#
    );
    Document::parse(&text, "models.mtlx".as_ref(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn constant(src: Option<&MaterialSource>) -> Vec<f32> {
    match src {
        Some(MaterialSource::Constant(v)) => v.channels().to_vec(),
        other => panic!("expected a constant, got {other:?}"),
    }
}

/// Standard normal CDF by the Abramowitz–Stegun 7.1.26 erf approximation (|error| < 1.5e-7),
/// written independently of the library's own Gaussian helpers.
fn phi(z: f64) -> f64 {
    let x = z.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.3275911 * x);
    let poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
    let erf = 1.0 - poly * (-x * x).exp();
    if z >= 0.0 {
        0.5 * (1.0 + erf)
    } else {
        0.5 * (1.0 - erf)
    }
}

#[test]
fn open_pbr_inputs_map_onto_standard_surface_names_with_openpbr_defaults() {
    let d = parse(
        r#"  <open_pbr_surface name="S" type="surfaceshader">
    <input name="base_color" type="color3" nodegraph="g" output="color"/>
    <input name="base_metalness" type="float" value="0.25"/>
    <input name="specular_ior" type="float" value="1.33"/>
    <input name="transmission_weight" type="float" value="0.5"/>
    <input name="geometry_opacity" type="float" value="0.3"/>
  </open_pbr_surface>
  <surfacematerial name="M" type="material"><input name="surfaceshader" type="surfaceshader" nodename="S"/></surfacematerial>"#,
    );
    assert_eq!(d.material_names(), vec!["M", "S"]);
    let b = d.material("M").unwrap();
    assert_eq!(b.model, "open_pbr_surface");
    assert!(b.warnings.is_empty(), "{:?}", b.warnings);
    assert_eq!(b.get("base_color"), Some(&MaterialSource::Output(d.graph().output_id("g/color").unwrap())));
    assert_eq!(constant(b.get("metalness")), vec![0.25]);
    assert_eq!(constant(b.get("specular_IOR")), vec![1.33]);
    assert_eq!(constant(b.get("transmission")), vec![0.5]);
    assert_eq!(constant(b.get("opacity")), vec![0.3]);
    // Unset: OpenPBR's own defaults (roughness 0.3, where Standard Surface has 0.2).
    assert_eq!(constant(b.get("specular_roughness")), vec![0.3]);
    assert_eq!(constant(b.get("base")), vec![1.0]);
    assert_eq!(constant(b.get("specular")), vec![1.0]);
    assert_eq!(constant(b.get("specular_color")), vec![1.0; 3]);
    assert_eq!(b.get("normal"), Some(&MaterialSource::Geometric));
    // Bake: set inputs are listed, unset ones take the model's default.
    assert!(bakeable_elements(&d).contains(&"M/S/base_metalness".to_string()));
    assert_eq!(
        resolve(&d, "M/S/specular_roughness").unwrap(),
        (BakeSource::Constant(Value::float(0.3)), ValueType::Float)
    );
    assert!(matches!(resolve(&d, "M/S/base_color").unwrap(), (BakeSource::Output(_), ValueType::Color3)));
}

#[test]
fn inputs_not_honoured_are_named_in_one_warning() {
    let d = parse(
        r#"  <open_pbr_surface name="O" type="surfaceshader">
    <input name="coat_weight" type="float" value="1"/>
    <input name="fuzz_weight" type="float" value="0.5"/>
    <input name="coat_ior" type="float" value="1.6"/>
    <input name="subsurface_radius_scale" type="color3" value="1, 0.5, 0.25"/>
    <input name="geometry_thin_walled" type="boolean" value="true"/>
  </open_pbr_surface>
  <gltf_pbr name="G" type="surfaceshader">
    <input name="clearcoat" type="float" value="1"/>
    <input name="sheen_color" type="color3" value="0.2, 0.2, 0.2"/>
    <input name="occlusion" type="float" value="0.5"/>
    <input name="emissive" type="color3" value="0, 0, 0"/>
  </gltf_pbr>
  <gltf_pbr name="Quiet" type="surfaceshader">
    <input name="occlusion" type="float" value="0.2"/>
    <input name="thickness" type="float" value="1"/>
  </gltf_pbr>"#,
    );
    let o = d.material("O").unwrap();
    assert_eq!(o.warnings.len(), 1, "{:?}", o.warnings);
    for name in ["`coat_weight`", "`fuzz_weight`", "`geometry_thin_walled`", "open_pbr_surface"] {
        assert!(o.warnings[0].contains(name), "{name} missing from {}", o.warnings[0]);
    }
    // Set to the model's own defaults: not mentioned.
    assert!(!o.warnings[0].contains("coat_ior") && !o.warnings[0].contains("radius_scale"), "{}", o.warnings[0]);
    let g = d.material("G").unwrap();
    assert_eq!(g.warnings.len(), 1, "{:?}", g.warnings);
    assert!(g.warnings[0].contains("`clearcoat`") && g.warnings[0].contains("`sheen_color`"), "{}", g.warnings[0]);
    assert!(!g.warnings[0].contains("occlusion") && !g.warnings[0].contains("emissive"), "{}", g.warnings[0]);
    // Inputs MaterialX's own gltf_pbr graph leaves unused are ignored quietly.
    assert!(d.material("Quiet").unwrap().warnings.is_empty());
}

#[test]
fn gltf_maps_metallic_roughness_and_tints_transmission_by_base_color() {
    let d = parse(
        r#"  <gltf_pbr name="S" type="surfaceshader">
    <input name="base_color" type="color3" value="0.9, 0.5, 0.1"/>
    <input name="roughness" type="float" value="0.4"/>
    <input name="transmission" type="float" value="0.7"/>
  </gltf_pbr>"#,
    );
    let b = d.material("S").unwrap();
    assert_eq!(b.model, "gltf_pbr");
    assert_eq!(constant(b.get("base")), vec![1.0]);
    assert_eq!(constant(b.get("base_color")), vec![0.9, 0.5, 0.1]);
    assert_eq!(constant(b.get("transmission_color")), vec![0.9, 0.5, 0.1]);
    assert_eq!(constant(b.get("specular_roughness")), vec![0.4]);
    assert_eq!(constant(b.get("transmission")), vec![0.7]);
    // glTF's defaults: fully metallic, IOR 1.5, specular 1.
    assert_eq!(constant(b.get("metalness")), vec![1.0]);
    assert_eq!(constant(b.get("specular_IOR")), vec![1.5]);
    assert_eq!(constant(b.get("specular")), vec![1.0]);
    assert_eq!(constant(b.get("opacity")), vec![1.0]);
    assert_eq!(resolve(&d, "S/metallic").unwrap(), (BakeSource::Constant(Value::float(1.0)), ValueType::Float));
    assert_eq!(
        resolve(&d, "S/alpha_mode").unwrap(),
        (BakeSource::Constant(Value::new(ValueType::Integer, &[0.0])), ValueType::Integer)
    );
}

#[test]
fn gltf_alpha_modes() {
    let shader =
        |name: &str, inputs: &str| format!(r#"  <gltf_pbr name="{name}" type="surfaceshader">{inputs}</gltf_pbr>"#);
    let a = |v: &str| format!(r#"<input name="alpha" type="float" value="{v}"/>"#);
    let mode = |m: u32| format!(r#"<input name="alpha_mode" type="integer" value="{m}"/>"#);
    let body = [
        shader("Opaque", &a("0.3")),
        shader("Blend", &(a("0.3") + &mode(2))),
        shader("MaskBelow", &(a("0.3") + &mode(1))),
        shader("MaskAbove", &(a("0.3") + &mode(1) + r#"<input name="alpha_cutoff" type="float" value="0.25"/>"#)),
        shader("MaskGraph", &(mode(1) + r#"<input name="alpha" type="float" nodegraph="g" output="u"/>"#)),
        shader("BlendGraph", &(mode(2) + r#"<input name="alpha" type="float" nodegraph="g" output="u"/>"#)),
    ]
    .join("\n");
    let d = parse(&body);
    let opacity = |m: &str| d.material(m).unwrap().get("opacity").cloned();
    assert_eq!(opacity("Opaque"), Some(MaterialSource::Constant(Value::float(1.0))));
    assert_eq!(opacity("Blend"), Some(MaterialSource::Constant(Value::float(0.3))));
    assert_eq!(opacity("MaskBelow"), Some(MaterialSource::Constant(Value::float(0.0))));
    assert_eq!(opacity("MaskAbove"), Some(MaterialSource::Constant(Value::float(1.0))));
    let u = d.graph().output_id("g/u").unwrap();
    assert_eq!(opacity("BlendGraph"), Some(MaterialSource::Output(u)));
    let Some(MaterialSource::Output(mask)) = opacity("MaskGraph") else { panic!("{:?}", opacity("MaskGraph")) };
    assert_ne!(mask, u);
    // The mask output is a shader-input output, not one of the document's own outputs.
    assert!(d.is_shader_input_output(&d.graph().output(mask).name));
    assert!(!bakeable_elements(&d).contains(&d.graph().output(mask).name));
    let g = d.graph();
    let eval = |u: f32, sigma: f32| {
        let fp = Footprint::new(Vec2::new(u, 0.5), Mat2::from_diagonal(Vec2::splat(sigma * sigma)));
        g.eval_output(mask, &fp, &mut graph::EvalScratch::new(g)).ch[0].mean as f64
    };
    // At a point, the hard cutoff (alpha = u ≥ 0.5).
    assert_eq!(eval(0.3, 0.0), 0.0);
    assert_eq!(eval(0.7, 0.0), 1.0);
    // Over a Gaussian footprint of u, the probability that u reaches the cutoff.
    for (mu, sigma) in [(0.45f32, 0.05f32), (0.5, 0.1), (0.56, 0.03), (0.3, 0.2)] {
        let want = phi((mu as f64 - 0.5) / sigma as f64);
        let got = eval(mu, sigma);
        assert!((got - want).abs() < 2e-3, "u ~ N({mu}, {sigma}²): {got} vs {want}");
    }
}
