//! MaterialX 1.39 import: a document's node graphs flattened into one [`Graph`], its shaders'
//! inputs, and its `standard_surface`, `open_pbr_surface` and `gltf_pbr` materials as
//! [`MaterialBinding`]s (see [`SHADING_MODELS`]).
//!
//! Names: a node `n` inside `<nodegraph name="g">` is `g/n`; a top-level node is `n`. Outputs
//! likewise (`g/out`). Connections by `nodename` (+ `output` for multi-output nodes),
//! `nodegraph` + `output`, and `interfacename` are resolved to sources; omitted inputs take the
//! node definition's defaults. Errors carry the file and the line of the offending element.
//!
//! Document features:
//!
//! - **Custom nodes**: a `nodedef` implemented by a `nodegraph` (its `nodedef` attribute, or an
//!   `<implementation nodegraph=...>`) is expanded inline wherever a node instantiates it. The
//!   instance's nodes are named `instance/node` (`g/instance/node` inside graph `g`); nested
//!   definitions nest their prefixes. Multi-output definitions are read through `output`. The
//!   nodedef is the one named by the instance's `nodedef` attribute, or else the one whose node,
//!   output type and input types match the instance (its `version`, else the
//!   `isdefaultversion` one). The implementing graph is also content of its own: its outputs
//!   (`NG/out`) evaluate with the nodedef's defaults. A definition that instantiates itself,
//!   directly or not, is an error.
//! - **Interfaces**: `interfacename` resolves through any depth: an instance's input, which may
//!   itself name its enclosing graph's interface, up to the document's top-level `<input>`s;
//!   inputs an instance leaves unset take the nodedef's `value` or `defaultgeomprop` (`UV0` is
//!   the texture coordinate; `Pobject`, `Nworld`, ... become the geometry nodes of that space when
//!   the library has them). A chain of interface names that returns to itself is an error.
//! - **Versions** 1.36 to 1.38 are upgraded as MaterialX's `Document::upgradeVersion` does, for
//!   what the node library can evaluate: `parameter` elements are inputs; `color2` is `vector2`;
//!   `combine`/`separate` become `combineN`/`separateN`, `rotate` `rotate2d`/`rotate3d`,
//!   `compare` `ifgreatereq` (inputs renamed and swapped), `geomattrvalue` `geompropvalue`;
//!   `atan2`'s inputs are renamed (1.37: swapped; 1.38: `in1`/`in2` to `iny`/`inx`); `channels`
//!   attributes and `swizzle` nodes become channel picks and `combineN` nodes; `<material>`
//!   elements with `<shaderref>`s become shader bindings; a `normalmap` in `object` space becomes
//!   `normalize(2·in − 1)`, and a tangent-space one drops its unbound `normal`/`tangent`/
//!   `bitangent` literals; a five-input `switch` feeds its fifth input to 1.39's sixth to tenth,
//!   so that `which` ≥ 4 still picks it. Rules for nodes the library does not evaluate (BSDFs,
//!   `artistic_ior`, ...) do not apply: those nodes are reported unsupported. Versions after 1.39
//!   and before 1.36 are errors.
//! - **Includes**: top-level `xi:include href="..."` elements are read (relative to the including
//!   file, then the search paths), recursively; an element already defined keeps its first
//!   definition; a missing include or an include cycle is an error naming the `xi:include`.
//! - **Files**: `fileprefix` (the nearest one on the element supplying the value or its
//!   ancestors) is prepended to file names; files are looked up beside the file that names them,
//!   beside the main document, then in the search paths.
//! - **Colour spaces**: the document's `colorspace` is the working space (`lin_rec709` by default;
//!   it must be linear: `lin_rec709` or `acescg`/`lin_ap1`). `color3`/`color4` values and images
//!   whose active colour space (their own `colorspace`, else the nearest ancestor's) differs are
//!   converted to it, as MaterialX's colour management does: `srgb_texture`, `lin_rec709`,
//!   `g22_rec709`, `g18_rec709`, `rec709_display`, `acescg` (`lin_ap1`), `g22_ap1`, `g18_ap1`,
//!   `lin_adobergb`, `adobergb`, `srgb_displayp3`, `lin_displayp3`. sRGB-encoded images are decoded
//!   before filtering (at load); other transfer curves and the primaries' matrix apply to the
//!   filtered value (exact for the matrix; for gamma curves exact at point footprints). Images of
//!   other types are not converted.
//! - `uniform` inputs may not connect to node outputs; `enum` names of a custom nodedef's input
//!   are accepted as values (mapped through its `enumvalues`).
//!
//! Unsupported nodes (unknown categories, types or inputs the library lacks, nodedefs without a
//! nodegraph) are collected, not reported one at a time: strict loading fails with all of them
//! (each with its file and line, [`LoadErrorKind::Unsupported`]); lenient loading leaves out the
//! outputs that depend on them ([`Document::skipped`], [`Document::unsupported`]).

use crate::error::{BuildError, LoadError, LoadErrorKind, Location, Unsupported};
use crate::graph::{Graph, GraphBuilder, OutputId, Source};
use crate::matrix::Matrix;
use crate::nodes::{self, channel, Param};
use crate::value::{Value, ValueType};
use glam::{DMat3, DVec3};
use roxmltree::Node as XNode;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// How to load a document.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Extra folders to search for referenced files (images, includes).
    pub search_paths: Vec<PathBuf>,
    /// Instead of failing on unsupported nodes, leave out every output that depends on one
    /// (listed by [`Document::skipped`]). Malformed documents still fail.
    pub lenient: bool,
}

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
    /// Inputs that could not be read, and (in one message) the inputs set to non-default values
    /// that the binding does not carry.
    pub warnings: Vec<String>,
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
pub const SHADING_MODELS: &[&str] = &["standard_surface", "open_pbr_surface", "gltf_pbr"];

/// Where one [`SUPPORTED_INPUTS`] entry of a binding comes from in a shading model.
#[derive(Clone, Copy, Debug)]
enum Mapped {
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
struct ShadingModel {
    category: &'static str,
    /// Where each [`SUPPORTED_INPUTS`] entry comes from, in the same order.
    map: &'static [Mapped],
    /// Other inputs the binding reads, with the model's defaults.
    extra: &'static [(&'static str, InputDefault)],
    /// Inputs the model's own MaterialX implementation leaves out of the shader it builds (so
    /// ignoring them renders what MaterialX renders): no warning.
    silent: &'static [&'static str],
    /// Inputs the renderer does not honour, with the model's defaults (one value for every
    /// channel, or one per channel): set to anything else, they are named in a warning. Inputs
    /// not listed anywhere (tangents, coat normals, unknown names) warn whenever set.
    unsupported: &'static [(&'static str, &'static [f32])],
}

const fn f(v: f32) -> InputDefault {
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

fn model_of(category: &str) -> Option<&'static ShadingModel> {
    MODELS.iter().copied().find(|m| m.category == category)
}

impl ShadingModel {
    /// The model's own default of its input `input`, if the binding knows it.
    fn default_of(&self, input: &str) -> Option<InputDefault> {
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
    fn handles(&self, input: &str) -> bool {
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
fn gltf_alpha_mode(si: Option<&ShaderInput>) -> Result<i32, String> {
    match si {
        Some(ShaderInput::Value(Some(v))) => Ok(v.v[0].round() as i32),
        Some(ShaderInput::Output(_)) => Err("`alpha_mode` must be a constant; read as 0 (OPAQUE)".into()),
        _ => Ok(0),
    }
}

/// glTF's `alpha_cutoff` from its input (0.5 when unset; a non-constant one is an error the
/// caller reports, read as 0.5).
fn gltf_alpha_cutoff(si: Option<&ShaderInput>) -> Result<f32, String> {
    match si {
        Some(ShaderInput::Value(Some(v))) => Ok(v.v[0]),
        Some(ShaderInput::Output(_)) => Err("`alpha_cutoff` must be a constant; read as 0.5".into()),
        _ => Ok(0.5),
    }
}

/// Derived values a shader's binding needs, built into the graph at load.
#[derive(Clone, Debug, Default)]
struct ShaderExtras {
    /// `gltf_pbr` in MASK mode with a graph-driven `alpha`: the `ifgreatereq` output.
    alpha_mask: Option<Result<OutputId, String>>,
}

#[derive(Clone, Debug)]
struct ShaderDef {
    name: String,
    category: String,
    inputs: Vec<(String, ShaderInput)>,
    extras: ShaderExtras,
    location: Location,
}

#[derive(Clone, Debug)]
enum ShaderInput {
    /// A value (`None`: declared without one).
    Value(Option<Value>),
    Output(Result<OutputId, String>),
}

/// A loaded MaterialX document.
#[derive(Debug)]
pub struct Document {
    path: PathBuf,
    files: Vec<PathBuf>,
    graph: Graph,
    shaders: Vec<ShaderDef>,
    /// material name → shader name
    materials: Vec<(String, String)>,
    skipped: Vec<(String, String)>,
    unsupported: Vec<Unsupported>,
    /// Outputs made for connected shader inputs (`shader.input`).
    shader_outputs: HashSet<String>,
}

impl Document {
    /// Loads a `.mtlx` file (strict: any unsupported node is an error).
    pub fn load(path: impl AsRef<Path>) -> Result<Document, LoadError> {
        Document::load_with(path, &LoadOptions::default())
    }

    /// Loads a `.mtlx` file with options.
    pub fn load_with(path: impl AsRef<Path>, opts: &LoadOptions) -> Result<Document, LoadError> {
        let path = path.as_ref();
        let at = Location { file: path.to_path_buf(), line: 0, column: 0 };
        let text = read_text(path, &at)?;
        Document::parse(&text, path, opts)
    }

    /// Parses document text; `path` names it in errors and anchors relative file names.
    pub fn parse(text: &str, path: &Path, opts: &LoadOptions) -> Result<Document, LoadError> {
        let mut sources: Vec<(PathBuf, String)> = Vec::new();
        gather(text.to_string(), path, opts, &mut sources, &mut Vec::new())?;
        let mut xmls = Vec::with_capacity(sources.len());
        for (p, t) in &sources {
            xmls.push(parse_xml(t, p)?);
        }
        let files: Vec<PathBuf> = sources.iter().map(|(p, _)| p.clone()).collect();
        let mut imp = Importer::new(&xmls, &files, opts)?;
        imp.collect()?;
        imp.build_all()?;
        if !opts.lenient && !imp.unsupported.is_empty() {
            // In document order: by file (the document, then its includes), line and column.
            let mut items = imp.unsupported;
            let order = |u: &Unsupported| {
                (files.iter().position(|f| *f == u.location.file), u.location.line, u.location.column)
            };
            items.sort_by_key(order);
            return Err(LoadError {
                location: items[0].location.clone(),
                kind: LoadErrorKind::Unsupported { items, supported: nodes::supported_list() },
            });
        }
        let Importer { builder, shaders, materials, skipped, unsupported, shader_outputs, .. } = imp;
        Ok(Document {
            path: path.to_path_buf(),
            files,
            graph: builder.build(),
            shaders,
            materials,
            skipped,
            unsupported,
            shader_outputs,
        })
    }

    /// The file this was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Every file read: the document, then its includes.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// The flattened graph of every node graph in the document.
    pub fn graph(&self) -> &Graph {
        &self.graph
    }

    /// Takes the graph.
    pub fn into_graph(self) -> Graph {
        self.graph
    }

    /// Outputs left out in lenient mode: `(output name, reason)`.
    pub fn skipped(&self) -> &[(String, String)] {
        &self.skipped
    }

    /// Every unsupported node found (lenient mode; strict loading fails on any).
    pub fn unsupported(&self) -> &[Unsupported] {
        &self.unsupported
    }

    /// Whether graph output `name` was made for a connected shader input (rather than being an
    /// `<output>` of the document).
    pub fn is_shader_input_output(&self, name: &str) -> bool {
        self.shader_outputs.contains(name)
    }

    /// Names of the `surfacematerial`s, then of the shaders of the [`SHADING_MODELS`].
    pub fn material_names(&self) -> Vec<&str> {
        self.materials
            .iter()
            .map(|(m, _)| m.as_str())
            .chain(self.shaders.iter().filter(|s| model_of(&s.category).is_some()).map(|s| s.name.as_str()))
            .collect()
    }

    /// The binding of material (or shader) `name`, whose shader must be one of the
    /// [`SHADING_MODELS`]. Its inputs carry `standard_surface`'s names whatever the model:
    /// each comes from the model's corresponding input (`open_pbr_surface`'s `base_metalness`,
    /// `gltf_pbr`'s `metallic` for `metalness`, ...), or takes that model's own default when
    /// unset (an `open_pbr_surface` left at its defaults has roughness 0.3, a `gltf_pbr` is a
    /// rough white metal). Inputs the renderer does not honour that are set to anything but the
    /// model's default are named together in one warning.
    pub fn material(&self, name: &str) -> Option<MaterialBinding> {
        let shader_name = self.materials.iter().find(|(m, _)| m == name).map(|(_, s)| s.as_str()).unwrap_or(name);
        let (sh, model) = self
            .shaders
            .iter()
            .filter(|s| s.name == shader_name)
            .find_map(|s| model_of(&s.category).map(|m| (s, m)))?;
        let lookup = |n: &str| sh.inputs.iter().find(|(k, _)| k == n).map(|(_, s)| s);
        let mut warnings: Vec<String> = Vec::new();
        let read = |n: &str, def: InputDefault, warnings: &mut Vec<String>| match lookup(n) {
            Some(ShaderInput::Value(Some(v))) => MaterialSource::Constant(*v),
            Some(ShaderInput::Output(Ok(o))) => MaterialSource::Output(*o),
            Some(ShaderInput::Output(Err(reason))) => {
                warnings.push(format!("{}: input `{n}` is not available: {reason}", sh.location));
                default_source(def)
            }
            _ => default_source(def),
        };
        let mut inputs = Vec::new();
        for (&(cname, cdef), mapped) in SUPPORTED_INPUTS.iter().zip(model.map) {
            let src = match *mapped {
                Mapped::Same => read(cname, cdef, &mut warnings),
                Mapped::Input(n, def) => read(n, def, &mut warnings),
                Mapped::Fixed(ty, v) => MaterialSource::Constant(Value::new(ty, &[v])),
                Mapped::GltfOpacity => self.gltf_opacity(sh, &mut warnings, &read),
            };
            inputs.push((cname, src));
        }
        let mut ignored = Vec::new();
        for (iname, si) in &sh.inputs {
            if model.handles(iname) {
                continue;
            }
            let default = model.unsupported.iter().find(|(n, _)| n == iname).map(|(_, d)| *d);
            let differs = match si {
                ShaderInput::Output(_) => true,
                ShaderInput::Value(Some(v)) => default.is_none_or(|d| {
                    v.channels().iter().enumerate().any(|(k, c)| (*c - d[k.min(d.len() - 1)]).abs() > 1e-6)
                }),
                ShaderInput::Value(None) => false,
            };
            if differs {
                ignored.push(format!("`{iname}`"));
            }
        }
        if !ignored.is_empty() {
            let (noun, verb) = if ignored.len() == 1 { ("input", "is") } else { ("inputs", "are") };
            warnings.push(format!(
                "{}: {} {noun} {} {verb} not supported and {verb} ignored",
                sh.location,
                model.category,
                ignored.join(", ")
            ));
        }
        // glTF reads `base_color` twice (base and transmission tint): say a problem once.
        let mut seen = HashSet::new();
        warnings.retain(|w| seen.insert(w.clone()));
        Some(MaterialBinding {
            name: name.to_string(),
            shader: sh.name.clone(),
            model: model.category,
            inputs,
            warnings,
        })
    }

    /// A `gltf_pbr`'s opacity, as its definition's graph computes it from `alpha`,
    /// `alpha_mode` and `alpha_cutoff` (see [`GLTF_PBR`]).
    fn gltf_opacity(
        &self,
        sh: &ShaderDef,
        warnings: &mut Vec<String>,
        read: &dyn Fn(&str, InputDefault, &mut Vec<String>) -> MaterialSource,
    ) -> MaterialSource {
        let lookup = |n: &str| sh.inputs.iter().find(|(k, _)| k == n).map(|(_, s)| s);
        let opaque = MaterialSource::Constant(Value::float(1.0));
        let mode = gltf_alpha_mode(lookup("alpha_mode")).unwrap_or_else(|w| {
            warnings.push(format!("{}: {w}", sh.location));
            0
        });
        match mode {
            0 => opaque,
            1 => {
                if matches!(lookup("alpha"), Some(ShaderInput::Output(Ok(_)))) {
                    return match &sh.extras.alpha_mask {
                        Some(Ok(o)) => MaterialSource::Output(*o),
                        Some(Err(reason)) => {
                            warnings.push(format!("{}: input `alpha` is not available: {reason}", sh.location));
                            opaque
                        }
                        None => opaque,
                    };
                }
                let cutoff = gltf_alpha_cutoff(lookup("alpha_cutoff")).unwrap_or_else(|w| {
                    warnings.push(format!("{}: {w}", sh.location));
                    0.5
                });
                let alpha = match read("alpha", f(1.0), warnings) {
                    MaterialSource::Constant(v) => v.v[0],
                    _ => 1.0,
                };
                MaterialSource::Constant(Value::float(if alpha >= cutoff { 1.0 } else { 0.0 }))
            }
            _ => read("alpha", f(1.0), warnings),
        }
    }

    /// Input `input` of a shader of any category, with the type it delivers: `material` names a
    /// material (then `shader`, if given, must be its shader) or a shader. `None` if there is no
    /// such shader; `Err` with the reason if the input cannot be evaluated. An input left unset
    /// takes its model's default for the [`SHADING_MODELS`] when the binding knows it (the
    /// inputs it reads; [`MaterialSource::Geometric`] for normals) and is an error otherwise
    /// (other shaders' defaults are not known here).
    pub fn shader_input(
        &self,
        material: &str,
        shader: Option<&str>,
        input: &str,
    ) -> Option<Result<(MaterialSource, ValueType), String>> {
        let sname = match self.materials.iter().find(|(m, _)| m == material) {
            Some((_, s)) => {
                if shader.is_some_and(|x| x != s) {
                    return None;
                }
                s.as_str()
            }
            None if shader.is_none() => material,
            None => return None,
        };
        let sh = self.shaders.iter().find(|s| s.name == sname)?;
        let unset = || match model_of(&sh.category).and_then(|m| m.default_of(input)) {
            Some(Some((ty, v))) => Ok((MaterialSource::Constant(Value::new(ty, &v[..ty.channels()])), ty)),
            Some(None) => Ok((MaterialSource::Geometric, ValueType::Vector3)),
            None => Err(format!("input `{input}` of `{}` ({}) is not set", sh.name, sh.category)),
        };
        Some(match sh.inputs.iter().find(|(n, _)| n == input).map(|(_, s)| s) {
            Some(ShaderInput::Value(Some(v))) => Ok((MaterialSource::Constant(*v), v.ty)),
            Some(ShaderInput::Output(Ok(o))) => Ok((MaterialSource::Output(*o), self.graph.output(*o).ty)),
            Some(ShaderInput::Output(Err(reason))) => Err(reason.clone()),
            Some(ShaderInput::Value(None)) | None => unset(),
        })
    }

    /// `material/shader/input` for every input set or connected on a material's shader, then
    /// `shader/input` for shaders no material uses.
    pub fn shader_input_paths(&self) -> Vec<String> {
        let mut v = Vec::new();
        let mut used = HashSet::new();
        for (m, s) in &self.materials {
            if let Some(sh) = self.shaders.iter().find(|x| &x.name == s) {
                used.insert(s.as_str());
                v.extend(sh.inputs.iter().filter(|(_, i)| is_set(i)).map(|(n, _)| format!("{m}/{s}/{n}")));
            }
        }
        for sh in self.shaders.iter().filter(|s| !used.contains(s.name.as_str())) {
            v.extend(sh.inputs.iter().filter(|(_, i)| is_set(i)).map(|(n, _)| format!("{}/{n}", sh.name)));
        }
        v
    }
}

fn is_set(i: &ShaderInput) -> bool {
    !matches!(i, ShaderInput::Value(None))
}

fn default_source(def: InputDefault) -> MaterialSource {
    match def {
        Some((ty, v)) => MaterialSource::Constant(Value::new(ty, &v[..ty.channels()])),
        None => MaterialSource::Geometric,
    }
}

const SHADER_TYPES: &[&str] =
    &["surfaceshader", "material", "displacementshader", "volumeshader", "lightshader", "BSDF", "EDF", "VDF"];

/// Top-level elements that carry no node content.
const NON_CONTENT: &[&str] = &[
    "nodedef",
    "typedef",
    "look",
    "lookgroup",
    "collection",
    "geominfo",
    "geompropdef",
    "implementation",
    "unitdef",
    "unittypedef",
    "propertyset",
    "variantset",
    "backdrop",
    "token",
    "attributedef",
    "targetdef",
    "member",
    "comment",
];

/// The newest version read, and the oldest upgraded.
const NEWEST: (u32, u32) = (1, 39);
const OLDEST: (u32, u32) = (1, 36);

const XINCLUDE_NS: &str = "http://www.w3.org/2001/XInclude";

fn read_text(path: &Path, at: &Location) -> Result<String, LoadError> {
    std::fs::read_to_string(path).map_err(|e| LoadError {
        location: at.clone(),
        kind: if e.kind() == std::io::ErrorKind::NotFound {
            LoadErrorKind::MissingFile(path.to_path_buf())
        } else {
            LoadErrorKind::Io(format!("{}: {e}", path.display()))
        },
    })
}

fn parse_xml<'i>(text: &'i str, path: &Path) -> Result<roxmltree::Document<'i>, LoadError> {
    roxmltree::Document::parse(text).map_err(|e| {
        let p = e.pos();
        LoadError {
            location: Location { file: path.to_path_buf(), line: p.row, column: p.col },
            kind: LoadErrorKind::Xml(e.to_string()),
        }
    })
}

fn canonical(p: &Path) -> PathBuf {
    p.canonicalize().unwrap_or_else(|_| p.to_path_buf())
}

/// Reads `text` (from `path`) and, depth first, every file it includes, into `out`.
fn gather(
    text: String,
    path: &Path,
    opts: &LoadOptions,
    out: &mut Vec<(PathBuf, String)>,
    stack: &mut Vec<PathBuf>,
) -> Result<(), LoadError> {
    let includes: Vec<(String, Location)> = {
        let xml = parse_xml(&text, path)?;
        let mut v = Vec::new();
        for el in xml.root_element().children().filter(|c| c.is_element()) {
            let t = el.tag_name();
            if t.name() == "include" && t.namespace() == Some(XINCLUDE_NS) {
                let p = xml.text_pos_at(el.range().start);
                let loc = Location { file: path.to_path_buf(), line: p.row, column: p.col };
                let Some(href) = el.attribute("href") else {
                    return Err(LoadError {
                        location: loc,
                        kind: LoadErrorKind::Structure("xi:include has no href attribute".into()),
                    });
                };
                v.push((href.to_string(), loc));
            }
        }
        v
    };
    stack.push(canonical(path));
    out.push((path.to_path_buf(), text));
    for (href, loc) in includes {
        let base = path.parent().unwrap_or(Path::new("."));
        let found = std::iter::once(base.join(&href))
            .chain(opts.search_paths.iter().map(|s| s.join(&href)))
            .find(|p| p.is_file());
        let Some(file) = found else {
            return Err(LoadError { location: loc, kind: LoadErrorKind::MissingFile(PathBuf::from(href)) });
        };
        let c = canonical(&file);
        if stack.contains(&c) {
            return Err(LoadError {
                location: loc,
                kind: LoadErrorKind::Structure(format!(
                    "include cycle: `{}` includes itself (through {})",
                    file.display(),
                    stack.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(" → ")
                )),
            });
        }
        if out.iter().any(|(p, _)| canonical(p) == c) {
            continue;
        }
        let t = read_text(&file, &loc)?;
        gather(t, &file, opts, out, stack)?;
    }
    stack.pop();
    Ok(())
}

fn parse_version(s: &str) -> Option<(u32, u32)> {
    let mut it = s.trim().split('.');
    let major = it.next()?.parse().ok()?;
    let minor = it.next()?.parse().ok()?;
    Some((major, minor))
}

/// How a colour space encodes values.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Transfer {
    Linear,
    Srgb,
    Gamma(f64),
}

/// Colour primaries (with their white point).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Primaries {
    Rec709,
    Ap1,
    AdobeRgb,
    DisplayP3,
}

impl Primaries {
    /// The matrix to linear Rec.709 primaries (rows: output channels), as MaterialX's colour
    /// management library defines it.
    fn to_rec709(self) -> DMat3 {
        let rows = match self {
            Primaries::Rec709 => return DMat3::IDENTITY,
            Primaries::Ap1 => [
                [1.705050992658, -0.621792120657, -0.083258872001],
                [-0.130256417507, 1.140804736575, -0.010548319068],
                [-0.024003356805, -0.128968976065, 1.15297233287],
            ],
            Primaries::AdobeRgb => [[1.39835574, -0.398355744, 0.0], [0.0, 1.0, 0.0], [0.0, -0.0429289893, 1.04292899]],
            Primaries::DisplayP3 => [
                [1.22493029, -0.22492968, 0.00000006],
                [-0.04205868, 1.04205894, -0.00000001],
                [-0.01964128, -0.07864794, 1.09828925],
            ],
        };
        DMat3::from_cols_array_2d(&rows).transpose()
    }
}

/// The colour spaces a document may name.
const COLOR_SPACES: &[&str] = &[
    "lin_rec709",
    "srgb_texture",
    "g22_rec709",
    "g18_rec709",
    "rec709_display",
    "acescg",
    "lin_ap1",
    "g22_ap1",
    "g18_ap1",
    "lin_adobergb",
    "adobergb",
    "srgb_displayp3",
    "lin_displayp3",
];

fn color_space(name: &str) -> Option<(Transfer, Primaries)> {
    use Primaries::*;
    use Transfer::*;
    Some(match name {
        "lin_rec709" => (Linear, Rec709),
        "srgb_texture" => (Srgb, Rec709),
        "g22_rec709" => (Gamma(2.2), Rec709),
        "g18_rec709" => (Gamma(1.8), Rec709),
        "rec709_display" => (Gamma(2.4), Rec709),
        "acescg" | "lin_ap1" => (Linear, Ap1),
        "g22_ap1" => (Gamma(2.2), Ap1),
        "g18_ap1" => (Gamma(1.8), Ap1),
        "lin_adobergb" => (Linear, AdobeRgb),
        "adobergb" => (Gamma(563.0 / 256.0), AdobeRgb),
        "srgb_displayp3" => (Srgb, DisplayP3),
        "lin_displayp3" => (Linear, DisplayP3),
        _ => return None,
    })
}

/// A conversion from a colour space to the working space.
#[derive(Clone, Copy, Debug)]
struct Conversion {
    transfer: Transfer,
    /// Source primaries to working primaries, `None` when they are the same.
    matrix: Option<DMat3>,
}

impl Conversion {
    fn apply(&self, rgb: DVec3) -> DVec3 {
        let decode = |x: f64| match self.transfer {
            Transfer::Linear => x,
            Transfer::Srgb => {
                if x > 0.04045 {
                    ((x + 0.055).max(0.0) / 1.055).powf(2.4)
                } else {
                    x / 12.92
                }
            }
            Transfer::Gamma(g) => x.max(0.0).powf(g),
        };
        let lin = DVec3::new(decode(rgb.x), decode(rgb.y), decode(rgb.z));
        match self.matrix {
            Some(m) => m * lin,
            None => lin,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
enum State {
    Visiting,
    Done(Source),
}

/// A failure: hard (always an error) or soft (depends on unsupported nodes: indices into
/// `Importer::unsupported`).
enum Fail {
    Hard(LoadError),
    Soft(Vec<usize>),
}

impl From<LoadError> for Fail {
    fn from(e: LoadError) -> Fail {
        Fail::Hard(e)
    }
}

/// Collects the unsupported nodes behind soft failures while going on with the other inputs.
fn merge_soft(acc: &mut Vec<usize>, f: Fail) -> Result<(), Fail> {
    match f {
        Fail::Soft(ix) => {
            acc.extend(ix);
            acc.sort_unstable();
            acc.dedup();
            Ok(())
        }
        hard => Err(hard),
    }
}

/// What `interfacename` refers to in a scope.
enum Iface<'a, 'i> {
    /// The document's top-level `<input>`s.
    Top,
    /// A node graph's own `<input>`s, resolved at the top level.
    Graph(HashMap<&'a str, XNode<'a, 'i>>),
    /// The implementation of nodedef `nodedef`: the inputs of `instance` (resolved in the
    /// scope's parent), else the nodedef's defaults (or the graph's own `<input>`s).
    Def { nodedef: usize, own: HashMap<&'a str, XNode<'a, 'i>>, instance: Option<XNode<'a, 'i>> },
}

struct Scope<'a, 'i> {
    /// Qualified-name prefix: "" at the top, the graph's name, or the instance's qualified name.
    prefix: String,
    nodes: HashMap<&'a str, XNode<'a, 'i>>,
    outputs: Vec<XNode<'a, 'i>>,
    iface: Iface<'a, 'i>,
    parent: Option<usize>,
}

struct NodeDefInfo<'a, 'i> {
    name: &'a str,
    node: &'a str,
    inputs: Vec<XNode<'a, 'i>>,
    /// `(name, type)` of each output.
    outputs: Vec<(&'a str, &'a str)>,
    version: Option<&'a str>,
    default_version: bool,
}

/// How a node's category is defined.
enum DefKind {
    /// By the node library.
    Builtin,
    /// By nodedef `k` of the document, implemented by a node graph.
    Custom(usize),
    /// By nodedef `k`, without a node graph implementation.
    Unimplemented(usize),
    /// Not at all.
    Unknown,
}

/// The contents of a `<nodegraph>`: nodes, outputs, interface inputs, shader nodes.
type GraphContent<'a, 'i> =
    (HashMap<&'a str, XNode<'a, 'i>>, Vec<XNode<'a, 'i>>, HashMap<&'a str, XNode<'a, 'i>>, Vec<XNode<'a, 'i>>);

struct Importer<'a, 'i> {
    docs: &'a [roxmltree::Document<'i>],
    paths: &'a [PathBuf],
    versions: Vec<(u32, u32)>,
    opts: LoadOptions,
    /// The working colour space's primaries.
    working: Primaries,
    scopes: Vec<Scope<'a, 'i>>,
    /// Scopes of `<nodegraph>`s by name.
    graph_scopes: HashMap<&'a str, usize>,
    /// Every `<nodegraph>` element by name (including implementations of outside nodedefs).
    graph_elems: HashMap<&'a str, XNode<'a, 'i>>,
    top_inputs: HashMap<&'a str, XNode<'a, 'i>>,
    nodedefs: Vec<NodeDefInfo<'a, 'i>>,
    nodedef_by_name: HashMap<&'a str, usize>,
    /// nodedef name → name of the node graph implementing it.
    impls: HashMap<&'a str, &'a str>,
    shader_elems: Vec<(usize, XNode<'a, 'i>)>,
    material_elems: Vec<XNode<'a, 'i>>,
    /// ≤ 1.37 `<material>` elements (with `<shaderref>`s).
    legacy_materials: Vec<XNode<'a, 'i>>,
    state: HashMap<String, State>,
    soft: HashMap<String, Vec<usize>>,
    /// Instance scopes by the instance's qualified name.
    instances: HashMap<String, usize>,
    builder: GraphBuilder,
    shaders: Vec<ShaderDef>,
    materials: Vec<(String, String)>,
    skipped: Vec<(String, String)>,
    unsupported: Vec<Unsupported>,
    shader_outputs: HashSet<String>,
}

fn qualify(scope: &str, name: &str) -> String {
    if scope.is_empty() {
        name.to_string()
    } else {
        format!("{scope}/{name}")
    }
}

impl<'a, 'i> Importer<'a, 'i> {
    fn new(docs: &'a [roxmltree::Document<'i>], paths: &'a [PathBuf], opts: &LoadOptions) -> Result<Self, LoadError> {
        let mut imp = Importer {
            docs,
            paths,
            versions: Vec::new(),
            opts: opts.clone(),
            working: Primaries::Rec709,
            scopes: Vec::new(),
            graph_scopes: HashMap::new(),
            graph_elems: HashMap::new(),
            top_inputs: HashMap::new(),
            nodedefs: Vec::new(),
            nodedef_by_name: HashMap::new(),
            impls: HashMap::new(),
            shader_elems: Vec::new(),
            material_elems: Vec::new(),
            legacy_materials: Vec::new(),
            state: HashMap::new(),
            soft: HashMap::new(),
            instances: HashMap::new(),
            builder: GraphBuilder::new(),
            shaders: Vec::new(),
            materials: Vec::new(),
            skipped: Vec::new(),
            unsupported: Vec::new(),
            shader_outputs: HashSet::new(),
        };
        for d in docs {
            let root = d.root_element();
            if root.tag_name().name() != "materialx" {
                return Err(imp.err(root, LoadErrorKind::Structure("root element is not <materialx>".into())));
            }
            let v = match root.attribute("version") {
                None => NEWEST,
                Some(s) => {
                    let v = parse_version(s).ok_or_else(|| {
                        imp.err(root, LoadErrorKind::Structure(format!("malformed MaterialX version `{s}`")))
                    })?;
                    if v > NEWEST {
                        return Err(imp.err(
                            root,
                            LoadErrorKind::Structure(format!(
                                "MaterialX version {s} is newer than this importer reads ({}.{})",
                                NEWEST.0, NEWEST.1
                            )),
                        ));
                    }
                    if v < OLDEST {
                        return Err(imp.err(
                            root,
                            LoadErrorKind::Structure(format!(
                                "MaterialX version {s} predates {}.{}, the oldest this importer upgrades",
                                OLDEST.0, OLDEST.1
                            )),
                        ));
                    }
                    v
                }
            };
            imp.versions.push(v);
        }
        let root = docs[0].root_element();
        if let Some(cs) = root.attribute("colorspace") {
            let (t, p) = color_space(cs).ok_or_else(|| imp.unknown_color_space(root, cs))?;
            if t != Transfer::Linear {
                return Err(imp.err(
                    root,
                    LoadErrorKind::Structure(format!(
                        "working colour space `{cs}` is not linear (use lin_rec709 or acescg)"
                    )),
                ));
            }
            imp.working = p;
        }
        Ok(imp)
    }

    fn unknown_color_space(&self, at: XNode, cs: &str) -> LoadError {
        self.err(
            at,
            LoadErrorKind::Structure(format!("unknown colour space `{cs}`; supported: {}", COLOR_SPACES.join(", "))),
        )
    }

    fn doc_index(&self, n: XNode) -> usize {
        let d = n.document();
        self.docs.iter().position(|x| std::ptr::eq(x, d)).unwrap_or(0)
    }

    fn version(&self, n: XNode) -> (u32, u32) {
        self.versions[self.doc_index(n)]
    }

    fn loc(&self, n: XNode) -> Location {
        let k = self.doc_index(n);
        let p = self.docs[k].text_pos_at(n.range().start);
        Location { file: self.paths[k].clone(), line: p.row, column: p.col }
    }

    fn err(&self, n: XNode, kind: LoadErrorKind) -> LoadError {
        LoadError { location: self.loc(n), kind }
    }

    fn hard(&self, n: XNode, kind: LoadErrorKind) -> Fail {
        Fail::Hard(self.err(n, kind))
    }

    /// Records an unsupported node (once per element and detail) and returns the soft failure.
    fn unsupported(&mut self, category: &str, node: &str, detail: String, at: XNode) -> Fail {
        let location = self.loc(at);
        let k = match self
            .unsupported
            .iter()
            .position(|u| u.category == category && u.detail == detail && u.location == location)
        {
            Some(k) => k,
            None => {
                self.unsupported.push(Unsupported {
                    category: category.to_string(),
                    node: node.to_string(),
                    detail,
                    location,
                });
                self.unsupported.len() - 1
            }
        };
        Fail::Soft(vec![k])
    }

    fn reason(&self, ix: &[usize]) -> String {
        let items: Vec<String> = ix.iter().map(|&k| self.unsupported[k].to_string()).collect();
        format!("needs unsupported {}", items.join(", "))
    }

    fn name_of(&self, el: XNode<'a, 'i>) -> Result<&'a str, LoadError> {
        el.attribute("name").ok_or_else(|| {
            self.err(el, LoadErrorKind::Structure(format!("<{}> has no name attribute", el.tag_name().name())))
        })
    }

    /// The type attribute, upgraded (`color2` was `vector2` before 1.38).
    fn type_name(&self, el: XNode<'a, 'i>) -> Option<&'a str> {
        match el.attribute("type") {
            Some("color2") if self.version(el) < (1, 38) => Some("vector2"),
            t => t,
        }
    }

    fn value_type(&self, el: XNode<'a, 'i>) -> Option<ValueType> {
        self.type_name(el).and_then(ValueType::from_name)
    }

    /// The input elements of a node (`parameter`s too before 1.38; `bindinput`/`bindparam` of a
    /// legacy `shaderref`).
    fn inputs_of(&self, el: XNode<'a, 'i>) -> Vec<XNode<'a, 'i>> {
        let legacy = self.version(el) < (1, 38);
        el.children()
            .filter(|c| {
                c.is_element()
                    && match c.tag_name().name() {
                        "input" => true,
                        "parameter" | "bindinput" | "bindparam" => legacy,
                        _ => false,
                    }
            })
            .collect()
    }

    /// A node's category, upgraded to 1.39.
    fn category(&self, el: XNode<'a, 'i>) -> &'a str {
        let c = el.tag_name().name();
        if self.version(el) >= (1, 37) {
            return c;
        }
        let has = |n: &str| self.inputs_of(el).iter().any(|i| i.attribute("name") == Some(n));
        match c {
            "rotate" => {
                if self.type_name(el) == Some("vector2") {
                    "rotate2d"
                } else {
                    "rotate3d"
                }
            }
            "compare" => "ifgreatereq",
            "geomattrvalue" => "geompropvalue",
            "combine" => {
                if has("in4") {
                    "combine4"
                } else if has("in3") {
                    "combine3"
                } else {
                    "combine2"
                }
            }
            "separate" => {
                let t = self.inputs_of(el).into_iter().find(|i| i.attribute("name") == Some("in"));
                match t.and_then(|i| self.value_type(i)).map(|t| t.channels()) {
                    Some(4) => "separate4",
                    Some(3) => "separate3",
                    _ => "separate2",
                }
            }
            "transformpoint" | "transformvector" | "transformnormal" if !has("fromspace") && !has("tospace") => {
                "transformmatrix"
            }
            _ => c,
        }
    }

    /// An input's name, upgraded to 1.39.
    fn input_name(&self, node: XNode<'a, 'i>, category: &str, inp: XNode<'a, 'i>) -> &'a str {
        let n = inp.attribute("name").unwrap_or("");
        let v = self.version(node);
        if v >= (1, 39) {
            return n;
        }
        let original = node.tag_name().name();
        match (original, category, n) {
            ("compare", _, "intest") if v < (1, 37) => "value1",
            ("compare", _, "cutoff") if v < (1, 37) => "value2",
            ("compare", _, "in1") if v < (1, 37) => "in2",
            ("compare", _, "in2") if v < (1, 37) => "in1",
            // 1.37 → 1.38 swaps in1 and in2; 1.38 → 1.39 renames in1 → iny, in2 → inx.
            (_, "atan2", "in1") => {
                if v < (1, 38) {
                    "inx"
                } else {
                    "iny"
                }
            }
            (_, "atan2", "in2") => {
                if v < (1, 38) {
                    "iny"
                } else {
                    "inx"
                }
            }
            _ => n,
        }
    }

    /// Reads the top level of every document.
    fn collect(&mut self) -> Result<(), LoadError> {
        let docs = self.docs;
        // Definitions first, so that graphs know whether they implement one.
        for d in docs {
            for el in d.root_element().children().filter(|c| c.is_element()) {
                match el.tag_name().name() {
                    "nodedef" => {
                        let name = self.name_of(el)?;
                        if self.nodedef_by_name.contains_key(name) {
                            continue;
                        }
                        let node = el.attribute("node").ok_or_else(|| {
                            self.err(el, LoadErrorKind::Structure(format!("nodedef `{name}` has no node attribute")))
                        })?;
                        let inputs = self.inputs_of(el);
                        let mut outputs: Vec<(&'a str, &'a str)> = Vec::new();
                        for o in el.children().filter(|c| c.is_element() && c.has_tag_name("output")) {
                            outputs.push((self.name_of(o)?, self.type_name(o).unwrap_or("")));
                        }
                        if outputs.is_empty() {
                            if let Some(t) = self.type_name(el).filter(|t| *t != "multioutput") {
                                outputs.push(("out", t));
                            }
                        }
                        self.nodedef_by_name.insert(name, self.nodedefs.len());
                        self.nodedefs.push(NodeDefInfo {
                            name,
                            node,
                            inputs,
                            outputs,
                            version: el.attribute("version"),
                            default_version: el.attribute("isdefaultversion") == Some("true"),
                        });
                    }
                    "implementation" => {
                        if let (Some(nd), Some(g)) = (el.attribute("nodedef"), el.attribute("nodegraph")) {
                            self.impls.entry(nd).or_insert(g);
                        }
                    }
                    "nodegraph" => {
                        let name = self.name_of(el)?;
                        self.graph_elems.entry(name).or_insert(el);
                        if let Some(nd) = el.attribute("nodedef") {
                            self.impls.entry(nd).or_insert(name);
                        }
                    }
                    _ => {}
                }
            }
        }
        self.scopes.push(Scope {
            prefix: String::new(),
            nodes: HashMap::new(),
            outputs: Vec::new(),
            iface: Iface::Top,
            parent: None,
        });
        let mut top_nodes: HashMap<&'a str, XNode<'a, 'i>> = HashMap::new();
        let mut top_outputs = Vec::new();
        for d in docs {
            for el in d.root_element().children().filter(|c| c.is_element()) {
                let tag = el.tag_name().name();
                if tag == "include" && el.tag_name().namespace() == Some(XINCLUDE_NS) {
                    continue;
                }
                match tag {
                    "nodegraph" => {
                        let name = self.name_of(el)?;
                        if self.graph_scopes.contains_key(name) || self.graph_elems.get(name) != Some(&el) {
                            continue;
                        }
                        let iface = match el.attribute("nodedef") {
                            Some(nd) => match self.nodedef_by_name.get(nd) {
                                Some(&k) => Iface::Def { nodedef: k, own: HashMap::new(), instance: None },
                                // Implements a definition from outside the document: not content.
                                None => continue,
                            },
                            None => Iface::Graph(HashMap::new()),
                        };
                        let (nodes, outputs, own_inputs, shaders) = self.scan_graph(el)?;
                        let iface = match iface {
                            Iface::Def { nodedef, .. } => Iface::Def { nodedef, own: own_inputs, instance: None },
                            _ => Iface::Graph(own_inputs),
                        };
                        let id = self.scopes.len();
                        self.scopes.push(Scope { prefix: name.to_string(), nodes, outputs, iface, parent: None });
                        self.graph_scopes.insert(name, id);
                        self.shader_elems.extend(shaders.into_iter().map(|s| (id, s)));
                    }
                    "output" => top_outputs.push(el),
                    "input" | "parameter" => {
                        let name = self.name_of(el)?;
                        self.top_inputs.entry(name).or_insert(el);
                    }
                    "material" if self.version(el) < (1, 38) => self.legacy_materials.push(el),
                    _ if NON_CONTENT.contains(&tag) => {}
                    _ => {
                        let ty = el.attribute("type").unwrap_or("");
                        if tag == "surfacematerial" || ty == "material" {
                            self.material_elems.push(el);
                        } else if SHADER_TYPES.contains(&ty) {
                            self.shader_elems.push((0, el));
                        } else {
                            let name = self.name_of(el)?;
                            if let Some(prev) = top_nodes.get(name) {
                                if self.doc_index(*prev) == self.doc_index(el) {
                                    return Err(self.err(el, BuildError::DuplicateName(name.to_string()).into()));
                                }
                                continue;
                            }
                            top_nodes.insert(name, el);
                        }
                    }
                }
            }
        }
        self.scopes[0].nodes = top_nodes;
        self.scopes[0].outputs = top_outputs;
        // Shaders of legacy materials: each `shaderref` is a shader node.
        for m in self.legacy_materials.clone() {
            let mname = self.name_of(m)?;
            for sr in m.children().filter(|c| c.is_element() && c.has_tag_name("shaderref")) {
                let sname = self.name_of(sr)?;
                self.shader_elems.push((0, sr));
                self.materials.push((mname.to_string(), sname.to_string()));
            }
        }
        Ok(())
    }

    /// The contents of a node graph element.
    fn scan_graph(&self, g: XNode<'a, 'i>) -> Result<GraphContent<'a, 'i>, LoadError> {
        let legacy = self.version(g) < (1, 38);
        let mut nodes = HashMap::new();
        let mut outputs = Vec::new();
        let mut inputs = HashMap::new();
        let mut shaders = Vec::new();
        for c in g.children().filter(|c| c.is_element()) {
            match c.tag_name().name() {
                "input" => {
                    inputs.insert(self.name_of(c)?, c);
                }
                "parameter" if legacy => {
                    inputs.insert(self.name_of(c)?, c);
                }
                "output" => outputs.push(c),
                "backdrop" | "token" | "comment" => {}
                _ => {
                    if SHADER_TYPES.contains(&c.attribute("type").unwrap_or("")) {
                        shaders.push(c);
                    } else {
                        let name = self.name_of(c)?;
                        if nodes.insert(name, c).is_some() {
                            return Err(self.err(c, BuildError::DuplicateName(name.to_string()).into()));
                        }
                    }
                }
            }
        }
        Ok((nodes, outputs, inputs, shaders))
    }

    fn build_all(&mut self) -> Result<(), LoadError> {
        let content_scopes = self.scopes.len();
        // Every node, so that every node is validated.
        for scope in 0..content_scopes {
            let mut names: Vec<(&'a str, (usize, usize))> =
                self.scopes[scope].nodes.iter().map(|(n, e)| (*n, (self.doc_index(*e), e.range().start))).collect();
            names.sort_by_key(|(_, p)| *p);
            for (n, _) in names {
                let el = self.scopes[scope].nodes[n];
                // Matrices are folded at load, not added to the graph: fold to check them.
                if let Some(size) = self.type_name(el).and_then(Matrix::size_of_type) {
                    match self.fold_matrix(scope, el, size, 0) {
                        Ok(_) | Err(Fail::Soft(_)) => {}
                        Err(Fail::Hard(e)) => return Err(e),
                    }
                    continue;
                }
                let outs: Vec<Option<&'a str>> = match self.resolve_def(scope, el) {
                    Ok(DefKind::Custom(k)) => self.nodedefs[k].outputs.iter().map(|(o, _)| Some(*o)).collect(),
                    Ok(_) => vec![None],
                    Err(Fail::Hard(e)) => return Err(e),
                    Err(Fail::Soft(_)) => continue,
                };
                for o in outs {
                    match self.node_output(scope, n, o, el) {
                        Ok(_) | Err(Fail::Soft(_)) => {}
                        Err(Fail::Hard(e)) => return Err(e),
                    }
                }
            }
        }
        // Outputs.
        for scope in 0..content_scopes {
            let outs = self.scopes[scope].outputs.clone();
            for o in outs {
                let name = qualify(&self.scopes[scope].prefix, self.name_of(o)?);
                let Some(tyname) = self.type_name(o) else {
                    return Err(self.err(o, LoadErrorKind::Structure("<output> has no type attribute".into())));
                };
                let Some(ty) = ValueType::from_name(tyname) else { continue };
                match self.output_source(scope, o) {
                    Ok(src) => {
                        let found = self.builder.source_type(&src);
                        if found.channels() != ty.channels() {
                            return Err(self.err(
                                o,
                                LoadErrorKind::Build(BuildError::TypeMismatch {
                                    node: name,
                                    input: "output".into(),
                                    expected: ty.name().into(),
                                    found,
                                }),
                            ));
                        }
                        self.builder.add_output(&name, ty, src).map_err(|e| self.err(o, e.into()))?;
                    }
                    Err(Fail::Soft(ix)) => {
                        let r = self.reason(&ix);
                        self.skipped.push((name, r));
                    }
                    Err(Fail::Hard(e)) => return Err(e),
                }
            }
        }
        // Shaders and materials.
        for (scope, el) in self.shader_elems.clone() {
            let sname = self.name_of(el)?.to_string();
            let category = match el.tag_name().name() {
                "shaderref" => el.attribute("node").unwrap_or("shaderref").to_string(),
                c => c.to_string(),
            };
            let mut inputs = Vec::new();
            for inp in self.inputs_of(el) {
                let iname = self.name_of(inp)?.to_string();
                let connected = inp.attribute("nodename").is_some()
                    || inp.attribute("nodegraph").is_some()
                    || inp.attribute("interfacename").is_some();
                // A connection to a nodegraph output binds that output itself.
                let existing = inp.attribute("nodegraph").and_then(|g| {
                    let sc = self.graph_scopes.get(g).map(|&s| &self.scopes[s])?;
                    let o = match inp.attribute("output") {
                        Some(o) => o,
                        None => sc.outputs.first().and_then(|o| o.attribute("name"))?,
                    };
                    self.builder.output_id(&qualify(g, o))
                });
                let si = if let Some(id) = existing {
                    ShaderInput::Output(Ok(id))
                } else if connected {
                    // Shaders in different graphs may share a name: qualify by the scope.
                    let out_name = qualify(&self.scopes[scope].prefix, &format!("{sname}.{iname}"));
                    let res = match self.input_source(scope, inp) {
                        Ok(Some(src)) => {
                            let ty = self.builder.source_type(&src);
                            self.shader_outputs.insert(out_name.clone());
                            Ok(self.builder.add_output(&out_name, ty, src).map_err(|e| self.err(inp, e.into()))?)
                        }
                        Ok(None) => Err("unconnected".to_string()),
                        Err(Fail::Soft(ix)) => Err(self.reason(&ix)),
                        Err(Fail::Hard(e)) => return Err(e),
                    };
                    ShaderInput::Output(res)
                } else {
                    let ty = match self.type_name(inp) {
                        Some(t) => ValueType::from_name(t),
                        None => {
                            return Err(self.err(inp, LoadErrorKind::Structure("<input> has no type attribute".into())))
                        }
                    };
                    let v = match (ty, inp.attribute("value")) {
                        (Some(t), Some(text)) => match self.typed_value(inp, t, text) {
                            Ok(v) => Some(v),
                            Err(Fail::Hard(e)) => return Err(e),
                            Err(Fail::Soft(_)) => None,
                        },
                        _ => None,
                    };
                    ShaderInput::Value(v)
                };
                inputs.push((iname, si));
            }
            let extras = if category == "gltf_pbr" {
                ShaderExtras { alpha_mask: self.gltf_alpha_mask(scope, el, &sname, &inputs)? }
            } else {
                ShaderExtras::default()
            };
            let location = self.loc(el);
            self.shaders.push(ShaderDef { name: sname, category, inputs, extras, location });
        }
        for el in self.material_elems.clone() {
            let mname = self.name_of(el)?.to_string();
            for inp in self.inputs_of(el) {
                if inp.attribute("name") == Some("surfaceshader") {
                    if let Some(s) = inp.attribute("nodename") {
                        self.materials.push((mname.clone(), s.to_string()));
                    }
                }
            }
        }
        Ok(())
    }

    /// For a `gltf_pbr` in MASK mode whose `alpha` is connected: adds `ifgreatereq(alpha,
    /// alpha_cutoff, 1, 0)` to the graph as output `<shader>.alpha_mask` (a shader-input
    /// output) and returns it; `None` for other modes and for constant alphas, which
    /// [`Document::material`] thresholds itself.
    fn gltf_alpha_mask(
        &mut self,
        scope: usize,
        el: XNode<'a, 'i>,
        sname: &str,
        inputs: &[(String, ShaderInput)],
    ) -> Result<Option<Result<OutputId, String>>, LoadError> {
        let lookup = |n: &str| inputs.iter().find(|(k, _)| k == n).map(|(_, s)| s);
        if gltf_alpha_mode(lookup("alpha_mode")) != Ok(1)
            || !matches!(lookup("alpha"), Some(ShaderInput::Output(Ok(_))))
        {
            return Ok(None);
        }
        let cutoff = gltf_alpha_cutoff(lookup("alpha_cutoff")).unwrap_or(0.5);
        let Some(inp) = self.inputs_of(el).into_iter().find(|i| i.attribute("name") == Some("alpha")) else {
            return Ok(None);
        };
        let src = match self.input_source(scope, inp) {
            Ok(Some(s)) => s,
            Ok(None) => return Ok(Some(Err("unconnected".into()))),
            Err(Fail::Soft(ix)) => return Ok(Some(Err(self.reason(&ix)))),
            Err(Fail::Hard(e)) => return Err(e),
        };
        let name = qualify(&self.scopes[scope].prefix, &format!("{sname}.alpha_mask"));
        let one = |v: f32| Source::Constant(Value::float(v));
        let node = match self.builder.add_node(
            &name,
            "ifgreatereq",
            ValueType::Float,
            &[("value1", src), ("value2", one(cutoff)), ("in1", one(1.0)), ("in2", one(0.0))],
            Vec::new(),
        ) {
            Ok(id) => id,
            Err(e) => return Ok(Some(Err(e.to_string()))),
        };
        self.shader_outputs.insert(name.clone());
        let out = self
            .builder
            .add_output(&name, ValueType::Float, Source::Node { node, channel: None })
            .map_err(|e| self.err(inp, e.into()))?;
        Ok(Some(Ok(out)))
    }

    /// Parses a value of type `ty` given on `el`: numbers, or a custom nodedef's enum name;
    /// colours are converted from their active colour space to the working space.
    fn typed_value(&self, el: XNode<'a, 'i>, ty: ValueType, text: &str) -> Result<Value, Fail> {
        let mut v = match parse_value(ty, text) {
            Some(v) => v,
            None => self.enum_value(el, text).and_then(|t| parse_value(ty, &t)).ok_or_else(|| {
                self.hard(el, LoadErrorKind::MalformedValue { ty: ty.name().to_string(), text: text.to_string() })
            })?,
        };
        if matches!(ty, ValueType::Color3 | ValueType::Color4) {
            if let Some(conv) = self.conversion(&[], el)? {
                let c = conv.apply(DVec3::new(v.v[0] as f64, v.v[1] as f64, v.v[2] as f64));
                v.v[0] = c.x as f32;
                v.v[1] = c.y as f32;
                v.v[2] = c.z as f32;
            }
        }
        Ok(v)
    }

    /// The `enumvalues` entry of enum name `text`, from `el`'s own `enum` or the matching input of
    /// the custom nodedef its node instantiates.
    fn enum_value(&self, el: XNode<'a, 'i>, text: &str) -> Option<String> {
        let lookup = |e: XNode| -> Option<String> {
            let names = e.attribute("enum")?;
            let values = e.attribute("enumvalues")?;
            let k = names.split(',').map(str::trim).position(|n| n == text.trim())?;
            // Values of multi-channel types are themselves comma separated: split evenly.
            let parts: Vec<&str> = values.split(',').map(str::trim).collect();
            let n = names.split(',').count();
            if n == 0 || !parts.len().is_multiple_of(n) {
                return None;
            }
            let w = parts.len() / n;
            Some(parts[k * w..(k + 1) * w].join(","))
        };
        if let Some(v) = lookup(el) {
            return Some(v);
        }
        let node = el.parent_element()?;
        let name = el.attribute("name")?;
        let category = self.category(node);
        let k = match node.attribute("nodedef").and_then(|n| self.nodedef_by_name.get(n)) {
            Some(&k) => k,
            None => self.nodedefs.iter().position(|d| d.node == category)?,
        };
        let di = self.nodedefs[k].inputs.iter().find(|i| i.attribute("name") == Some(name))?;
        lookup(*di)
    }

    /// The conversion from the active colour space to the working space: the `colorspace` of the
    /// first of `own` that has one, else of `el` or its nearest ancestor; `None` when there is
    /// nothing to do.
    fn conversion(&self, own: &[XNode<'a, 'i>], el: XNode<'a, 'i>) -> Result<Option<Conversion>, Fail> {
        let found = own
            .iter()
            .find_map(|e| e.attribute("colorspace").map(|c| (*e, c)))
            .or_else(|| el.ancestors().find_map(|a| a.attribute("colorspace").map(|c| (a, c))));
        let Some((at, cs)) = found else { return Ok(None) };
        if cs.is_empty() {
            return Ok(None);
        }
        let (transfer, primaries) = color_space(cs).ok_or_else(|| Fail::Hard(self.unknown_color_space(at, cs)))?;
        let matrix = (primaries != self.working)
            .then(|| self.working.to_rec709().inverse() * primaries.to_rec709())
            .filter(|m| !m.abs_diff_eq(DMat3::IDENTITY, 1e-12));
        if transfer == Transfer::Linear && matrix.is_none() {
            return Ok(None);
        }
        Ok(Some(Conversion { transfer, matrix }))
    }

    /// The source of an `<output>` element in `scope`.
    fn output_source(&mut self, scope: usize, o: XNode<'a, 'i>) -> Result<Source, Fail> {
        match self.input_source(scope, o)? {
            Some(s) => Ok(s),
            None => Err(self.hard(o, LoadErrorKind::Structure("output is not connected".into()))),
        }
    }

    /// The element that finally binds interface input `iname` of `scope` (following
    /// `interfacename` chains outwards), with the scope to resolve it in; `None` when the
    /// interface input exists but is neither set nor connected.
    fn interface_binding(
        &self,
        scope: usize,
        iname: &'a str,
        at: XNode<'a, 'i>,
    ) -> Result<Option<(XNode<'a, 'i>, usize)>, Fail> {
        let (mut sc, mut name, mut at) = (scope, iname, at);
        let mut seen: Vec<(usize, &'a str)> = Vec::new();
        loop {
            if seen.contains(&(sc, name)) {
                let chain: Vec<&str> = seen.iter().map(|(_, n)| *n).chain(std::iter::once(name)).collect();
                return Err(self.hard(at, LoadErrorKind::Structure(format!("interface cycle: {}", chain.join(" → ")))));
            }
            seen.push((sc, name));
            let (el, next): (Option<XNode<'a, 'i>>, usize) = match &self.scopes[sc].iface {
                Iface::Top => (self.top_inputs.get(name).copied(), 0),
                Iface::Graph(m) => (m.get(name).copied(), 0),
                Iface::Def { nodedef, own, instance } => {
                    let declared = self.nodedefs[*nodedef]
                        .inputs
                        .iter()
                        .find(|i| i.attribute("name") == Some(name))
                        .copied()
                        .or_else(|| own.get(name).copied());
                    let bound = instance.and_then(|i| {
                        self.inputs_of(i).into_iter().find(|c| {
                            c.attribute("name") == Some(name)
                                && ["value", "nodename", "nodegraph", "interfacename", "output"]
                                    .iter()
                                    .any(|a| c.attribute(*a).is_some())
                        })
                    });
                    match (declared, bound) {
                        (Some(d), None) => return Ok(Some((d, sc))),
                        (None, _) => (None, sc),
                        (Some(_), Some(b)) => (Some(b), self.scopes[sc].parent.unwrap_or(0)),
                    }
                }
            };
            let Some(el) = el else {
                let from = qualify(&self.scopes[scope].prefix, at.attribute("name").unwrap_or("?"));
                return Err(self.hard(at, LoadErrorKind::Dangling { from, to: format!("interface input `{name}`") }));
            };
            match el.attribute("interfacename") {
                Some(n2) => {
                    sc = next;
                    name = n2;
                    at = el;
                }
                None => return Ok(Some((el, next))),
            }
        }
    }

    /// The source of an `<input>` (or `<output>`) element: `None` when it neither has a value
    /// nor a connection.
    fn input_source(&mut self, scope: usize, inp: XNode<'a, 'i>) -> Result<Option<Source>, Fail> {
        let declared = self.value_type(inp);
        let from = qualify(&self.scopes[scope].prefix, inp.attribute("name").unwrap_or("?"));
        // The port named in messages: `node.input` for a node's input.
        let port = match inp.parent_element() {
            Some(p) if !matches!(p.tag_name().name(), "nodegraph" | "materialx") => qualify(
                &self.scopes[scope].prefix,
                &format!("{}.{}", p.attribute("name").unwrap_or("?"), inp.attribute("name").unwrap_or("?")),
            ),
            _ => from.clone(),
        };
        let connected = inp.attribute("nodename").is_some() || inp.attribute("nodegraph").is_some();
        if connected && inp.attribute("uniform") == Some("true") {
            return Err(self.hard(
                inp,
                LoadErrorKind::Structure(format!("uniform input `{port}` cannot connect to a node output")),
            ));
        }
        let src = if let Some(target) = inp.attribute("nodename") {
            let output = inp.attribute("output");
            if self.scopes[scope].nodes.contains_key(target) {
                let target: &'a str = self.scopes[scope].nodes.get_key_value(target).map(|(k, _)| *k).unwrap_or(target);
                self.node_output(scope, target, output, inp)?
            } else if scope == 0 && self.graph_scopes.contains_key(target) && output.is_some() {
                self.graph_output(target, output.unwrap_or(""), inp, &port)?
            } else {
                let to = qualify(&self.scopes[scope].prefix, target);
                return Err(self.hard(inp, LoadErrorKind::Dangling { from: port, to }));
            }
        } else if let Some(g) = inp.attribute("nodegraph") {
            let out = inp.attribute("output").unwrap_or("");
            self.graph_output(g, out, inp, &port)?
        } else if let Some(iface) = inp.attribute("interfacename") {
            match self.interface_binding(scope, iface, inp)? {
                None => return Ok(None),
                Some((el, sc)) => match self.input_source(sc, el)? {
                    Some(s) => s,
                    None => return Ok(None),
                },
            }
        } else if let Some(text) = inp.attribute("value") {
            match declared {
                Some(t) => Source::Constant(self.typed_value(inp, t, text)?),
                None => return Ok(None),
            }
        } else if let Some(gp) = inp.attribute("defaultgeomprop") {
            self.geomprop(gp, inp)?
        } else {
            return Ok(None);
        };
        let src = match (inp.attribute("channels"), declared) {
            (Some(ch), Some(t)) if !ch.is_empty() => {
                let q = format!("{from}#channels");
                self.swizzle(&q, src, ch, t, inp)?
            }
            _ => src,
        };
        if let (Some(t), Source::Node { .. }) = (declared, &src) {
            let found = self.builder.source_type(&src);
            if found != t {
                return Err(self.hard(
                    inp,
                    LoadErrorKind::Build(BuildError::TypeMismatch {
                        node: from,
                        input: inp.attribute("name").unwrap_or("?").to_string(),
                        expected: t.name().to_string(),
                        found,
                    }),
                ));
            }
        }
        Ok(Some(src))
    }

    /// The value of a geometric property (`defaultgeomprop`): the texture coordinate, or the
    /// library's geometry node for it (object and world space are the same in tessera), shared
    /// with the builder's own defaults (`#default/<category>`).
    fn geomprop(&mut self, name: &str, at: XNode<'a, 'i>) -> Result<Source, Fail> {
        let category = match name {
            "UV0" => return Ok(Source::Texcoord),
            "Pobject" | "Pworld" => "position",
            "Nobject" | "Nworld" => "normal",
            "Tobject" | "Tworld" => "tangent",
            "Bobject" | "Bworld" => "bitangent",
            _ => return Err(self.unsupported("geomprop", name, format!("geometric property `{name}`"), at)),
        };
        let node = format!("#default/{category}");
        if let Some(id) = self.builder.node_id(&node) {
            return Ok(Source::Node { node: id, channel: None });
        }
        if nodes::definition(category).is_none() {
            return Err(self.unsupported(category, &node, format!("for defaultgeomprop `{name}`"), at));
        }
        match self.builder.add_node(&node, category, ValueType::Vector3, &[], Vec::new()) {
            Ok(id) => Ok(Source::Node { node: id, channel: None }),
            Err(e) => Err(self.unsupported(category, &node, e.to_string(), at)),
        }
    }

    /// Channel `k` of `src` as a float source.
    fn pick(&mut self, src: &Source, k: usize, at: XNode<'a, 'i>) -> Result<Source, Fail> {
        Ok(match src {
            Source::Constant(v) => Source::Constant(Value::float(if v.ty.is_scalar() { v.v[0] } else { v.v[k] })),
            Source::Node { node, channel: None } => {
                if self.builder.node_type(*node).is_scalar() {
                    src.clone()
                } else {
                    Source::Node { node: *node, channel: Some(k as u8) }
                }
            }
            Source::Node { channel: Some(_), .. } => src.clone(),
            _ => {
                // Geometric data: a pass-through node to pick the channel from.
                let name = format!("#{src:?}");
                let ty = self.builder.source_type(src);
                let id = match self.builder.node_id(&name) {
                    Some(id) => id,
                    None => self
                        .builder
                        .add_node(&name, "dot", ty, &[("in", src.clone())], vec![])
                        .map_err(|e| self.hard(at, e.into()))?,
                };
                Source::Node { node: id, channel: Some(k as u8) }
            }
        })
    }

    /// `src` reordered by a `channels` string (`"rgb"`, `"xxx"`, `"x0y1"`, ...) into type `dest`:
    /// MaterialX's `swizzle` / `channels` semantics up to 1.38.
    fn swizzle(
        &mut self,
        q: &str,
        src: Source,
        channels: &str,
        dest: ValueType,
        at: XNode<'a, 'i>,
    ) -> Result<Source, Fail> {
        let src_ty = self.builder.source_type(&src);
        let n_src = src_ty.channels();
        let chars: Vec<char> = channels.chars().filter(|c| !c.is_whitespace()).collect();
        let mut parts = Vec::with_capacity(4);
        for i in 0..dest.channels() {
            let c = chars.get(i).copied().unwrap_or('x');
            let part = match c {
                '0' => Source::Constant(Value::float(0.0)),
                '1' => Source::Constant(Value::float(1.0)),
                _ => {
                    let k = match c {
                        'r' | 'x' => 0,
                        'g' | 'y' => 1,
                        'b' | 'z' => 2,
                        // `a` of a former color2 is its second channel.
                        'a' if n_src == 2 => 1,
                        'a' | 'w' => 3,
                        _ => {
                            return Err(self.hard(
                                at,
                                LoadErrorKind::Structure(format!("unknown channel `{c}` in channels `{channels}`")),
                            ))
                        }
                    };
                    if k >= n_src && n_src > 1 {
                        return Err(self.hard(
                            at,
                            LoadErrorKind::Structure(format!(
                                "channel `{c}` of `{channels}` is out of range for {src_ty}"
                            )),
                        ));
                    }
                    self.pick(&src, k, at)?
                }
            };
            parts.push(part);
        }
        if parts.len() == 1 {
            return Ok(parts.pop().unwrap_or(src));
        }
        if let Some(id) = self.builder.node_id(q) {
            return Ok(Source::Node { node: id, channel: None });
        }
        let names = ["in1", "in2", "in3", "in4"];
        let inputs: Vec<(&str, Source)> = names.iter().copied().zip(parts).collect();
        let id = self
            .builder
            .add_node(q, &format!("combine{}", inputs.len()), dest, &inputs, vec![])
            .map_err(|e| self.hard(at, e.into()))?;
        Ok(Source::Node { node: id, channel: None })
    }

    /// The source of output `out` of nodegraph `g` (the only output if `out` is empty).
    fn graph_output(&mut self, g: &str, out: &str, at: XNode<'a, 'i>, from: &str) -> Result<Source, Fail> {
        let Some(&sc) = self.graph_scopes.get(g) else {
            return Err(self.hard(at, LoadErrorKind::Dangling { from: from.to_string(), to: g.to_string() }));
        };
        let o = self.scopes[sc].outputs.iter().find(|o| out.is_empty() || o.attribute("name") == Some(out)).copied();
        let Some(o) = o else {
            return Err(self.hard(at, LoadErrorKind::Dangling { from: from.to_string(), to: format!("{g}/{out}") }));
        };
        self.output_source(sc, o)
    }

    /// How node `el`'s category is defined.
    fn resolve_def(&self, scope: usize, el: XNode<'a, 'i>) -> Result<DefKind, Fail> {
        let category = self.category(el);
        let builtin = nodes::definition(category).is_some();
        // The library's own node (filtered) wins over a document's nodegraph implementation of
        // the same category (e.g. an included standard library), where it has the type.
        let ty = self.type_name(el).unwrap_or("");
        let builtin_fits = nodes::definition(category)
            .is_some_and(|d| ty == "multioutput" || ValueType::from_name(ty).is_some_and(|t| (d.types)(t)));
        if builtin_fits {
            return Ok(DefKind::Builtin);
        }
        let with_impl = |k: usize| {
            if self.impls.contains_key(self.nodedefs[k].name) {
                DefKind::Custom(k)
            } else if builtin {
                DefKind::Builtin
            } else {
                DefKind::Unimplemented(k)
            }
        };
        let q = || qualify(&self.scopes[scope].prefix, el.attribute("name").unwrap_or("?"));
        if let Some(nd) = el.attribute("nodedef") {
            if let Some(&k) = self.nodedef_by_name.get(nd) {
                return Ok(with_impl(k));
            }
            if builtin {
                return Ok(DefKind::Builtin);
            }
            return Err(self.hard(
                el,
                LoadErrorKind::Structure(format!("node `{}` names nodedef `{nd}`, which is not defined", q())),
            ));
        }
        let cands: Vec<usize> = (0..self.nodedefs.len()).filter(|&k| self.nodedefs[k].node == category).collect();
        if cands.is_empty() {
            return Ok(if builtin { DefKind::Builtin } else { DefKind::Unknown });
        }
        let matching: Vec<usize> = cands.iter().copied().filter(|&k| self.nodedef_matches(k, el)).collect();
        let chosen = match el.attribute("version") {
            Some(v) => matching.iter().copied().find(|&k| self.nodedefs[k].version == Some(v)),
            None => matching
                .iter()
                .copied()
                .find(|&k| self.nodedefs[k].default_version)
                .or_else(|| matching.first().copied()),
        };
        match chosen {
            Some(k) => Ok(with_impl(k)),
            None if builtin => Ok(DefKind::Builtin),
            None => {
                let list: Vec<String> = cands
                    .iter()
                    .map(|&k| {
                        let d = &self.nodedefs[k];
                        let outs: Vec<String> = d.outputs.iter().map(|(n, t)| format!("{n}: {t}")).collect();
                        format!("{} ({})", d.name, outs.join(", "))
                    })
                    .collect();
                Err(self.hard(
                    el,
                    LoadErrorKind::Structure(format!(
                        "no nodedef of `{category}` matches node `{}` (type `{}`{}); candidates: {}",
                        q(),
                        self.type_name(el).unwrap_or(""),
                        el.attribute("version").map(|v| format!(", version {v}")).unwrap_or_default(),
                        list.join("; ")
                    )),
                ))
            }
        }
    }

    /// Whether nodedef `k` fits node `el`: its output type(s) and every typed input.
    fn nodedef_matches(&self, k: usize, el: XNode<'a, 'i>) -> bool {
        let d = &self.nodedefs[k];
        let ty = self.type_name(el).unwrap_or("");
        let outputs_ok =
            if ty == "multioutput" { d.outputs.len() > 1 } else { d.outputs.len() == 1 && d.outputs[0].1 == ty };
        outputs_ok
            && self.inputs_of(el).iter().all(|i| {
                let name = i.attribute("name");
                d.inputs.iter().find(|di| di.attribute("name") == name).is_some_and(|di| match self.type_name(*i) {
                    Some(t) => self.type_name(*di) == Some(t),
                    None => true,
                })
            })
    }

    /// Output `output` (or the default one) of node `name` in `scope`.
    fn node_output(
        &mut self,
        scope: usize,
        name: &'a str,
        output: Option<&'a str>,
        at: XNode<'a, 'i>,
    ) -> Result<Source, Fail> {
        let el = self.scopes[scope].nodes[name];
        if let DefKind::Custom(k) = self.resolve_def(scope, el)? {
            return self.instance_output(scope, name, el, k, output, at);
        }
        let src = self.node(scope, name)?;
        match (output, &src) {
            (Some(o), Source::Node { node, channel: None })
                if self.builder.node_category(*node).starts_with("separate") =>
            {
                let n = self.builder.node_type(*node).channels();
                match channel::output_channel(o).filter(|c| (*c as usize) < n) {
                    Some(c) => Ok(Source::Node { node: *node, channel: Some(c) }),
                    None => {
                        let from = qualify(&self.scopes[scope].prefix, at.attribute("name").unwrap_or("?"));
                        let to = format!("{}.{o}", qualify(&self.scopes[scope].prefix, name));
                        Err(self.hard(at, LoadErrorKind::Dangling { from, to }))
                    }
                }
            }
            _ => Ok(src),
        }
    }

    /// Output `output` of custom node `name` (instantiating nodedef `k`), expanding its
    /// definition once per instance.
    fn instance_output(
        &mut self,
        scope: usize,
        name: &'a str,
        el: XNode<'a, 'i>,
        k: usize,
        output: Option<&'a str>,
        at: XNode<'a, 'i>,
    ) -> Result<Source, Fail> {
        let q = qualify(&self.scopes[scope].prefix, name);
        let outputs = &self.nodedefs[k].outputs;
        let oname = match output {
            Some(o) => o,
            None => outputs.first().map(|(n, _)| *n).unwrap_or("out"),
        };
        if !outputs.iter().any(|(n, _)| *n == oname) {
            let from = qualify(&self.scopes[scope].prefix, at.attribute("name").unwrap_or("?"));
            return Err(self.hard(at, LoadErrorKind::Dangling { from, to: format!("{q}.{oname}") }));
        }
        let key = format!("{q}.{oname}");
        match self.state.get(&key) {
            Some(State::Done(s)) => return Ok(s.clone()),
            Some(State::Visiting) => return Err(self.hard(el, LoadErrorKind::Cycle(q))),
            None => {}
        }
        if let Some(r) = self.soft.get(&key) {
            return Err(Fail::Soft(r.clone()));
        }
        if self.state.get(&q) == Some(&State::Visiting) {
            return Err(self.hard(el, LoadErrorKind::Cycle(q)));
        }
        self.state.insert(q.clone(), State::Visiting);
        let r = self.instance_output_inner(scope, &q, el, k, oname);
        self.state.remove(&q);
        match r {
            Ok(s) => {
                self.state.insert(key, State::Done(s.clone()));
                Ok(s)
            }
            Err(Fail::Soft(ix)) => {
                self.soft.insert(key, ix.clone());
                Err(Fail::Soft(ix))
            }
            Err(e) => Err(e),
        }
    }

    fn instance_output_inner(
        &mut self,
        scope: usize,
        q: &str,
        el: XNode<'a, 'i>,
        k: usize,
        oname: &str,
    ) -> Result<Source, Fail> {
        let inst = match self.instances.get(q) {
            Some(&s) => s,
            None => {
                // A definition that instantiates itself never ends.
                let mut p = Some(scope);
                while let Some(s) = p {
                    if let Iface::Def { nodedef, .. } = self.scopes[s].iface {
                        if nodedef == k {
                            return Err(self.hard(
                                el,
                                LoadErrorKind::Structure(format!(
                                    "node `{q}` instantiates `{}` inside its own definition (recursive nodedef)",
                                    self.nodedefs[k].name
                                )),
                            ));
                        }
                    }
                    p = self.scopes[s].parent;
                }
                let gname = self.impls[self.nodedefs[k].name];
                let Some(&g) = self.graph_elems.get(gname) else {
                    return Err(self.hard(
                        el,
                        LoadErrorKind::Structure(format!(
                            "nodedef `{}` is implemented by nodegraph `{gname}`, which is not defined",
                            self.nodedefs[k].name
                        )),
                    ));
                };
                let (nodes, outputs, own, _) = self.scan_graph(g)?;
                let id = self.scopes.len();
                self.scopes.push(Scope {
                    prefix: q.to_string(),
                    nodes,
                    outputs,
                    iface: Iface::Def { nodedef: k, own, instance: Some(el) },
                    parent: Some(scope),
                });
                self.instances.insert(q.to_string(), id);
                id
            }
        };
        let o = self.scopes[inst].outputs.iter().find(|o| o.attribute("name") == Some(oname)).copied();
        let Some(o) = o else {
            return Err(self.hard(
                el,
                LoadErrorKind::Structure(format!(
                    "the nodegraph implementing `{}` has no output `{oname}`",
                    self.nodedefs[k].name
                )),
            ));
        };
        self.output_source(inst, o)
    }

    /// Creates (once) the library node called `name` in `scope`, and everything upstream of it.
    fn node(&mut self, scope: usize, name: &'a str) -> Result<Source, Fail> {
        let q = qualify(&self.scopes[scope].prefix, name);
        let el = self.scopes[scope].nodes[name];
        match self.state.get(&q) {
            Some(State::Done(s)) => return Ok(s.clone()),
            Some(State::Visiting) => return Err(self.hard(el, LoadErrorKind::Cycle(q))),
            None => {}
        }
        if let Some(r) = self.soft.get(&q) {
            return Err(Fail::Soft(r.clone()));
        }
        self.state.insert(q.clone(), State::Visiting);
        let r = self.make_node(scope, &q, el);
        self.state.remove(&q);
        match r {
            Ok(s) => {
                self.state.insert(q, State::Done(s.clone()));
                Ok(s)
            }
            Err(Fail::Soft(ix)) => {
                self.soft.insert(q, ix.clone());
                Err(Fail::Soft(ix))
            }
            Err(e) => Err(e),
        }
    }

    fn make_node(&mut self, scope: usize, q: &str, el: XNode<'a, 'i>) -> Result<Source, Fail> {
        let category = self.category(el);
        let tyname = self.type_name(el).unwrap_or("");
        if category == "swizzle" && self.version(el) < (1, 39) {
            return self.legacy_swizzle(scope, q, el);
        }
        if let Some(src) = self.matrix_reader(scope, q, el, category)? {
            return Ok(src);
        }
        let kind = self.resolve_def(scope, el)?;
        let def = match (kind, nodes::definition(category)) {
            (DefKind::Builtin, Some(def)) => def,
            (kind, _) => {
                // Still visit the inputs, to report every unsupported node upstream too.
                let mut soft = Vec::new();
                for inp in self.inputs_of(el) {
                    if let Err(f) = self.input_source(scope, inp) {
                        merge_soft(&mut soft, f)?;
                    }
                }
                let detail = match kind {
                    DefKind::Unimplemented(k) => {
                        format!("nodedef `{}` has no nodegraph implementation", self.nodedefs[k].name)
                    }
                    _ => String::new(),
                };
                let Fail::Soft(me) = self.unsupported(category, q, detail, el) else { unreachable!() };
                soft.extend(me);
                soft.sort_unstable();
                soft.dedup();
                return Err(Fail::Soft(soft));
            }
        };
        let mut inputs: Vec<(&'static str, Source)> = Vec::new();
        let mut params: Vec<Param> = Vec::new();
        let mut in_type = None;
        let mut soft: Vec<usize> = Vec::new();
        let mut conversion = None;
        for inp in self.inputs_of(el) {
            let iname = self.input_name(el, category, inp);
            if let Some(n) = self.type_name(inp).and_then(Matrix::size_of_type) {
                match self.matrix_input(scope, inp, n, 0) {
                    Ok(Some(value)) => params.push(Param::Matrix { name: iname.to_string(), value }),
                    Ok(None) => {}
                    Err(f) => merge_soft(&mut soft, f)?,
                }
                continue;
            }
            if let Some(p) = def.params.iter().find(|p| **p == iname) {
                // A string input may take its value from an interface.
                let src = match inp.attribute("interfacename") {
                    Some(i) => self.interface_binding(scope, i, inp)?.map(|(e, _)| e).unwrap_or(inp),
                    None => inp,
                };
                let value = src.attribute("value").unwrap_or("").to_string();
                if inp.attribute("type") == Some("filename") || src.attribute("type") == Some("filename") {
                    let path = self.resolve_file(src, &value)?;
                    // Only colour images are colour managed (as in MaterialX).
                    let mut colorspace = String::new();
                    if matches!(ValueType::from_name(tyname), Some(ValueType::Color3 | ValueType::Color4)) {
                        // The file input's own colour space, the interface input's, else inherited.
                        if let Some(c) = self.conversion(&[inp, src], inp)? {
                            if c.transfer == Transfer::Srgb {
                                colorspace = "srgb_texture".to_string();
                            }
                            conversion = Some(c);
                        }
                    }
                    params.push(Param::File { name: p.to_string(), path, colorspace });
                } else {
                    params.push(Param::Str { name: p.to_string(), value });
                }
                continue;
            }
            // Before 1.39 a normal map's frame inputs were literals; 1.39's upgrade drops the
            // unbound ones in favour of the geometric frame.
            if category == "normalmap"
                && self.version(el) < (1, 39)
                && matches!(iname, "normal" | "tangent" | "bitangent")
                && ["nodename", "nodegraph", "interfacename"].iter().all(|a| inp.attribute(*a).is_none())
            {
                continue;
            }
            let Some(spec) = def.inputs.iter().find(|s| s.name == iname) else {
                let f = self.unsupported(category, q, format!("input `{iname}`"), inp);
                merge_soft(&mut soft, f)?;
                continue;
            };
            match self.input_source(scope, inp) {
                Ok(Some(src)) => {
                    if spec.name == "in" {
                        in_type = Some(self.builder.source_type(&src));
                    }
                    inputs.push((spec.name, src));
                }
                Ok(None) => {
                    if spec.name == "in" {
                        in_type = self.value_type(inp);
                    }
                }
                Err(f) => merge_soft(&mut soft, f)?,
            }
        }
        let ty = if tyname == "multioutput" {
            in_type.or_else(|| {
                self.inputs_of(el)
                    .into_iter()
                    .find(|c| c.attribute("name") == Some("in"))
                    .and_then(|c| self.value_type(c))
            })
        } else {
            ValueType::from_name(tyname)
        };
        let Some(ty) = ty else {
            let f = self.unsupported(category, q, format!("type `{tyname}`"), el);
            merge_soft(&mut soft, f)?;
            return Err(Fail::Soft(soft));
        };
        if !soft.is_empty() {
            return Err(Fail::Soft(soft));
        }
        // Before 1.39 a switch had five inputs, the fifth taken from `which` ≥ 4 on; 1.39 has
        // ten. Feeding the fifth's source to the new five keeps the old choice.
        if category == "switch" && self.version(el) < (1, 39) {
            let fifth = inputs.iter().find(|(n, _)| *n == "in5").map(|(_, s)| s.clone());
            let fifth = fifth.unwrap_or_else(|| Source::Constant(Value::splat(ty, 0.0)));
            for name in ["in6", "in7", "in8", "in9", "in10"] {
                inputs.retain(|(n, _)| *n != name);
                inputs.push((name, fifth.clone()));
            }
        }
        let id = match self.builder.add_node(q, category, ty, &inputs, params) {
            Ok(id) => id,
            Err(BuildError::UnsupportedType { .. }) => {
                return Err(self.unsupported(category, q, format!("type `{tyname}`"), el));
            }
            Err(e) => return Err(self.hard(el, e.into())),
        };
        let src = Source::Node { node: id, channel: None };
        match conversion {
            Some(c) => self.convert_colors(q, src, ty, &c, el),
            None => Ok(src),
        }
    }

    /// `extract` of a matrix row and `determinant`: nodes that read a (uniform) matrix and give
    /// a constant. `None` for every other node.
    fn matrix_reader(
        &mut self,
        scope: usize,
        q: &str,
        el: XNode<'a, 'i>,
        category: &str,
    ) -> Result<Option<Source>, Fail> {
        if !matches!(category, "extract" | "determinant") {
            return Ok(None);
        }
        let inputs = self.inputs_of(el);
        let Some(inp) = inputs.iter().copied().find(|c| c.attribute("name") == Some("in")) else {
            return Ok(None);
        };
        let Some(n) = self.type_name(inp).and_then(Matrix::size_of_type) else {
            return Ok(None);
        };
        let m = self.matrix_input(scope, inp, n, 0)?.unwrap_or_else(|| Matrix::identity(n));
        if category == "determinant" {
            return Ok(Some(Source::Constant(Value::float(m.determinant() as f32))));
        }
        let index = match inputs.iter().copied().find(|c| c.attribute("name") == Some("index")) {
            Some(i) => self.uniform_value(scope, i, q)?.map_or(0, |v| v.v[0].round() as i64),
            None => 0,
        };
        let ty = if n == 3 { ValueType::Vector3 } else { ValueType::Vector4 };
        if self.value_type(el) != Some(ty) {
            let found = self.type_name(el).unwrap_or("?");
            return Err(self.hard(
                el,
                LoadErrorKind::Structure(format!(
                    "`{q}`: extract from a matrix{n}{n} gives a {ty} (one row), not a {found}"
                )),
            ));
        }
        let Some(row) = usize::try_from(index).ok().and_then(|i| m.row(i)) else {
            return Err(self.hard(
                el,
                LoadErrorKind::Structure(format!(
                    "`{q}`: index {index} is not a row of a matrix{n}{n} (0 to {})",
                    n - 1
                )),
            ));
        };
        let row: Vec<f32> = row.iter().map(|x| *x as f32).collect();
        Ok(Some(Source::Constant(Value::new(ty, &row))))
    }

    /// The value of a non-matrix input that a matrix computation needs at load: `None` when
    /// omitted; unsupported (naming the input) when it varies over the surface.
    fn uniform_value(&mut self, scope: usize, inp: XNode<'a, 'i>, q: &str) -> Result<Option<Value>, Fail> {
        match self.input_source(scope, inp)? {
            None => Ok(None),
            Some(Source::Constant(v)) => Ok(Some(v)),
            Some(_) => {
                let name = inp.attribute("name").unwrap_or("?");
                let category = inp.parent_element().map_or("?", |p| self.category(p));
                Err(self.unsupported(
                    category,
                    q,
                    format!("input `{name}` varies over the surface, but matrices are uniforms in tessera"),
                    inp,
                ))
            }
        }
    }

    /// The matrix an `<input>` of type matrix33/44 carries, folded at load: its value, or the
    /// matrix node (or interface input) it connects to. `None` when the input is neither set nor
    /// connected (its node's default applies).
    fn matrix_input(
        &mut self,
        scope: usize,
        inp: XNode<'a, 'i>,
        n: usize,
        depth: usize,
    ) -> Result<Option<Matrix>, Fail> {
        let port = inp.attribute("name").unwrap_or("?");
        if depth > 256 {
            let q = qualify(&self.scopes[scope].prefix, port);
            return Err(self.hard(inp, LoadErrorKind::Cycle(q)));
        }
        if let Some(target) = inp.attribute("nodename") {
            let Some(el) = self.scopes[scope].nodes.get(target).copied() else {
                let from = qualify(&self.scopes[scope].prefix, port);
                let to = qualify(&self.scopes[scope].prefix, target);
                return Err(self.hard(inp, LoadErrorKind::Dangling { from, to }));
            };
            return self.fold_matrix(scope, el, n, depth + 1).map(Some);
        }
        if let Some(iface) = inp.attribute("interfacename") {
            return match self.interface_binding(scope, iface, inp)? {
                None => Ok(None),
                Some((el, sc)) => self.matrix_input(sc, el, n, depth + 1),
            };
        }
        if inp.attribute("nodegraph").is_some() {
            let q = qualify(&self.scopes[scope].prefix, port);
            return Err(self.unsupported("nodegraph", &q, "a matrix-typed node graph output".into(), inp));
        }
        match inp.attribute("value") {
            None => Ok(None),
            Some(text) => match Matrix::parse(n, text) {
                Some(m) => Ok(Some(m)),
                None => Err(self.hard(
                    inp,
                    LoadErrorKind::MalformedValue {
                        ty: format!("matrix{n}{n} (n² numbers, row by row)"),
                        text: text.into(),
                    },
                )),
            },
        }
    }

    /// Folds a matrix-valued node to its value.
    fn fold_matrix(&mut self, scope: usize, el: XNode<'a, 'i>, n: usize, depth: usize) -> Result<Matrix, Fail> {
        let category = self.category(el);
        let q = qualify(&self.scopes[scope].prefix, el.attribute("name").unwrap_or("?"));
        let inputs = self.inputs_of(el);
        let find = |name: &str| inputs.iter().copied().find(|c| c.attribute("name") == Some(name));
        let ident = Matrix::identity(n);
        // A matrix operand, or a float broadcast to every entry (the `FA` variants).
        let operand = |me: &mut Self, name: &str, default: Matrix| -> Result<Matrix, Fail> {
            let Some(inp) = find(name) else { return Ok(default) };
            if me.type_name(inp).and_then(Matrix::size_of_type).is_some() {
                return Ok(me.matrix_input(scope, inp, n, depth)?.unwrap_or(default));
            }
            Ok(me.uniform_value(scope, inp, &q)?.map_or(default, |v| Matrix::splat(n, v.v[0] as f64)))
        };
        Ok(match category {
            "constant" => operand(self, "value", ident)?,
            "dot" => operand(self, "in", ident)?,
            "transpose" => operand(self, "in", ident)?.transpose(),
            "invertmatrix" => {
                let m = operand(self, "in", ident)?;
                m.inverse().ok_or_else(|| {
                    self.hard(
                        el,
                        LoadErrorKind::Structure(format!(
                            "`{q}`: cannot invert a singular matrix (determinant {:e})",
                            m.determinant()
                        )),
                    )
                })?
            }
            "add" | "subtract" | "multiply" | "divide" => {
                let a = operand(self, "in1", Matrix::splat(n, 0.0))?;
                let b_is_matrix = find("in2").and_then(|i| self.type_name(i)).and_then(Matrix::size_of_type).is_some();
                let b = operand(
                    self,
                    "in2",
                    if category == "add" || category == "subtract" { Matrix::splat(n, 0.0) } else { ident },
                )?;
                match category {
                    "add" => a.zip(&b, |x, y| x + y),
                    "subtract" => a.zip(&b, |x, y| x - y),
                    "multiply" if b_is_matrix => a.mul(&b),
                    "multiply" => a.zip(&b, |x, y| x * y),
                    _ if b_is_matrix => match b.inverse() {
                        Some(inv) => a.mul(&inv),
                        None => {
                            return Err(self
                                .hard(el, LoadErrorKind::Structure(format!("`{q}`: division by a singular matrix"))))
                        }
                    },
                    _ => a.zip(&b, |x, y| x / y),
                }
            }
            "creatematrix" => {
                let mut m = Matrix::identity(n);
                for r in 0..n {
                    let name = ["in1", "in2", "in3", "in4"][r];
                    let Some(inp) = find(name) else { continue };
                    if let Some(v) = self.uniform_value(scope, inp, &q)? {
                        let k = v.ty.channels();
                        for c in 0..k.min(n) {
                            m.m[r][c] = v.v[c] as f64;
                        }
                        // vector3 rows of a matrix44: (x, y, z, 0), the last row (x, y, z, 1).
                        if n == 4 && k == 3 {
                            m.m[r][3] = if r == 3 { 1.0 } else { 0.0 };
                        }
                    }
                }
                m
            }
            "ifgreater" | "ifgreatereq" | "ifequal" => {
                let v1 = find("value1").map(|i| self.uniform_value(scope, i, &q)).transpose()?.flatten();
                let v2 = find("value2").map(|i| self.uniform_value(scope, i, &q)).transpose()?.flatten();
                let (a, b) = (v1.map_or(1.0, |v| v.v[0]), v2.map_or(0.0, |v| v.v[0]));
                let yes = match category {
                    "ifgreater" => a > b,
                    "ifgreatereq" => a >= b,
                    _ => a == b,
                };
                operand(self, if yes { "in1" } else { "in2" }, Matrix::splat(n, 0.0))?
            }
            _ => {
                return Err(self.unsupported(category, &q, format!("matrix{n}{n}-valued `{category}`"), el));
            }
        })
    }

    /// A ≤ 1.38 `swizzle` node.
    fn legacy_swizzle(&mut self, scope: usize, q: &str, el: XNode<'a, 'i>) -> Result<Source, Fail> {
        let Some(dest) = self.value_type(el) else {
            let t = self.type_name(el).unwrap_or("").to_string();
            return Err(self.unsupported("swizzle", q, format!("type `{t}`"), el));
        };
        let mut src = None;
        let mut channels = String::new();
        for inp in self.inputs_of(el) {
            match inp.attribute("name") {
                Some("in") => {
                    src = self.input_source(scope, inp)?;
                    if src.is_none() {
                        let t = self.value_type(inp).unwrap_or(ValueType::Float);
                        src = Some(Source::Constant(Value::splat(t, 0.0)));
                    }
                }
                Some("channels") => channels = inp.attribute("value").unwrap_or("").to_string(),
                _ => {}
            }
        }
        let src = src.unwrap_or(Source::Constant(Value::float(0.0)));
        self.swizzle(q, src, &channels, dest, el)
    }

    /// Appends the nodes converting a colour image's filtered value to the working space.
    fn convert_colors(
        &mut self,
        q: &str,
        src: Source,
        ty: ValueType,
        c: &Conversion,
        at: XNode<'a, 'i>,
    ) -> Result<Source, Fail> {
        let add = |imp: &mut Self, suffix: &str, cat: &str, t: ValueType, ins: &[(&str, Source)]| {
            imp.builder
                .add_node(&format!("{q}#colorspace_{suffix}"), cat, t, ins, vec![])
                .map(|id| Source::Node { node: id, channel: None })
                .map_err(|e| imp.hard(at, e.into()))
        };
        let mut s = src.clone();
        if let Transfer::Gamma(g) = c.transfer {
            let m = add(self, "max", "max", ty, &[("in1", s), ("in2", Source::Constant(Value::float(0.0)))])?;
            s = add(self, "gamma", "power", ty, &[("in1", m), ("in2", Source::Constant(Value::float(g as f32)))])?;
        }
        let rgb: Vec<Source> = match c.matrix {
            Some(m) => {
                let mut out = Vec::new();
                for (k, suffix) in ["r", "g", "b"].iter().enumerate() {
                    let row = m.row(k);
                    let mut v = Value::splat(ty, 0.0);
                    v.v[..3].copy_from_slice(&[row.x as f32, row.y as f32, row.z as f32]);
                    out.push(add(
                        self,
                        suffix,
                        "dotproduct",
                        ValueType::Float,
                        &[("in1", s.clone()), ("in2", Source::Constant(v))],
                    )?);
                }
                out
            }
            None if ty == ValueType::Color4 => {
                (0..3).map(|k| self.pick(&s, k, at)).collect::<Result<Vec<_>, Fail>>()?
            }
            None => return Ok(s),
        };
        let mut ins: Vec<(&str, Source)> = ["in1", "in2", "in3"].into_iter().zip(rgb).collect();
        if ty == ValueType::Color4 {
            ins.push(("in4", self.pick(&src, 3, at)?));
        }
        let cat = if ty == ValueType::Color4 { "combine4" } else { "combine3" };
        add(self, "out", cat, ty, &ins)
    }

    /// Finds a referenced file: `fileprefix` (the nearest on `at` or its ancestors) prepended,
    /// looked up beside the file naming it, beside the document, then in the search paths.
    fn resolve_file(&self, at: XNode<'a, 'i>, value: &str) -> Result<PathBuf, Fail> {
        let prefix = at.ancestors().find_map(|a| a.attribute("fileprefix")).unwrap_or("");
        let name = format!("{prefix}{value}");
        let own = self.paths[self.doc_index(at)].parent().unwrap_or(Path::new(".")).to_path_buf();
        let main = self.paths[0].parent().unwrap_or(Path::new(".")).to_path_buf();
        std::iter::once(own.join(&name))
            .chain(std::iter::once(main.join(&name)))
            .chain(self.opts.search_paths.iter().map(|s| s.join(&name)))
            .find(|p| p.is_file())
            .ok_or_else(|| self.hard(at, LoadErrorKind::MissingFile(PathBuf::from(name))))
    }
}

/// Parses a MaterialX `value` string of type `ty`.
pub fn parse_value(ty: ValueType, text: &str) -> Option<Value> {
    let t = text.trim();
    match ty {
        ValueType::Boolean => match t {
            "true" => Some(Value::splat(ty, 1.0)),
            "false" => Some(Value::splat(ty, 0.0)),
            _ => None,
        },
        ValueType::Integer => t.parse::<i32>().ok().map(|i| Value::splat(ty, i as f32)),
        _ => {
            let parts: Vec<&str> = t.split(',').map(|s| s.trim()).collect();
            if parts.len() != ty.channels() {
                return None;
            }
            let mut v = [0.0f32; 4];
            for (x, p) in v.iter_mut().zip(&parts) {
                *x = p.parse::<f32>().ok().filter(|x| x.is_finite())?;
            }
            Some(Value { ty, v })
        }
    }
}
