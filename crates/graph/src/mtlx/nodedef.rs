//! Node definitions: which `nodedef` a node instantiates, and custom nodes expanded from their graphs.

use super::importer::{qualify, Fail, Iface, Importer, Scope, State};
use crate::error::LoadErrorKind;
use crate::graph::Source;
use crate::nodes;
use crate::value::ValueType;
use roxmltree::Node as XNode;

pub(super) struct NodeDefInfo<'a, 'i> {
    pub(super) name: &'a str,
    pub(super) node: &'a str,
    pub(super) inputs: Vec<XNode<'a, 'i>>,
    /// `(name, type)` of each output.
    pub(super) outputs: Vec<(&'a str, &'a str)>,
    pub(super) version: Option<&'a str>,
    pub(super) default_version: bool,
}

/// How a node's category is defined.
pub(super) enum DefKind {
    /// By the node library.
    Builtin,
    /// By nodedef `k` of the document, implemented by a node graph.
    Custom(usize),
    /// By nodedef `k`, without a node graph implementation.
    Unimplemented(usize),
    /// Not at all.
    Unknown,
}

impl<'a, 'i> Importer<'a, 'i> {
    /// How node `el`'s category is defined.
    pub(super) fn resolve_def(&self, scope: usize, el: XNode<'a, 'i>) -> Result<DefKind, Fail> {
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

    /// Output `output` of custom node `name` (instantiating nodedef `k`), expanding its
    /// definition once per instance.
    pub(super) fn instance_output(
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
                // A definition that instantiates itself never ends; one nested too deep in
                // others is refused before its names (which grow with the depth) and the walks
                // up this chain make loading quadratic.
                let mut p = Some(scope);
                let mut depth = 0;
                while let Some(s) = p {
                    if let Iface::Def { nodedef, .. } = self.scopes[s].iface {
                        if nodedef == k {
                            return Err(self.hard(
                                el,
                                LoadErrorKind::Structure(format!(
                                    "node `{}` instantiates `{}` inside its own definition (recursive nodedef)",
                                    crate::text::excerpt(q),
                                    self.nodedefs[k].name
                                )),
                            ));
                        }
                        depth += 1;
                    }
                    p = self.scopes[s].parent;
                }
                if depth >= crate::MAX_INSTANCE_DEPTH {
                    return Err(self.hard(
                        el,
                        LoadErrorKind::Structure(format!(
                            "node `{}` (`{}`) is implemented by a node graph nested more than {} deep in \
                             other nodes' implementations",
                            crate::text::excerpt(q),
                            self.nodedefs[k].name,
                            crate::MAX_INSTANCE_DEPTH
                        )),
                    ));
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
}
