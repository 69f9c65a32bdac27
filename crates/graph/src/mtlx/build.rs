//! The importer's second pass: every node, output, shader and material built into the graph.

use super::color::Transfer;
use super::document::{ShaderDef, ShaderExtras, ShaderInput};
use super::importer::{merge_soft, qualify, Fail, Importer, State};
use super::nodedef::DefKind;
use super::shading::{gltf_alpha_cutoff, gltf_alpha_mode};
use crate::error::{BuildError, LoadError, LoadErrorKind};
use crate::graph::{OutputId, Source};
use crate::matrix::Matrix;
use crate::nodes::{self, channel, Param};
use crate::value::{Value, ValueType};
use roxmltree::Node as XNode;

impl<'a, 'i> Importer<'a, 'i> {
    pub(super) fn build_all(&mut self) -> Result<(), LoadError> {
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
                    // A node of outputs of several types is a library node per output.
                    Ok(_) if nodes::flake::CATEGORIES.contains(&self.category(el)) => {
                        nodes::flake::OUTPUTS.iter().map(|o| Some(*o)).collect()
                    }
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
                    // Leniently, an output that cannot be built is left out with the reason.
                    Err(Fail::Hard(e)) if self.opts.lenient && scoped(&e.kind) => {
                        self.skipped.push((name, e.to_string()));
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
                        // Leniently, scoped to the shader input (see `scoped`).
                        Err(Fail::Hard(e)) if self.opts.lenient && scoped(&e.kind) => Err(e.to_string()),
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
                    match (ty, inp.attribute("value")) {
                        (Some(t), Some(text)) => match self.typed_value(inp, t, text) {
                            Ok(v) => ShaderInput::Value(Some(v)),
                            Err(Fail::Hard(e)) if self.opts.lenient && scoped(&e.kind) => {
                                ShaderInput::Output(Err(e.to_string()))
                            }
                            Err(Fail::Hard(e)) => return Err(e),
                            Err(Fail::Soft(_)) => ShaderInput::Value(None),
                        },
                        _ => ShaderInput::Value(None),
                    }
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
    ///
    /// [`Document::material`]: super::Document::material
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

    /// Output `output` (or the default one) of node `name` in `scope`.
    pub(super) fn node_output(
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
        if nodes::flake::CATEGORIES.contains(&self.category(el)) {
            return self.multi_output_node(scope, name, output, at);
        }
        let src = self.node(scope, name)?;
        match (output, &src) {
            (Some(o), Source::Node { node, channel: None })
                if self.builder.node_category(*node).starts_with("separate") =>
            {
                let n = self.builder.node_type(*node).channels();
                match channel::output_channel(o).filter(|c| (*c as usize) < n) {
                    Some(c) => Ok(Source::Node { node: *node, channel: Some(c) }),
                    None => Err(self.no_such_output(scope, name, o, at)),
                }
            }
            _ => Ok(src),
        }
    }

    /// Output `output` of a node whose outputs have different types (`flake2d`, `flake3d`):
    /// tessera's values have one type each, so each output the document connects is a library
    /// node of its own, `name.output`, with the node's inputs and its output named.
    fn multi_output_node(
        &mut self,
        scope: usize,
        name: &'a str,
        output: Option<&'a str>,
        at: XNode<'a, 'i>,
    ) -> Result<Source, Fail> {
        let Some(o) = output.filter(|o| nodes::flake::output_type(o).is_some()) else {
            return Err(self.no_such_output(scope, name, output.unwrap_or("?"), at));
        };
        self.node_as(scope, name, Some(o))
    }

    /// The error of input `at` connected to output `output` of node `name`, which has none of
    /// that name.
    fn no_such_output(&self, scope: usize, name: &str, output: &str, at: XNode<'a, 'i>) -> Fail {
        let from = qualify(&self.scopes[scope].prefix, at.attribute("name").unwrap_or("?"));
        let to = format!("{}.{output}", qualify(&self.scopes[scope].prefix, name));
        self.hard(at, LoadErrorKind::Dangling { from, to })
    }

    /// Creates (once) the library node called `name` in `scope`, and everything upstream of it.
    fn node(&mut self, scope: usize, name: &'a str) -> Result<Source, Fail> {
        self.node_as(scope, name, None)
    }

    /// [`Self::node`], for output `output` of a multi-output node (its own library node,
    /// `name.output`).
    fn node_as(&mut self, scope: usize, name: &'a str, output: Option<&'a str>) -> Result<Source, Fail> {
        let q = qualify(&self.scopes[scope].prefix, name);
        let q = match output {
            Some(o) => format!("{q}.{o}"),
            None => q,
        };
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
        let r = self.make_node(scope, &q, el, output);
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
            // Leniently, a node that cannot be built (a malformed value, a missing file, a
            // wrong type) fails only what needs it, like an unsupported node: scoped to the
            // outputs and material inputs downstream, each told why (see `scoped`).
            Err(Fail::Hard(e)) if self.opts.lenient && scoped(&e.kind) => {
                let k = self.broken(self.category(el), &q, e);
                self.soft.insert(q, vec![k]);
                Err(Fail::Soft(vec![k]))
            }
            Err(e) => Err(e),
        }
    }

    /// `frame` and `time`, folded at load: the frame rendered ([`LoadOptions::frame`], 1 unless
    /// set, as in MaterialX's viewers) and its time in seconds, `frame / fps` (a `divide` node
    /// where `fps` is connected; 0 at 0 fps, as every division by zero).
    ///
    /// [`LoadOptions::frame`]: super::LoadOptions::frame
    fn application_node(
        &mut self,
        scope: usize,
        q: &str,
        el: XNode<'a, 'i>,
        category: &str,
    ) -> Result<Option<Source>, Fail> {
        if !nodes::FOLDED_AT_LOAD.contains(&category) {
            return Ok(None);
        }
        if self.type_name(el) != Some("float") {
            let found = self.type_name(el).unwrap_or("no type");
            return Err(
                self.hard(el, LoadErrorKind::Structure(format!("`{q}`: `{category}` is a float, not a {found}")))
            );
        }
        let frame = self.opts.frame.unwrap_or(1.0);
        if category == "frame" {
            return Ok(Some(Source::Constant(Value::float(frame))));
        }
        let mut fps = Source::Constant(Value::float(24.0));
        for inp in self.inputs_of(el) {
            let iname = self.input_name(el, category, inp);
            if iname != "fps" {
                let f = self.unsupported(category, q, no_such_input(category, iname, &["fps"]), inp);
                return Err(f);
            }
            if let Some(src) = self.input_source(scope, inp)? {
                fps = src;
            }
        }
        if let Source::Constant(v) = &fps {
            let t = if v.v[0] == 0.0 { 0.0 } else { frame / v.v[0] };
            return Ok(Some(Source::Constant(Value::float(t))));
        }
        let inputs = [("in1", Source::Constant(Value::float(frame))), ("in2", fps)];
        match self.builder.add_node(q, "divide", ValueType::Float, &inputs, Vec::new()) {
            Ok(id) => Ok(Some(Source::Node { node: id, channel: None })),
            Err(e) => Err(self.hard(el, e.into())),
        }
    }

    fn make_node(&mut self, scope: usize, q: &str, el: XNode<'a, 'i>, output: Option<&str>) -> Result<Source, Fail> {
        let category = self.category(el);
        let tyname = self.type_name(el).unwrap_or("");
        if category == "swizzle" && self.version(el) < (1, 39) {
            return self.legacy_swizzle(scope, q, el);
        }
        if let Some(src) = self.matrix_reader(scope, q, el, category)? {
            return Ok(src);
        }
        if let Some(src) = self.application_node(scope, q, el, category)? {
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
                    // An empty file name names no file: the node decides (an image gives its
                    // default, as in MaterialX).
                    let path = if value.trim().is_empty() {
                        std::path::PathBuf::new()
                    } else {
                        self.resolve_file(src, &value)?
                    };
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
                let names: Vec<&str> = def.inputs.iter().map(|s| s.name).collect();
                let f = self.unsupported(category, q, no_such_input(category, iname, &names), inp);
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
        if let Some(o) = output {
            params.push(Param::Str { name: "output".into(), value: o.to_string() });
        }
        let ty = if let Some(t) = output.and_then(nodes::flake::output_type) {
            Some(t)
        } else if tyname == "multioutput" {
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
            let f = self.unsupported(category, q, unknown_type(tyname), el);
            merge_soft(&mut soft, f)?;
            return Err(Fail::Soft(soft));
        };
        if !soft.is_empty() {
            return Err(Fail::Soft(soft));
        }
        let id = match self.builder.add_node(q, category, ty, &inputs, params) {
            Ok(id) => id,
            Err(BuildError::UnsupportedType { .. }) => {
                return Err(self.unsupported(category, q, format!("no `{tyname}` variant in tessera"), el));
            }
            Err(e) => return Err(self.hard(el, e.into())),
        };
        let src = Source::Node { node: id, channel: None };
        match conversion {
            Some(c) => self.convert_colors(q, src, ty, &c, el),
            None => Ok(src),
        }
    }
}

/// Whether an error of a node is the node's own (a lenient load then fails only what needs
/// it): a bad value, type, input, connection or file. Cycles, malformed structure and the
/// document-wide limits (node count, nesting) stay errors of the whole document: going on after
/// them could cost what the limits exist to prevent.
fn scoped(kind: &LoadErrorKind) -> bool {
    match kind {
        LoadErrorKind::Build(b) => !matches!(b, BuildError::TooManyNodes(_) | BuildError::DuplicateName(_)),
        LoadErrorKind::Dangling { .. } | LoadErrorKind::MissingFile(_) | LoadErrorKind::MalformedValue { .. } => true,
        _ => false,
    }
}

/// The closest of `names` to a misspelt `name`, when it is close: at most one edit per three
/// letters (at least one, at most three), a swap of neighbours counting as one.
fn closest<'n>(name: &str, names: &[&'n str]) -> Option<&'n str> {
    let reach = (name.chars().count() / 3).clamp(1, 3);
    names.iter().map(|n| (strsim::damerau_levenshtein(name, n), *n)).filter(|(d, _)| *d <= reach).min().map(|(_, n)| n)
}

/// The message for an input the node's definition does not have: the inputs it does have, and
/// the likely one when the name is a misspelling of it.
fn no_such_input(category: &str, input: &str, names: &[&str]) -> String {
    let guess = closest(input, names).map_or(String::new(), |n| format!("did you mean `{n}`? "));
    let input = crate::text::excerpt(input);
    format!("`{category}` has no input `{input}`; {guess}its inputs: {}", names.join(", "))
}

/// MaterialX's data types that tessera does not evaluate as node outputs.
const OTHER_MATERIALX_TYPES: &[&str] = &[
    "matrix33",
    "matrix44",
    "string",
    "filename",
    "integerarray",
    "floatarray",
    "color3array",
    "color4array",
    "vector2array",
    "vector3array",
    "vector4array",
    "stringarray",
    "BSDF",
    "EDF",
    "VDF",
    "surfaceshader",
    "displacementshader",
    "volumeshader",
    "lightshader",
    "material",
];

/// The message for a node output type no node of tessera's library has: a MaterialX type
/// tessera does not evaluate, or a name that is no MaterialX type at all (with the likely one).
fn unknown_type(ty: &str) -> String {
    const VALUE_TYPES: &[&str] = &["float", "integer", "boolean", "vector2", "vector3", "vector4", "color3", "color4"];
    let short = crate::text::excerpt(ty);
    if OTHER_MATERIALX_TYPES.contains(&ty) {
        return format!("type `{short}` is not one tessera evaluates (value types: {})", VALUE_TYPES.join(", "));
    }
    let all: Vec<&str> = VALUE_TYPES.iter().chain(OTHER_MATERIALX_TYPES).copied().collect();
    let guess = closest(ty, &all).map_or(String::new(), |n| format!("; did you mean `{n}`?"));
    format!("`{short}` is not a MaterialX type{guess}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn misspellings_get_the_likely_name() {
        assert_eq!(closest("texcord", &["texcoord", "octaves"]), Some("texcoord"));
        assert_eq!(closest("amplitud", &["amplitude", "pivot"]), Some("amplitude"));
        assert_eq!(closest("zzz", &["texcoord", "octaves"]), None);
        assert_eq!(closest("in", &["in1", "in2"]), Some("in1"));
        assert!(unknown_type("flaot").contains("did you mean `float`"));
        assert!(unknown_type("colour3").contains("did you mean `color3`"));
        assert!(unknown_type("matrix33").contains("not one tessera evaluates"));
        assert!(!unknown_type("qqqqqqq").contains("did you mean"));
    }
}
