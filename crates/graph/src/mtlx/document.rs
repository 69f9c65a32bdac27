//! The loaded [`Document`]: its graph, its materials' bindings and its shaders' inputs.

use super::files::{gather, parse_xml, read_text};
use super::importer::Importer;
use super::shading::{
    f, gltf_alpha_cutoff, gltf_alpha_mode, model_of, InputDefault, Mapped, MaterialBinding, MaterialSource,
    SUPPORTED_INPUTS,
};
use super::LoadOptions;
use crate::error::{LoadError, LoadErrorKind, Location, Unsupported};
use crate::graph::{Graph, OutputId};
use crate::nodes;
use crate::value::{Value, ValueType};
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// Derived values a shader's binding needs, built into the graph at load.
#[derive(Clone, Debug, Default)]
pub(super) struct ShaderExtras {
    /// `gltf_pbr` in MASK mode with a graph-driven `alpha`: the `ifgreatereq` output.
    pub(super) alpha_mask: Option<Result<OutputId, String>>,
}

#[derive(Clone, Debug)]
pub(super) struct ShaderDef {
    pub(super) name: String,
    pub(super) category: String,
    pub(super) inputs: Vec<(String, ShaderInput)>,
    pub(super) extras: ShaderExtras,
    pub(super) location: Location,
}

#[derive(Clone, Debug)]
pub(super) enum ShaderInput {
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
    /// The node graphs that implement nodedefs: their own nodes are built once at the
    /// nodedef's defaults only to check them, so their warnings are not the document's.
    definition_graphs: Vec<String>,
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
        let definition_graphs = imp.definition_graphs();
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
            definition_graphs,
        })
    }

    /// Load warnings about the document's nodes (a node that gives its default, a property
    /// tessera does not carry): the graph's, less those of the nodes of node graphs that
    /// implement nodedefs, which are built at the nodedef's defaults only to be checked (an
    /// included library's image nodes with empty files would otherwise warn by the dozen).
    /// Instances of those nodedefs, named after the node that uses them, still warn.
    pub fn warnings(&self) -> Vec<String> {
        let g = &self.graph;
        g.node_ids()
            .filter(|id| {
                let name = g.node_name(*id);
                !self
                    .definition_graphs
                    .iter()
                    .any(|d| name.strip_prefix(d.as_str()).is_some_and(|r| r.starts_with('/')))
            })
            .filter_map(|id| g.node_warning(id))
            .collect()
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
    ///
    /// [`SHADING_MODELS`]: super::SHADING_MODELS
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
    ///
    /// [`SHADING_MODELS`]: super::SHADING_MODELS
    pub fn material(&self, name: &str) -> Option<MaterialBinding> {
        let shader_name = self.materials.iter().find(|(m, _)| m == name).map(|(_, s)| s.as_str()).unwrap_or(name);
        let (sh, model) = self
            .shaders
            .iter()
            .filter(|s| s.name == shader_name)
            .find_map(|s| model_of(&s.category).map(|m| (s, m)))?;
        let lookup = |n: &str| sh.inputs.iter().find(|(k, _)| k == n).map(|(_, s)| s);
        let mut warnings: Vec<String> = Vec::new();
        let mut unavailable: Vec<String> = Vec::new();
        let read = |n: &str, def: InputDefault, unavailable: &mut Vec<String>| match lookup(n) {
            Some(ShaderInput::Value(Some(v))) => MaterialSource::Constant(*v),
            Some(ShaderInput::Output(Ok(o))) => MaterialSource::Output(*o),
            Some(ShaderInput::Output(Err(reason))) => {
                unavailable.push(format!("{}: input `{n}` is not available: {reason}", sh.location));
                default_source(def)
            }
            _ => default_source(def),
        };
        let mut inputs = Vec::new();
        for (&(cname, cdef), mapped) in SUPPORTED_INPUTS.iter().zip(model.map) {
            let src = match *mapped {
                Mapped::Same => read(cname, cdef, &mut unavailable),
                Mapped::Input(n, def) => read(n, def, &mut unavailable),
                Mapped::Fixed(ty, v) => MaterialSource::Constant(Value::new(ty, &[v])),
                Mapped::GltfOpacity => self.gltf_opacity(sh, &mut warnings, &mut unavailable, &read),
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
        unavailable.retain(|w| seen.insert(w.clone()));
        Some(MaterialBinding {
            name: name.to_string(),
            shader: sh.name.clone(),
            model: model.category,
            inputs,
            warnings,
            unavailable,
        })
    }

    /// A `gltf_pbr`'s opacity, as its definition's graph computes it from `alpha`,
    /// `alpha_mode` and `alpha_cutoff` (see [`GLTF_PBR`]).
    ///
    /// [`GLTF_PBR`]: super::shading::GLTF_PBR
    fn gltf_opacity(
        &self,
        sh: &ShaderDef,
        warnings: &mut Vec<String>,
        unavailable: &mut Vec<String>,
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
                            unavailable.push(format!("{}: input `alpha` is not available: {reason}", sh.location));
                            opaque
                        }
                        None => opaque,
                    };
                }
                let cutoff = gltf_alpha_cutoff(lookup("alpha_cutoff")).unwrap_or_else(|w| {
                    warnings.push(format!("{}: {w}", sh.location));
                    0.5
                });
                let alpha = match read("alpha", f(1.0), unavailable) {
                    MaterialSource::Constant(v) => v.v[0],
                    _ => 1.0,
                };
                MaterialSource::Constant(Value::float(if alpha >= cutoff { 1.0 } else { 0.0 }))
            }
            _ => read("alpha", f(1.0), unavailable),
        }
    }

    /// Input `input` of a shader of any category, with the type it delivers: `material` names a
    /// material (then `shader`, if given, must be its shader) or a shader. `None` if there is no
    /// such shader; `Err` with the reason if the input cannot be evaluated. An input left unset
    /// takes its model's default for the [`SHADING_MODELS`] when the binding knows it (the
    /// inputs it reads; [`MaterialSource::Geometric`] for normals) and is an error otherwise
    /// (other shaders' defaults are not known here).
    ///
    /// [`SHADING_MODELS`]: super::SHADING_MODELS
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
