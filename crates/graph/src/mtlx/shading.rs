//! The shading models that load as bindings: where each input of a binding comes from, and its default.

use super::document::ShaderInput;
use crate::graph::OutputId;
use crate::value::{Value, ValueType};

/// Where a material input takes its value from.
#[derive(Clone, Debug, PartialEq)]
pub enum MaterialSource {
    /// A uniform value.
    Constant(Value),
    /// A graph output.
    Output(OutputId),
    /// Not set and without a constant default (the geometric normal for `normal`).
    Geometric,
}

/// A material's supported inputs, each a constant or a graph output, named as `standard_surface`
/// names them whatever the shading model (see [`SHADING_MODELS`]).
#[derive(Clone, Debug)]
pub struct MaterialBinding {
    /// The material (or shader) name asked for.
    pub name: String,
    /// The shader node's name.
    pub shader: String,
    /// The shader node's category: one of [`SHADING_MODELS`].
    pub model: &'static str,
    /// `(input name, source)` for every supported input, in [`SUPPORTED_INPUTS`] order, with the
    /// `standard_surface` names: an `open_pbr_surface`'s `base_metalness` is `metalness` here.
    pub inputs: Vec<(&'static str, MaterialSource)>,
    /// The inputs set to non-default values that the binding does not carry (in one message),
    /// and other inputs it reads differently from what they say.
    pub warnings: Vec<String>,
    /// Inputs the material needs that cannot be evaluated (a graph output that depends on an
    /// unsupported or broken node, in a document loaded leniently), each with the reason: the
    /// binding gives them their defaults, and a renderer should refuse the material.
    pub unavailable: Vec<String>,
}

impl MaterialBinding {
    /// The source of input `name` (a `standard_surface` name).
    pub fn get(&self, name: &str) -> Option<&MaterialSource> {
        self.inputs.iter().find(|(n, _)| *n == name).map(|(_, s)| s)
    }
}

/// A material input's default: its type and value, or `None` for geometric data.
pub type InputDefault = Option<(ValueType, [f32; 3])>;

/// The inputs a binding carries, by their `standard_surface` names, with `standard_surface`'s
/// defaults: the parameters of the renderer's layered BSDF (plus `opacity` and `normal`, which
/// the renderer applies itself).
pub const SUPPORTED_INPUTS: &[(&str, InputDefault)] = &[
    ("base", Some((ValueType::Float, [1.0, 0.0, 0.0]))),
    ("base_color", Some((ValueType::Color3, [0.8, 0.8, 0.8]))),
    ("metalness", Some((ValueType::Float, [0.0, 0.0, 0.0]))),
    ("specular", Some((ValueType::Float, [1.0, 0.0, 0.0]))),
    ("specular_color", Some((ValueType::Color3, [1.0, 1.0, 1.0]))),
    ("specular_roughness", Some((ValueType::Float, [0.2, 0.0, 0.0]))),
    ("specular_IOR", Some((ValueType::Float, [1.5, 0.0, 0.0]))),
    ("transmission", Some((ValueType::Float, [0.0, 0.0, 0.0]))),
    ("transmission_color", Some((ValueType::Color3, [1.0, 1.0, 1.0]))),
    ("opacity", Some((ValueType::Color3, [1.0, 1.0, 1.0]))),
    ("normal", None),
];

/// The shading models whose materials load as [`MaterialBinding`]s (MaterialX 1.39 node
/// names). All three render with the same BSDF; see [`Document::material`] for how the other
/// two map onto `standard_surface`'s inputs.
///
/// [`Document::material`]: super::Document::material
pub const SHADING_MODELS: &[&str] = &["standard_surface", "open_pbr_surface", "gltf_pbr"];

/// Where one [`SUPPORTED_INPUTS`] entry of a binding comes from in a shading model.
#[derive(Clone, Copy, Debug)]
pub(super) enum Mapped {
    /// The model's input of the same name, with the [`SUPPORTED_INPUTS`] default.
    Same,
    /// The model's input of this name, with the model's own default.
    Input(&'static str, InputDefault),
    /// The model has no such input: always this value.
    Fixed(ValueType, f32),
    /// glTF's `alpha` as `alpha_mode` and `alpha_cutoff` make it an opacity.
    GltfOpacity,
}

/// How a shading model's inputs become a [`MaterialBinding`].
pub(super) struct ShadingModel {
    pub(super) category: &'static str,
    /// Where each [`SUPPORTED_INPUTS`] entry comes from, in the same order.
    pub(super) map: &'static [Mapped],
    /// Other inputs the binding reads, with the model's defaults.
    extra: &'static [(&'static str, InputDefault)],
    /// Inputs the model's own MaterialX implementation leaves out of the shader it builds (so
    /// ignoring them renders what MaterialX renders): no warning.
    silent: &'static [&'static str],
    /// Inputs the renderer does not honour, with the model's defaults (one value for every
    /// channel, or one per channel): set to anything else, they are named in a warning. Inputs
    /// not listed anywhere (tangents, coat normals, unknown names) warn whenever set.
    pub(super) unsupported: &'static [(&'static str, &'static [f32])],
}

pub(super) const fn f(v: f32) -> InputDefault {
    Some((ValueType::Float, [v, 0.0, 0.0]))
}

const fn c3(v: f32) -> InputDefault {
    Some((ValueType::Color3, [v, v, v]))
}

/// `standard_surface` (Autodesk Standard Surface; MaterialX 1.39's default nodedef is version
/// 1.0.1). The defaults below are those of MaterialX's `libraries/bxdf/standard_surface.mtlx`.
const STANDARD_SURFACE: ShadingModel = ShadingModel {
    category: "standard_surface",
    map: &[Mapped::Same; 11],
    extra: &[],
    silent: &[],
    unsupported: &[
        ("diffuse_roughness", &[0.0]),
        ("specular_anisotropy", &[0.0]),
        ("specular_rotation", &[0.0]),
        ("transmission_depth", &[0.0]),
        ("transmission_scatter", &[0.0]),
        ("transmission_scatter_anisotropy", &[0.0]),
        ("transmission_dispersion", &[0.0]),
        ("transmission_extra_roughness", &[0.0]),
        ("subsurface", &[0.0]),
        ("subsurface_color", &[1.0]),
        ("subsurface_radius", &[1.0]),
        ("subsurface_scale", &[1.0]),
        ("subsurface_anisotropy", &[0.0]),
        ("sheen", &[0.0]),
        ("sheen_color", &[1.0]),
        ("sheen_roughness", &[0.3]),
        ("coat", &[0.0]),
        ("coat_color", &[1.0]),
        ("coat_roughness", &[0.1]),
        ("coat_anisotropy", &[0.0]),
        ("coat_rotation", &[0.0]),
        ("coat_IOR", &[1.5]),
        ("coat_affect_color", &[0.0]),
        ("coat_affect_roughness", &[0.0]),
        ("thin_film_thickness", &[0.0]),
        ("thin_film_IOR", &[1.5]),
        ("emission", &[0.0]),
        ("emission_color", &[1.0]),
        ("thin_walled", &[0.0]),
    ],
};

/// OpenPBR Surface. Defaults: the `ND_open_pbr_surface_surfaceshader` nodedef of MaterialX
/// 1.39's `libraries/bxdf/open_pbr_surface.mtlx`, which the OpenPBR table of the 1.39 PBR
/// specification (`MaterialX.PBRSpec.md`) repeats: a base of weight 1 and colour 0.8, no
/// metalness, specular weight 1, white specular colour, specular roughness 0.3 (not 0.2 as in
/// Standard Surface), IOR 1.5, no transmission, opacity 1, not thin-walled.
///
/// Mapping: `base_weight` → `base`, `base_metalness` → `metalness`, `specular_weight` →
/// `specular`, `specular_ior` → `specular_IOR`, `transmission_weight` → `transmission`,
/// `transmission_color` → `transmission_color` (with `transmission_depth` 0 OpenPBR reads it as a
/// plain tint, which is what the BSDF does with it), `geometry_opacity` (a float) → `opacity`,
/// `geometry_normal` → `normal`. `geometry_thin_walled` stands for `standard_surface`'s
/// `thin_walled`, which the BSDF does not model: set, it is warned about, as there.
const OPEN_PBR_SURFACE: ShadingModel = ShadingModel {
    category: "open_pbr_surface",
    map: &[
        Mapped::Input("base_weight", f(1.0)),
        Mapped::Input("base_color", c3(0.8)),
        Mapped::Input("base_metalness", f(0.0)),
        Mapped::Input("specular_weight", f(1.0)),
        Mapped::Input("specular_color", c3(1.0)),
        Mapped::Input("specular_roughness", f(0.3)),
        Mapped::Input("specular_ior", f(1.5)),
        Mapped::Input("transmission_weight", f(0.0)),
        Mapped::Input("transmission_color", c3(1.0)),
        Mapped::Input("geometry_opacity", f(1.0)),
        Mapped::Input("geometry_normal", None),
    ],
    extra: &[],
    silent: &[],
    unsupported: &[
        ("base_diffuse_roughness", &[0.0]),
        ("specular_roughness_anisotropy", &[0.0]),
        ("transmission_depth", &[0.0]),
        ("transmission_scatter", &[0.0]),
        ("transmission_scatter_anisotropy", &[0.0]),
        ("transmission_dispersion_scale", &[0.0]),
        ("transmission_dispersion_abbe_number", &[20.0]),
        ("subsurface_weight", &[0.0]),
        ("subsurface_color", &[0.8]),
        ("subsurface_radius", &[1.0]),
        ("subsurface_radius_scale", &[1.0, 0.5, 0.25]),
        ("subsurface_scatter_anisotropy", &[0.0]),
        ("fuzz_weight", &[0.0]),
        ("fuzz_color", &[1.0]),
        ("fuzz_roughness", &[0.5]),
        ("coat_weight", &[0.0]),
        ("coat_color", &[1.0]),
        ("coat_roughness", &[0.0]),
        ("coat_roughness_anisotropy", &[0.0]),
        ("coat_ior", &[1.6]),
        ("coat_darkening", &[1.0]),
        ("thin_film_weight", &[0.0]),
        ("thin_film_thickness", &[0.5]),
        ("thin_film_ior", &[1.4]),
        ("emission_luminance", &[0.0]),
        ("emission_color", &[1.0]),
        ("geometry_thin_walled", &[0.0]),
    ],
};

/// Khronos glTF PBR (`gltf_pbr`). Defaults: the `ND_gltf_pbr_surfaceshader` nodedef of MaterialX's
/// `libraries/bxdf/gltf_pbr.mtlx` and the glTF table of the 1.39 PBR specification: white base
/// colour, fully metallic, roughness 1, IOR 1.5, no transmission, specular 1 with white colour,
/// alpha 1 with `alpha_mode` 0 (OPAQUE) and `alpha_cutoff` 0.5.
///
/// Mapping: `base` is 1 (glTF has no base weight); `metallic` → `metalness`, `roughness` →
/// `specular_roughness`, `ior` → `specular_IOR`; glTF tints its refraction lobe by
/// `base_color`, so `base_color` is also `transmission_color`. The opacity follows the
/// definition's own graph: OPAQUE (0) ignores `alpha` (opacity 1), MASK (1) is 1 where
/// `alpha ≥ alpha_cutoff` and 0 elsewhere, any other mode (BLEND, 2) is `alpha` itself. A MASK
/// of a graph-driven `alpha` is an `ifgreatereq` node added to the graph (output
/// `<shader>.alpha_mask`), so it is filtered like any node: over a footprint it is the
/// probability that `alpha` reaches the cutoff, a smooth step of the footprint's width, and the
/// hard step at a point.
///
/// The dielectric specular layer keeps the BSDF's exact Fresnel of `ior` where glTF uses
/// Schlick's curve, and its metal reads `specular`/`specular_color` as the edge tint where glTF's
/// metal uses a white one: close, not identical. `occlusion` (baked ambient occlusion, which a
/// path tracer computes), and the volume inputs `thickness`, `attenuation_distance`,
/// `attenuation_color` and `dispersion` are part of the interface that MaterialX's own graph
/// does not use either, so they are ignored without a warning.
const GLTF_PBR: ShadingModel = ShadingModel {
    category: "gltf_pbr",
    map: &[
        Mapped::Fixed(ValueType::Float, 1.0),
        Mapped::Input("base_color", c3(1.0)),
        Mapped::Input("metallic", f(1.0)),
        Mapped::Input("specular", f(1.0)),
        Mapped::Input("specular_color", c3(1.0)),
        Mapped::Input("roughness", f(1.0)),
        Mapped::Input("ior", f(1.5)),
        Mapped::Input("transmission", f(0.0)),
        Mapped::Input("base_color", c3(1.0)),
        Mapped::GltfOpacity,
        Mapped::Input("normal", None),
    ],
    extra: &[("alpha", f(1.0)), ("alpha_mode", Some((ValueType::Integer, [0.0, 0.0, 0.0]))), ("alpha_cutoff", f(0.5))],
    silent: &["occlusion", "thickness", "attenuation_distance", "attenuation_color", "dispersion"],
    unsupported: &[
        ("iridescence", &[0.0]),
        ("iridescence_ior", &[1.3]),
        ("iridescence_thickness", &[100.0]),
        ("sheen_color", &[0.0]),
        ("sheen_roughness", &[0.0]),
        ("clearcoat", &[0.0]),
        ("clearcoat_roughness", &[0.0]),
        ("emissive", &[0.0]),
        ("emissive_strength", &[1.0]),
        ("anisotropy_strength", &[0.0]),
        ("anisotropy_rotation", &[0.0]),
    ],
};

const MODELS: &[&ShadingModel] = &[&STANDARD_SURFACE, &OPEN_PBR_SURFACE, &GLTF_PBR];

// Every model maps every supported input (checked when compiling).
const _: () = {
    let mut k = 0;
    while k < MODELS.len() {
        assert!(MODELS[k].map.len() == SUPPORTED_INPUTS.len());
        k += 1;
    }
};

pub(super) fn model_of(category: &str) -> Option<&'static ShadingModel> {
    MODELS.iter().copied().find(|m| m.category == category)
}

impl ShadingModel {
    /// The model's own default of its input `input`, if the binding knows it.
    pub(super) fn default_of(&self, input: &str) -> Option<InputDefault> {
        for (k, m) in self.map.iter().enumerate() {
            match *m {
                Mapped::Same if SUPPORTED_INPUTS[k].0 == input => return Some(SUPPORTED_INPUTS[k].1),
                Mapped::Input(n, d) if n == input => return Some(d),
                _ => {}
            }
        }
        self.extra.iter().find(|(n, _)| *n == input).map(|(_, d)| *d)
    }

    /// Whether the binding reads input `input` (or deliberately leaves it out).
    pub(super) fn handles(&self, input: &str) -> bool {
        self.map.iter().enumerate().any(|(k, m)| match *m {
            Mapped::Same => SUPPORTED_INPUTS[k].0 == input,
            Mapped::Input(n, _) => n == input,
            _ => false,
        }) || self.extra.iter().any(|(n, _)| *n == input)
            || self.silent.contains(&input)
    }
}

/// glTF's `alpha_mode` from its input (0 when unset; a non-constant one is an error the
/// caller reports, read as 0).
pub(super) fn gltf_alpha_mode(si: Option<&ShaderInput>) -> Result<i32, String> {
    match si {
        Some(ShaderInput::Value(Some(v))) => Ok(v.v[0].round() as i32),
        Some(ShaderInput::Output(_)) => Err("`alpha_mode` must be a constant; read as 0 (OPAQUE)".into()),
        _ => Ok(0),
    }
}

/// glTF's `alpha_cutoff` from its input (0.5 when unset; a non-constant one is an error the
/// caller reports, read as 0.5).
pub(super) fn gltf_alpha_cutoff(si: Option<&ShaderInput>) -> Result<f32, String> {
    match si {
        Some(ShaderInput::Value(Some(v))) => Ok(v.v[0]),
        Some(ShaderInput::Output(_)) => Err("`alpha_cutoff` must be a constant; read as 0.5".into()),
        _ => Ok(0.5),
    }
}
