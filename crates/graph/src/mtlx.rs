//! MaterialX 1.39 import: a document's node graphs flattened into one [`Graph`], and its
//! `standard_surface` materials as [`MaterialBinding`]s.
//!
//! Names: a node `n` inside `<nodegraph name="g">` is `g/n`; a top-level node is `n`. Outputs
//! likewise (`g/out`). Connections by `nodename` (+ `output` for multi-output nodes),
//! `nodegraph` + `output`, and `interfacename` are resolved to sources; omitted inputs take the
//! node definition's defaults. Nodegraphs that implement a `nodedef` are definitions, not
//! content, and are skipped. Errors carry the file and the line of the offending element.

use crate::error::{BuildError, LoadError, LoadErrorKind, Location};
use crate::graph::{Graph, GraphBuilder, NodeId, OutputId, Source};
use crate::nodes::{self, channel, Param};
use crate::value::{Value, ValueType};
use roxmltree::Node as XNode;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// How to load a document.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Extra folders to search for referenced files.
    pub search_paths: Vec<PathBuf>,
    /// Instead of failing on an unsupported node, leave out every output that depends on it
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

/// A `standard_surface`'s supported inputs, each a constant or a graph output.
#[derive(Clone, Debug)]
pub struct MaterialBinding {
    /// The material (or shader) name asked for.
    pub name: String,
    /// The `standard_surface` node's name.
    pub shader: String,
    /// `(input name, source)` for every supported input, in [`SUPPORTED_INPUTS`] order.
    pub inputs: Vec<(&'static str, MaterialSource)>,
    /// Inputs set to non-default values that the binding does not carry.
    pub warnings: Vec<String>,
}

impl MaterialBinding {
    /// The source of input `name`.
    pub fn get(&self, name: &str) -> Option<&MaterialSource> {
        self.inputs.iter().find(|(n, _)| *n == name).map(|(_, s)| s)
    }
}

/// A `standard_surface` input's default: its type and value, or `None` for geometric data.
pub type InputDefault = Option<(ValueType, [f32; 3])>;

/// `standard_surface` inputs a binding carries, with their defaults.
pub const SUPPORTED_INPUTS: &[(&str, InputDefault)] = &[
    ("base", Some((ValueType::Float, [1.0, 0.0, 0.0]))),
    ("base_color", Some((ValueType::Color3, [0.8, 0.8, 0.8]))),
    ("metalness", Some((ValueType::Float, [0.0, 0.0, 0.0]))),
    ("specular", Some((ValueType::Float, [1.0, 0.0, 0.0]))),
    ("specular_color", Some((ValueType::Color3, [1.0, 1.0, 1.0]))),
    ("specular_roughness", Some((ValueType::Float, [0.2, 0.0, 0.0]))),
    ("specular_IOR", Some((ValueType::Float, [1.5, 0.0, 0.0]))),
    ("transmission", Some((ValueType::Float, [0.0, 0.0, 0.0]))),
    ("opacity", Some((ValueType::Color3, [1.0, 1.0, 1.0]))),
    ("normal", None),
];

/// Defaults of the `standard_surface` inputs a binding does not carry: setting one to anything
/// else is reported as a warning.
const UNSUPPORTED_DEFAULTS: &[(&str, f32)] = &[
    ("diffuse_roughness", 0.0),
    ("specular_anisotropy", 0.0),
    ("specular_rotation", 0.0),
    ("transmission_depth", 0.0),
    ("transmission_scatter_anisotropy", 0.0),
    ("transmission_dispersion", 0.0),
    ("transmission_extra_roughness", 0.0),
    ("subsurface", 0.0),
    ("sheen", 0.0),
    ("coat", 0.0),
    ("coat_affect_color", 0.0),
    ("coat_affect_roughness", 0.0),
    ("thin_film_thickness", 0.0),
    ("emission", 0.0),
    ("transmission_color", 1.0),
    ("subsurface_color", 1.0),
    ("subsurface_radius", 1.0),
    ("subsurface_scale", 1.0),
    ("subsurface_anisotropy", 0.0),
    ("sheen_color", 1.0),
    ("sheen_roughness", 0.3),
    ("coat_color", 1.0),
    ("coat_roughness", 0.1),
    ("coat_anisotropy", 0.0),
    ("coat_rotation", 0.0),
    ("coat_IOR", 1.5),
    ("thin_film_IOR", 1.5),
    ("emission_color", 1.0),
    ("thin_walled", 0.0),
];

#[derive(Clone, Debug)]
struct ShaderDef {
    name: String,
    inputs: Vec<(String, ShaderInput)>,
    location: Location,
}

#[derive(Clone, Debug)]
enum ShaderInput {
    Value(Option<Value>),
    Output(Result<OutputId, String>),
}

/// A loaded MaterialX document.
#[derive(Debug)]
pub struct Document {
    path: PathBuf,
    graph: Graph,
    shaders: Vec<ShaderDef>,
    /// material name → shader name
    materials: Vec<(String, String)>,
    skipped: Vec<(String, String)>,
}

impl Document {
    /// Loads a `.mtlx` file (strict: any unsupported node is an error).
    pub fn load(path: impl AsRef<Path>) -> Result<Document, LoadError> {
        Document::load_with(path, &LoadOptions::default())
    }

    /// Loads a `.mtlx` file with options.
    pub fn load_with(path: impl AsRef<Path>, opts: &LoadOptions) -> Result<Document, LoadError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| LoadError {
            location: Location { file: path.to_path_buf(), line: 0, column: 0 },
            kind: if e.kind() == std::io::ErrorKind::NotFound {
                LoadErrorKind::MissingFile(path.to_path_buf())
            } else {
                LoadErrorKind::Io(e.to_string())
            },
        })?;
        Document::parse(&text, path, opts)
    }

    /// Parses document text; `path` names it in errors and anchors relative file names.
    pub fn parse(text: &str, path: &Path, opts: &LoadOptions) -> Result<Document, LoadError> {
        let xml = roxmltree::Document::parse(text).map_err(|e| {
            let p = e.pos();
            LoadError {
                location: Location { file: path.to_path_buf(), line: p.row, column: p.col },
                kind: LoadErrorKind::Xml(e.to_string()),
            }
        })?;
        let mut imp = Importer::new(&xml, path, opts);
        imp.collect()?;
        imp.build_all()?;
        let Importer { builder, shaders, materials, skipped, .. } = imp;
        Ok(Document { path: path.to_path_buf(), graph: builder.build(), shaders, materials, skipped })
    }

    /// The file this was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
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

    /// Names of the `surfacematerial`s, then of `standard_surface` shaders.
    pub fn material_names(&self) -> Vec<&str> {
        self.materials.iter().map(|(m, _)| m.as_str()).chain(self.shaders.iter().map(|s| s.name.as_str())).collect()
    }

    /// The binding of material (or shader) `name`.
    pub fn material(&self, name: &str) -> Option<MaterialBinding> {
        let shader_name = self.materials.iter().find(|(m, _)| m == name).map(|(_, s)| s.as_str()).unwrap_or(name);
        let sh = self.shaders.iter().find(|s| s.name == shader_name)?;
        let mut inputs = Vec::new();
        let mut warnings = Vec::new();
        for &(iname, def) in SUPPORTED_INPUTS {
            let src = match sh.inputs.iter().find(|(n, _)| n == iname).map(|(_, s)| s) {
                Some(ShaderInput::Value(Some(v))) => MaterialSource::Constant(*v),
                Some(ShaderInput::Output(Ok(o))) => MaterialSource::Output(*o),
                Some(ShaderInput::Output(Err(reason))) => {
                    warnings.push(format!("{}: input `{iname}` is not available: {reason}", sh.location));
                    default_source(def)
                }
                _ => default_source(def),
            };
            inputs.push((iname, src));
        }
        for (iname, si) in &sh.inputs {
            if SUPPORTED_INPUTS.iter().any(|(n, _)| n == iname) {
                continue;
            }
            let default = UNSUPPORTED_DEFAULTS.iter().find(|(n, _)| n == iname).map(|(_, d)| *d);
            let differs = match si {
                ShaderInput::Output(_) => true,
                ShaderInput::Value(Some(v)) => {
                    default.is_none_or(|d| v.channels().iter().any(|c| (*c - d).abs() > 1e-6))
                }
                ShaderInput::Value(None) => false,
            };
            if differs {
                warnings
                    .push(format!("{}: standard_surface input `{iname}` is not supported and is ignored", sh.location));
            }
        }
        Some(MaterialBinding { name: name.to_string(), shader: sh.name.clone(), inputs, warnings })
    }
}

fn default_source(def: InputDefault) -> MaterialSource {
    match def {
        Some((ty, v)) => MaterialSource::Constant(Value::new(ty, &v[..ty.channels()])),
        None => MaterialSource::Geometric,
    }
}

const SHADER_TYPES: &[&str] =
    &["surfaceshader", "material", "displacementshader", "volumeshader", "lightshader", "BSDF", "EDF", "VDF"];

#[derive(Clone, Copy, PartialEq, Debug)]
enum State {
    Visiting,
    Done(NodeId),
}

/// A failure: hard (always an error) or soft (an unsupported node, in lenient mode).
enum Fail {
    Hard(LoadError),
    Soft(String),
}

impl From<LoadError> for Fail {
    fn from(e: LoadError) -> Fail {
        Fail::Hard(e)
    }
}

struct Scope<'a, 'i> {
    nodes: HashMap<&'a str, XNode<'a, 'i>>,
    interface: HashMap<&'a str, XNode<'a, 'i>>,
    outputs: Vec<XNode<'a, 'i>>,
}

struct Importer<'a, 'i> {
    xml: &'a roxmltree::Document<'i>,
    path: PathBuf,
    opts: LoadOptions,
    scopes: HashMap<&'a str, Scope<'a, 'i>>,
    scope_order: Vec<&'a str>,
    shader_elems: Vec<(&'a str, XNode<'a, 'i>)>,
    material_elems: Vec<XNode<'a, 'i>>,
    state: HashMap<String, State>,
    soft: HashMap<String, String>,
    builder: GraphBuilder,
    shaders: Vec<ShaderDef>,
    materials: Vec<(String, String)>,
    skipped: Vec<(String, String)>,
}

fn qualify(scope: &str, name: &str) -> String {
    if scope.is_empty() {
        name.to_string()
    } else {
        format!("{scope}/{name}")
    }
}

impl<'a, 'i> Importer<'a, 'i> {
    fn new(xml: &'a roxmltree::Document<'i>, path: &Path, opts: &LoadOptions) -> Self {
        Importer {
            xml,
            path: path.to_path_buf(),
            opts: opts.clone(),
            scopes: HashMap::new(),
            scope_order: Vec::new(),
            shader_elems: Vec::new(),
            material_elems: Vec::new(),
            state: HashMap::new(),
            soft: HashMap::new(),
            builder: GraphBuilder::new(),
            shaders: Vec::new(),
            materials: Vec::new(),
            skipped: Vec::new(),
        }
    }

    fn loc(&self, n: XNode) -> Location {
        let p = self.xml.text_pos_at(n.range().start);
        Location { file: self.path.clone(), line: p.row, column: p.col }
    }

    fn err(&self, n: XNode, kind: LoadErrorKind) -> LoadError {
        LoadError { location: self.loc(n), kind }
    }

    fn collect(&mut self) -> Result<(), LoadError> {
        let root = self.xml.root_element();
        if root.tag_name().name() != "materialx" {
            return Err(self.err(root, LoadErrorKind::Structure("root element is not <materialx>".into())));
        }
        let mut top = Scope { nodes: HashMap::new(), interface: HashMap::new(), outputs: Vec::new() };
        for el in root.children().filter(|c| c.is_element()) {
            let tag = el.tag_name().name();
            match tag {
                "nodegraph" => {
                    if el.attribute("nodedef").is_some() {
                        continue;
                    }
                    let name = self.name_of(el)?;
                    let mut sc = Scope { nodes: HashMap::new(), interface: HashMap::new(), outputs: Vec::new() };
                    for c in el.children().filter(|c| c.is_element()) {
                        match c.tag_name().name() {
                            "input" => {
                                sc.interface.insert(self.name_of(c)?, c);
                            }
                            "output" => sc.outputs.push(c),
                            _ => {
                                if SHADER_TYPES.contains(&c.attribute("type").unwrap_or("")) {
                                    self.shader_elems.push((name, c));
                                } else {
                                    sc.nodes.insert(self.name_of(c)?, c);
                                }
                            }
                        }
                    }
                    self.scopes.insert(name, sc);
                    self.scope_order.push(name);
                }
                "output" => top.outputs.push(el),
                "nodedef" | "typedef" | "look" | "collection" | "geominfo" | "implementation" | "unitdef"
                | "unittypedef" | "propertyset" | "variantset" | "backdrop" | "token" | "input" => {}
                _ => {
                    let ty = el.attribute("type").unwrap_or("");
                    if tag == "surfacematerial" || ty == "material" {
                        self.material_elems.push(el);
                    } else if SHADER_TYPES.contains(&ty) {
                        self.shader_elems.push(("", el));
                    } else {
                        top.nodes.insert(self.name_of(el)?, el);
                    }
                }
            }
        }
        self.scopes.insert("", top);
        self.scope_order.insert(0, "");
        Ok(())
    }

    fn name_of(&self, el: XNode<'a, 'i>) -> Result<&'a str, LoadError> {
        el.attribute("name").ok_or_else(|| {
            self.err(el, LoadErrorKind::Structure(format!("<{}> has no name attribute", el.tag_name().name())))
        })
    }

    fn build_all(&mut self) -> Result<(), LoadError> {
        let order = self.scope_order.clone();
        // Every node, so that every node is validated.
        for scope in &order {
            let mut names: Vec<(&'a str, usize)> =
                self.scopes[scope].nodes.iter().map(|(n, e)| (*n, e.range().start)).collect();
            names.sort_by_key(|(_, p)| *p);
            for (n, _) in names {
                match self.node(scope, n) {
                    Ok(_) | Err(Fail::Soft(_)) => {}
                    Err(Fail::Hard(e)) => return Err(e),
                }
            }
        }
        // Outputs.
        for scope in &order {
            let outs = self.scopes[scope].outputs.clone();
            for o in outs {
                let name = qualify(scope, self.name_of(o)?);
                let ty = self.type_of(o)?;
                let Some(ty) = ty else { continue };
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
                    Err(Fail::Soft(r)) => self.skipped.push((name, r)),
                    Err(Fail::Hard(e)) => return Err(e),
                }
            }
        }
        // Shaders and materials.
        let shader_elems = self.shader_elems.clone();
        for (scope, el) in shader_elems {
            if el.tag_name().name() != "standard_surface" {
                continue;
            }
            let sname = self.name_of(el)?.to_string();
            let mut inputs = Vec::new();
            for inp in el.children().filter(|c| c.is_element() && c.has_tag_name("input")) {
                let iname = self.name_of(inp)?.to_string();
                let connected = inp.attribute("nodename").is_some()
                    || inp.attribute("nodegraph").is_some()
                    || inp.attribute("interfacename").is_some();
                // A connection to a nodegraph output binds that output itself.
                let existing = inp.attribute("nodegraph").and_then(|g| match inp.attribute("output") {
                    Some(o) => self.builder.output_id(&qualify(g, o)),
                    None => self
                        .scopes
                        .get(g)
                        .and_then(|sc| sc.outputs.first())
                        .and_then(|o| o.attribute("name"))
                        .and_then(|o| self.builder.output_id(&qualify(g, o))),
                });
                let si = if let Some(id) = existing {
                    ShaderInput::Output(Ok(id))
                } else if connected {
                    // Shaders in different graphs may share a name: qualify by the scope.
                    let out_name = qualify(scope, &format!("{sname}.{iname}"));
                    let res = match self.input_source(scope, inp) {
                        Ok(Some(src)) => {
                            let ty = self.builder.source_type(&src);
                            Ok(self.builder.add_output(&out_name, ty, src).map_err(|e| self.err(inp, e.into()))?)
                        }
                        Ok(None) => Err("unconnected".to_string()),
                        Err(Fail::Soft(r)) => Err(r),
                        Err(Fail::Hard(e)) => return Err(e),
                    };
                    ShaderInput::Output(res)
                } else {
                    let ty = self.type_of(inp)?;
                    let v = match (ty, inp.attribute("value")) {
                        (Some(t), Some(text)) => Some(self.parse_value(inp, t, text)?),
                        _ => None,
                    };
                    ShaderInput::Value(v)
                };
                inputs.push((iname, si));
            }
            let location = self.loc(el);
            self.shaders.push(ShaderDef { name: sname, inputs, location });
        }
        for el in self.material_elems.clone() {
            let mname = self.name_of(el)?.to_string();
            for inp in el.children().filter(|c| c.is_element() && c.has_tag_name("input")) {
                if inp.attribute("name") == Some("surfaceshader") {
                    if let Some(s) = inp.attribute("nodename") {
                        self.materials.push((mname.clone(), s.to_string()));
                    }
                }
            }
        }
        Ok(())
    }

    fn type_of(&self, el: XNode<'a, 'i>) -> Result<Option<ValueType>, LoadError> {
        let t = el.attribute("type").ok_or_else(|| {
            self.err(el, LoadErrorKind::Structure(format!("<{}> has no type attribute", el.tag_name().name())))
        })?;
        Ok(ValueType::from_name(t))
    }

    fn parse_value(&self, el: XNode<'a, 'i>, ty: ValueType, text: &str) -> Result<Value, LoadError> {
        parse_value(ty, text).ok_or_else(|| {
            self.err(el, LoadErrorKind::MalformedValue { ty: ty.name().to_string(), text: text.to_string() })
        })
    }

    /// The source of an `<output>` element in `scope`.
    fn output_source(&mut self, scope: &'a str, o: XNode<'a, 'i>) -> Result<Source, Fail> {
        match self.input_source(scope, o)? {
            Some(s) => Ok(s),
            None => Err(Fail::Hard(self.err(o, LoadErrorKind::Structure("output is not connected".into())))),
        }
    }

    /// The source of an `<input>` (or `<output>`) element: `None` when it neither has a value
    /// nor a connection.
    fn input_source(&mut self, scope: &'a str, inp: XNode<'a, 'i>) -> Result<Option<Source>, Fail> {
        let declared = inp.attribute("type").and_then(ValueType::from_name);
        let from = qualify(scope, inp.attribute("name").unwrap_or("?"));
        let src = if let Some(target) = inp.attribute("nodename") {
            let output = inp.attribute("output");
            if self.scopes[scope].nodes.contains_key(target) {
                let id = self.node(scope, target)?;
                let channel =
                    match output {
                        Some(o) if self.builder_category(id).starts_with("separate") => {
                            Some(channel::output_channel(o).ok_or_else(|| {
                                Fail::Hard(self.err(
                                    inp,
                                    LoadErrorKind::Dangling { from: from.clone(), to: format!("{target}.{o}") },
                                ))
                            })?)
                        }
                        _ => None,
                    };
                Source::Node { node: id, channel }
            } else if scope.is_empty() && self.scopes.contains_key(target) && output.is_some() {
                self.graph_output(target, output.unwrap_or(""), inp, &from)?
            } else {
                return Err(Fail::Hard(self.err(inp, LoadErrorKind::Dangling { from, to: qualify(scope, target) })));
            }
        } else if let Some(g) = inp.attribute("nodegraph") {
            let out = inp.attribute("output").unwrap_or("");
            self.graph_output(g, out, inp, &from)?
        } else if let Some(iface) = inp.attribute("interfacename") {
            let Some(ie) = self.scopes.get(scope).and_then(|s| s.interface.get(iface)).copied() else {
                return Err(Fail::Hard(self.err(inp, LoadErrorKind::Dangling { from, to: qualify(scope, iface) })));
            };
            match self.input_source("", ie)? {
                Some(s) => s,
                None => return Ok(None),
            }
        } else if let Some(text) = inp.attribute("value") {
            match declared {
                Some(t) => Source::Constant(self.parse_value(inp, t, text)?),
                None => return Ok(None),
            }
        } else {
            return Ok(None);
        };
        if let (Some(t), Source::Node { .. }) = (declared, &src) {
            let found = self.builder.source_type(&src);
            if found != t {
                return Err(Fail::Hard(self.err(
                    inp,
                    LoadErrorKind::Build(BuildError::TypeMismatch {
                        node: from,
                        input: inp.attribute("name").unwrap_or("?").to_string(),
                        expected: t.name().to_string(),
                        found,
                    }),
                )));
            }
        }
        Ok(Some(src))
    }

    fn builder_category(&self, id: NodeId) -> &'static str {
        self.builder.node_category(id)
    }

    /// The source of output `out` of nodegraph `g` (the only output if `out` is empty).
    fn graph_output(&mut self, g: &str, out: &str, at: XNode<'a, 'i>, from: &str) -> Result<Source, Fail> {
        let Some((gname, sc)) = self.scopes.get_key_value(g) else {
            return Err(Fail::Hard(
                self.err(at, LoadErrorKind::Dangling { from: from.to_string(), to: g.to_string() }),
            ));
        };
        let gname: &'a str = gname;
        let o = sc.outputs.iter().find(|o| out.is_empty() || o.attribute("name") == Some(out)).copied();
        let Some(o) = o else {
            return Err(Fail::Hard(
                self.err(at, LoadErrorKind::Dangling { from: from.to_string(), to: format!("{g}/{out}") }),
            ));
        };
        self.output_source(gname, o)
    }

    /// Creates (once) the node called `name` in `scope`, and everything upstream of it.
    fn node(&mut self, scope: &'a str, name: &'a str) -> Result<NodeId, Fail> {
        let q = qualify(scope, name);
        let el = self.scopes[scope].nodes[name];
        match self.state.get(&q) {
            Some(State::Done(id)) => return Ok(*id),
            Some(State::Visiting) => return Err(Fail::Hard(self.err(el, LoadErrorKind::Cycle(q)))),
            None => {}
        }
        if let Some(r) = self.soft.get(&q) {
            return Err(Fail::Soft(r.clone()));
        }
        self.state.insert(q.clone(), State::Visiting);
        let r = self.make_node(scope, &q, el);
        match r {
            Ok(id) => {
                self.state.insert(q, State::Done(id));
                Ok(id)
            }
            Err(Fail::Soft(reason)) => {
                self.state.remove(&q);
                self.soft.insert(q, reason.clone());
                Err(Fail::Soft(reason))
            }
            Err(e) => Err(e),
        }
    }

    fn make_node(&mut self, scope: &'a str, q: &str, el: XNode<'a, 'i>) -> Result<NodeId, Fail> {
        let category = el.tag_name().name();
        let Some(def) = nodes::definition(category) else {
            let e = BuildError::UnknownNode { category: category.to_string(), supported: nodes::supported_list() };
            if self.opts.lenient {
                return Err(Fail::Soft(format!("unsupported node `{category}` ({q})")));
            }
            return Err(Fail::Hard(self.err(el, e.into())));
        };
        let tyname = el.attribute("type").unwrap_or("");
        let mut inputs: Vec<(&'static str, Source)> = Vec::new();
        let mut params: Vec<Param> = Vec::new();
        let mut in_type = None;
        for inp in el.children().filter(|c| c.is_element() && c.has_tag_name("input")) {
            let iname = inp.attribute("name").unwrap_or("");
            if let Some(p) = def.params.iter().find(|p| **p == iname) {
                // A string input may take its value from the enclosing graph's interface.
                let src = inp
                    .attribute("interfacename")
                    .and_then(|i| self.scopes.get(scope).and_then(|s| s.interface.get(i)).copied())
                    .unwrap_or(inp);
                let value = src.attribute("value").unwrap_or("").to_string();
                if inp.attribute("type") == Some("filename") || src.attribute("type") == Some("filename") {
                    let path = self.resolve_file(inp, &value)?;
                    // The colour space: the input's, the interface's, or inherited.
                    let colorspace = [inp, src]
                        .into_iter()
                        .chain(inp.ancestors().filter(|a| a.is_element()))
                        .find_map(|e| e.attribute("colorspace"))
                        .unwrap_or("")
                        .to_string();
                    params.push(Param::File { name: p.to_string(), path, colorspace });
                } else {
                    params.push(Param::Str { name: p.to_string(), value });
                }
                continue;
            }
            let Some(spec) = def.inputs.iter().find(|s| s.name == iname) else {
                if self.opts.lenient {
                    return Err(Fail::Soft(format!("unsupported input `{iname}` of `{category}` ({q})")));
                }
                return Err(Fail::Hard(
                    self.err(inp, BuildError::UnknownInput { node: q.to_string(), input: iname.to_string() }.into()),
                ));
            };
            if let Some(src) = self.input_source(scope, inp)? {
                if spec.name == "in" {
                    in_type = Some(self.builder.source_type(&src));
                }
                inputs.push((spec.name, src));
            } else if spec.name == "in" {
                in_type = inp.attribute("type").and_then(ValueType::from_name);
            }
        }
        let ty = if tyname == "multioutput" {
            in_type.or_else(|| {
                el.children()
                    .find(|c| c.has_tag_name("input") && c.attribute("name") == Some("in"))
                    .and_then(|c| c.attribute("type"))
                    .and_then(ValueType::from_name)
            })
        } else {
            ValueType::from_name(tyname)
        };
        let Some(ty) = ty else {
            if self.opts.lenient {
                return Err(Fail::Soft(format!("unsupported type `{tyname}` of `{q}`")));
            }
            return Err(Fail::Hard(
                self.err(el, LoadErrorKind::Structure(format!("node `{q}` has unsupported type `{tyname}`"))),
            ));
        };
        match self.builder.add_node(q, category, ty, &inputs, params) {
            Ok(id) => Ok(id),
            Err(e @ BuildError::UnsupportedType { .. }) if self.opts.lenient => Err(Fail::Soft(e.to_string())),
            Err(e) => Err(Fail::Hard(self.err(el, e.into()))),
        }
    }

    fn resolve_file(&self, at: XNode<'a, 'i>, value: &str) -> Result<PathBuf, Fail> {
        let base = self.path.parent().unwrap_or(Path::new("."));
        let mut candidates = vec![base.join(value)];
        for s in &self.opts.search_paths {
            candidates.push(s.join(value));
        }
        candidates
            .into_iter()
            .find(|p| p.is_file())
            .ok_or_else(|| Fail::Hard(self.err(at, LoadErrorKind::MissingFile(PathBuf::from(value)))))
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
