//! Input sources: what an `<input>` or `<output>` reads, through connections and interfaces.

use super::importer::{qualify, Fail, Iface, Importer};
use super::parse_value;
use crate::error::{BuildError, LoadErrorKind};
use crate::graph::Source;
use crate::nodes;
use crate::value::{Value, ValueType};
use glam::DVec3;
use roxmltree::Node as XNode;

impl<'a, 'i> Importer<'a, 'i> {
    /// Parses a value of type `ty` given on `el`: numbers, or a custom nodedef's enum name;
    /// colours are converted from their active colour space to the working space.
    pub(super) fn typed_value(&self, el: XNode<'a, 'i>, ty: ValueType, text: &str) -> Result<Value, Fail> {
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

    /// The source of an `<output>` element in `scope`.
    pub(super) fn output_source(&mut self, scope: usize, o: XNode<'a, 'i>) -> Result<Source, Fail> {
        match self.input_source(scope, o)? {
            Some(s) => Ok(s),
            None => Err(self.hard(o, LoadErrorKind::Structure("output is not connected".into()))),
        }
    }

    /// The element that finally binds interface input `iname` of `scope` (following
    /// `interfacename` chains outwards), with the scope to resolve it in; `None` when the
    /// interface input exists but is neither set nor connected.
    pub(super) fn interface_binding(
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
    pub(super) fn input_source(&mut self, scope: usize, inp: XNode<'a, 'i>) -> Result<Option<Source>, Fail> {
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
                // A node's input is named as `node.input`; a graph output by its own name.
                let (node, input) = match inp.parent_element() {
                    Some(p) if !matches!(p.tag_name().name(), "nodegraph" | "materialx") => (
                        qualify(&self.scopes[scope].prefix, p.attribute("name").unwrap_or("?")),
                        inp.attribute("name").unwrap_or("?").to_string(),
                    ),
                    _ => (from, String::new()),
                };
                return Err(self.hard(
                    inp,
                    LoadErrorKind::Build(BuildError::TypeMismatch {
                        node,
                        input,
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
    pub(super) fn pick(&mut self, src: &Source, k: usize, at: XNode<'a, 'i>) -> Result<Source, Fail> {
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
}
