//! The importer: its state, its two kinds of failure, and its first pass over each document's top level.

use super::color::{color_space, Primaries, Transfer};
use super::document::ShaderDef;
use super::files::XINCLUDE_NS;
use super::nodedef::NodeDefInfo;
use super::upgrade::{parse_version, NEWEST, OLDEST};
use super::LoadOptions;
use crate::error::{BuildError, LoadError, LoadErrorKind, Location, Unsupported};
use crate::graph::{GraphBuilder, Source};
use roxmltree::Node as XNode;
use std::collections::{HashMap, HashSet};
use std::path::PathBuf;

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

#[derive(Clone, Debug, PartialEq)]
pub(super) enum State {
    Visiting,
    Done(Source),
}

/// A failure: hard (always an error) or soft (depends on unsupported nodes: indices into
/// `Importer::unsupported`).
pub(super) enum Fail {
    Hard(LoadError),
    Soft(Vec<usize>),
}

impl From<LoadError> for Fail {
    fn from(e: LoadError) -> Fail {
        Fail::Hard(e)
    }
}

/// Collects the unsupported nodes behind soft failures while going on with the other inputs.
pub(super) fn merge_soft(acc: &mut Vec<usize>, f: Fail) -> Result<(), Fail> {
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
pub(super) enum Iface<'a, 'i> {
    /// The document's top-level `<input>`s.
    Top,
    /// A node graph's own `<input>`s, resolved at the top level.
    Graph(HashMap<&'a str, XNode<'a, 'i>>),
    /// The implementation of nodedef `nodedef`: the inputs of `instance` (resolved in the
    /// scope's parent), else the nodedef's defaults (or the graph's own `<input>`s).
    Def { nodedef: usize, own: HashMap<&'a str, XNode<'a, 'i>>, instance: Option<XNode<'a, 'i>> },
}

pub(super) struct Scope<'a, 'i> {
    /// Qualified-name prefix: "" at the top, the graph's name, or the instance's qualified name.
    pub(super) prefix: String,
    pub(super) nodes: HashMap<&'a str, XNode<'a, 'i>>,
    pub(super) outputs: Vec<XNode<'a, 'i>>,
    pub(super) iface: Iface<'a, 'i>,
    pub(super) parent: Option<usize>,
}

/// The contents of a `<nodegraph>`: nodes, outputs, interface inputs, shader nodes.
type GraphContent<'a, 'i> =
    (HashMap<&'a str, XNode<'a, 'i>>, Vec<XNode<'a, 'i>>, HashMap<&'a str, XNode<'a, 'i>>, Vec<XNode<'a, 'i>>);

pub(super) struct Importer<'a, 'i> {
    docs: &'a [roxmltree::Document<'i>],
    pub(super) paths: &'a [PathBuf],
    versions: Vec<(u32, u32)>,
    pub(super) opts: LoadOptions,
    /// The working colour space's primaries.
    pub(super) working: Primaries,
    pub(super) scopes: Vec<Scope<'a, 'i>>,
    /// Scopes of `<nodegraph>`s by name.
    pub(super) graph_scopes: HashMap<&'a str, usize>,
    /// Every `<nodegraph>` element by name (including implementations of outside nodedefs).
    pub(super) graph_elems: HashMap<&'a str, XNode<'a, 'i>>,
    pub(super) top_inputs: HashMap<&'a str, XNode<'a, 'i>>,
    pub(super) nodedefs: Vec<NodeDefInfo<'a, 'i>>,
    pub(super) nodedef_by_name: HashMap<&'a str, usize>,
    /// nodedef name → name of the node graph implementing it.
    pub(super) impls: HashMap<&'a str, &'a str>,
    pub(super) shader_elems: Vec<(usize, XNode<'a, 'i>)>,
    pub(super) material_elems: Vec<XNode<'a, 'i>>,
    /// ≤ 1.37 `<material>` elements (with `<shaderref>`s).
    legacy_materials: Vec<XNode<'a, 'i>>,
    pub(super) state: HashMap<String, State>,
    pub(super) soft: HashMap<String, Vec<usize>>,
    /// Instance scopes by the instance's qualified name.
    pub(super) instances: HashMap<String, usize>,
    pub(super) builder: GraphBuilder,
    pub(super) shaders: Vec<ShaderDef>,
    pub(super) materials: Vec<(String, String)>,
    pub(super) skipped: Vec<(String, String)>,
    pub(super) unsupported: Vec<Unsupported>,
    pub(super) shader_outputs: HashSet<String>,
}

pub(super) fn qualify(scope: &str, name: &str) -> String {
    if scope.is_empty() {
        name.to_string()
    } else {
        format!("{scope}/{name}")
    }
}

impl<'a, 'i> Importer<'a, 'i> {
    pub(super) fn new(
        docs: &'a [roxmltree::Document<'i>],
        paths: &'a [PathBuf],
        opts: &LoadOptions,
    ) -> Result<Self, LoadError> {
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
                        imp.err(
                            root,
                            LoadErrorKind::Structure(format!(
                                "malformed MaterialX version `{}`",
                                crate::text::excerpt(s)
                            )),
                        )
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

    pub(super) fn doc_index(&self, n: XNode) -> usize {
        let d = n.document();
        self.docs.iter().position(|x| std::ptr::eq(x, d)).unwrap_or(0)
    }

    pub(super) fn version(&self, n: XNode) -> (u32, u32) {
        self.versions[self.doc_index(n)]
    }

    pub(super) fn loc(&self, n: XNode) -> Location {
        let k = self.doc_index(n);
        let p = self.docs[k].text_pos_at(n.range().start);
        Location { file: self.paths[k].clone(), line: p.row, column: p.col }
    }

    pub(super) fn err(&self, n: XNode, kind: LoadErrorKind) -> LoadError {
        LoadError { location: self.loc(n), kind }
    }

    pub(super) fn hard(&self, n: XNode, kind: LoadErrorKind) -> Fail {
        Fail::Hard(self.err(n, kind))
    }

    /// Records an unsupported node (once per element and detail) and returns the soft failure.
    pub(super) fn unsupported(&mut self, category: &str, node: &str, detail: String, at: XNode) -> Fail {
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

    /// The names of the node graphs that implement nodedefs (scopes of `Iface::Def` without an
    /// instance: the copies checked at the defaults).
    pub(super) fn definition_graphs(&self) -> Vec<String> {
        self.scopes
            .iter()
            .filter(|s| matches!(s.iface, Iface::Def { instance: None, .. }) && s.parent.is_none())
            .map(|s| s.prefix.clone())
            .collect()
    }

    /// Records node `node` as broken by `e` (scoped, as an unsupported node is): its entry.
    pub(super) fn broken(&mut self, category: &str, node: &str, e: LoadError) -> usize {
        self.unsupported.push(Unsupported {
            category: category.to_string(),
            node: node.to_string(),
            detail: e.kind.to_string(),
            location: e.location,
        });
        self.unsupported.len() - 1
    }

    pub(super) fn reason(&self, ix: &[usize]) -> String {
        // Unknown categories are unsupported; a known node with a bad input or type is named
        // with what is wrong with it.
        let (unknown, bad): (Vec<&Unsupported>, Vec<&Unsupported>) =
            ix.iter().map(|&k| &self.unsupported[k]).partition(|u| u.detail.is_empty());
        let mut parts = Vec::new();
        if !unknown.is_empty() {
            let items: Vec<String> = unknown.iter().map(|u| u.to_string()).collect();
            parts.push(format!("needs unsupported {}", items.join(", ")));
        }
        if !bad.is_empty() {
            let items: Vec<String> = bad.iter().map(|u| u.to_string()).collect();
            parts.push(format!("needs {}", items.join("; ")));
        }
        parts.join("; ")
    }

    pub(super) fn name_of(&self, el: XNode<'a, 'i>) -> Result<&'a str, LoadError> {
        el.attribute("name").ok_or_else(|| {
            self.err(el, LoadErrorKind::Structure(format!("<{}> has no name attribute", el.tag_name().name())))
        })
    }

    /// Reads the top level of every document.
    pub(super) fn collect(&mut self) -> Result<(), LoadError> {
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
    pub(super) fn scan_graph(&self, g: XNode<'a, 'i>) -> Result<GraphContent<'a, 'i>, LoadError> {
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
}
