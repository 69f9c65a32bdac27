//! The graph IR: typed nodes in topological order, named outputs, and a builder that validates.

use crate::error::BuildError;
use crate::nodes::{self, Op, Param};
use crate::value::{Filtered, Value, ValueType};
use std::collections::HashMap;

/// Stable index of a node in its [`Graph`] (valid for the graph's lifetime).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeId(pub u32);

/// Index of a named output of a [`Graph`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct OutputId(pub u32);

/// Where an input (or an output) takes its value from.
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    /// A uniform value.
    Constant(Value),
    /// The geometric texture coordinate (MaterialX `UV0`, the default of `texcoord` inputs).
    Texcoord,
    /// A geometric property of the shading point (MaterialX `Pobject`, `Nobject`, ...: the
    /// default of 3D nodes' `position` / `normal` inputs); a vector3.
    Geometry(GeomProp),
    /// Another node's output; `channel` picks one channel (outputs of `separateN`).
    Node {
        /// Upstream node.
        node: NodeId,
        /// Channel picked from its value, if any.
        channel: Option<u8>,
    },
}

/// A geometric property of the shading point, in world space (= object space in tessera).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GeomProp {
    /// Position (`Pobject`, `Pworld`).
    Position,
    /// Shading normal (`Nobject`, `Nworld`).
    Normal,
    /// Tangent (`Tobject`, `Tworld`).
    Tangent,
    /// Bitangent (`Bobject`, `Bworld`).
    Bitangent,
}

/// One node: its operation, type, connected inputs in the order of its [`nodes`] table.
#[derive(Debug)]
pub(crate) struct Node {
    pub name: String,
    pub category: &'static str,
    pub op: Op,
    pub ty: ValueType,
    pub inputs: Vec<Source>,
    /// Per input: its value as a `Filtered` where it is a constant (zero otherwise), built once
    /// so that evaluation copies it instead of assembling it.
    pub consts: Box<[Filtered]>,
    /// Whether the node reads its inputs' gradients even at point footprints (heighttonormal).
    pub reads_gradients: bool,
    /// A channel-wise math operation ([`nodes::math::is_channelwise`]) of at most 8 inputs that
    /// are constants, the texture coordinate or whole upstream values: evaluated from its
    /// inputs where they lie, with no input slots filled.
    pub direct: Option<nodes::math::MathOp>,
    pub params: Vec<Param>,
    /// This node and every node it depends on, ascending (= topological order), made on first
    /// request ([`Graph::upstream`]): only the nodes evaluations start from (outputs, cached
    /// nodes) are asked for it. Made for every node as it was added, a chain of n nodes held
    /// n²/2 entries (1.8 GB and 1.4 s to load for 30 000).
    pub upstream: std::sync::OnceLock<Box<[NodeId]>>,
    /// Whether its value depends on the shading point through uv alone.
    pub uv_only: bool,
}

/// A named graph output.
#[derive(Clone, Debug)]
pub struct GraphOutput {
    /// Name (`nodegraph/output` for outputs inside a nodegraph).
    pub name: String,
    /// Type.
    pub ty: ValueType,
    /// Where its value comes from.
    pub source: Source,
}

/// An immutable, validated procedural texture graph. Nodes are stored in topological order.
#[derive(Debug)]
pub struct Graph {
    pub(crate) nodes: Vec<Node>,
    pub(crate) outputs: Vec<GraphOutput>,
    by_name: HashMap<String, NodeId>,
    out_by_name: HashMap<String, OutputId>,
}

impl Graph {
    /// The node called `name`.
    pub fn node_id(&self, name: &str) -> Option<NodeId> {
        self.by_name.get(name).copied()
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// All node ids, in topological order.
    pub fn node_ids(&self) -> impl Iterator<Item = NodeId> + '_ {
        (0..self.nodes.len() as u32).map(NodeId)
    }

    /// A node's name.
    pub fn node_name(&self, id: NodeId) -> &str {
        &self.nodes[id.0 as usize].name
    }

    /// A node's MaterialX category (`noise2d`, `multiply`, ...).
    pub fn node_category(&self, id: NodeId) -> &'static str {
        self.nodes[id.0 as usize].category
    }

    /// A node's output type.
    pub fn node_type(&self, id: NodeId) -> ValueType {
        self.nodes[id.0 as usize].ty
    }

    /// The nodes feeding `id`'s inputs, in input order.
    pub fn node_inputs(&self, id: NodeId) -> Vec<(&'static str, &Source)> {
        let n = &self.nodes[id.0 as usize];
        nodes::input_names(n.category).into_iter().zip(n.inputs.iter()).collect()
    }

    /// The graph's outputs.
    pub fn outputs(&self) -> &[GraphOutput] {
        &self.outputs
    }

    /// The output called `name`.
    pub fn output_id(&self, name: &str) -> Option<OutputId> {
        self.out_by_name.get(name).copied()
    }

    /// An output by id.
    pub fn output(&self, id: OutputId) -> &GraphOutput {
        &self.outputs[id.0 as usize]
    }

    /// A node's uniform string inputs (file names, modes).
    pub fn node_params(&self, id: NodeId) -> &[Param] {
        &self.nodes[id.0 as usize].params
    }

    /// The nodes that evaluating `id` needs, in topological order (including `id`).
    pub fn upstream(&self, id: NodeId) -> &[NodeId] {
        self.nodes[id.0 as usize].upstream.get_or_init(|| self.collect_upstream(id))
    }

    /// [`Self::upstream`] by a walk over the inputs: every node `id` reaches, ascending (node
    /// ids are assigned in topological order, each after its inputs).
    fn collect_upstream(&self, id: NodeId) -> Box<[NodeId]> {
        let mut seen = vec![false; id.0 as usize + 1];
        let mut stack = vec![id];
        seen[id.0 as usize] = true;
        let mut found = Vec::new();
        while let Some(n) = stack.pop() {
            found.push(n);
            for src in &self.nodes[n.0 as usize].inputs {
                if let Source::Node { node, .. } = src {
                    if !std::mem::replace(&mut seen[node.0 as usize], true) {
                        stack.push(*node);
                    }
                }
            }
        }
        found.sort_unstable();
        found.into_boxed_slice()
    }

    /// Whether node `id` depends on the shading point through its uv alone: false when it or
    /// anything upstream reads position, normal, tangent or bitangent (`position`, `normal`,
    /// `tangent`, `bitangent`, a 3D noise's default `position`, `geompropvalue` of anything but
    /// a uv set). Only such nodes can be cached as textures over the uv plane.
    pub fn is_uv_only(&self, id: NodeId) -> bool {
        self.nodes[id.0 as usize].uv_only
    }

    /// Whether a source depends on the shading point through its uv alone.
    pub fn source_is_uv_only(&self, s: &Source) -> bool {
        match s {
            Source::Constant(_) | Source::Texcoord => true,
            Source::Geometry(_) => false,
            Source::Node { node, .. } => self.is_uv_only(*node),
        }
    }

    /// Warnings about nodes that load but cannot do what the document asks (an unknown
    /// `geompropvalue` giving its default, a second uv set read as the first), each naming
    /// its node.
    pub fn warnings(&self) -> Vec<String> {
        (0..self.nodes.len() as u32).filter_map(|k| self.node_warning(NodeId(k))).collect()
    }

    /// The load warning of node `id`, if any, naming the node.
    pub fn node_warning(&self, id: NodeId) -> Option<String> {
        let n = &self.nodes[id.0 as usize];
        nodes::warning(&n.op).map(|w| format!("node `{}` ({}): {w}", n.name, n.category))
    }
}

/// Builds a [`Graph`] node by node; inputs must name nodes added before (so no cycles).
#[derive(Debug, Default)]
pub struct GraphBuilder {
    nodes: Vec<Node>,
    outputs: Vec<GraphOutput>,
    by_name: HashMap<String, NodeId>,
    out_by_name: HashMap<String, OutputId>,
}

impl GraphBuilder {
    /// An empty builder.
    pub fn new() -> GraphBuilder {
        GraphBuilder::default()
    }

    /// Type of an already added node.
    pub fn node_type(&self, id: NodeId) -> ValueType {
        self.nodes[id.0 as usize].ty
    }

    /// Category of an already added node.
    pub fn node_category(&self, id: NodeId) -> &'static str {
        self.nodes[id.0 as usize].category
    }

    /// The output called `name`, if added.
    pub fn output_id(&self, name: &str) -> Option<OutputId> {
        self.out_by_name.get(name).copied()
    }

    /// Number of outputs added.
    pub fn output_count(&self) -> usize {
        self.outputs.len()
    }

    /// The node called `name`, if added.
    pub fn node_id(&self, name: &str) -> Option<NodeId> {
        self.by_name.get(name).copied()
    }

    /// The type a [`Source`] delivers.
    pub fn source_type(&self, s: &Source) -> ValueType {
        match s {
            Source::Constant(v) => v.ty,
            Source::Texcoord => ValueType::Vector2,
            Source::Geometry(_) => ValueType::Vector3,
            Source::Node { node, channel } => {
                if channel.is_some() {
                    ValueType::Float
                } else {
                    self.node_type(*node)
                }
            }
        }
    }

    /// Adds a node of MaterialX `category` and output type `ty`. `inputs` name MaterialX
    /// inputs; omitted ones take the node definition's defaults. `params` are the uniform
    /// string/filename inputs (e.g. an image's resolved `file`).
    pub fn add_node(
        &mut self,
        name: &str,
        category: &str,
        ty: ValueType,
        inputs: &[(&str, Source)],
        params: Vec<Param>,
    ) -> Result<NodeId, BuildError> {
        if self.by_name.len() >= crate::MAX_NODES {
            return Err(BuildError::TooManyNodes(crate::MAX_NODES));
        }
        if self.by_name.contains_key(name) {
            return Err(BuildError::DuplicateName(name.to_string()));
        }
        let def = nodes::definition(category).ok_or_else(|| BuildError::UnknownNode {
            category: category.to_string(),
            supported: nodes::supported_list(),
        })?;
        if !(def.types)(ty) {
            return Err(BuildError::UnsupportedType { node: name.to_string(), category: def.category, ty });
        }
        for (iname, _) in inputs {
            if !def.inputs.iter().any(|s| s.name == *iname) {
                return Err(BuildError::UnknownInput { node: name.to_string(), input: iname.to_string() });
            }
        }
        let mut srcs = Vec::with_capacity(def.inputs.len());
        let mut types = Vec::with_capacity(def.inputs.len());
        let mut deps: Vec<NodeId> = Vec::new();
        let mut uv_only = true;
        for spec in def.inputs {
            let src = match inputs.iter().find(|(n, _)| *n == spec.name) {
                Some((_, s)) => s.clone(),
                None => spec.default_source_with(ty, &types),
            };
            let found = self.source_type(&src);
            if !spec.accepts_with(ty, found, &types) {
                return Err(BuildError::TypeMismatch {
                    node: name.to_string(),
                    input: spec.name.to_string(),
                    expected: spec.expected(ty),
                    found,
                });
            }
            match src {
                Source::Node { node, .. } => {
                    deps.push(node);
                    uv_only &= self.nodes[node.0 as usize].uv_only;
                }
                Source::Geometry(_) => uv_only = false,
                Source::Constant(_) | Source::Texcoord => {}
            }
            srcs.push(src);
            types.push(found);
        }
        let op = (def.build)(def.category, ty, &types, &srcs, &params)
            .map_err(|msg| BuildError::Invalid { node: name.to_string(), message: msg })?;
        uv_only &= !nodes::reads_geometry(&op);
        let id = NodeId(self.nodes.len() as u32);
        let consts = srcs
            .iter()
            .map(|s| match s {
                Source::Constant(v) => Filtered::constant(*v),
                _ => Filtered::zero(ValueType::Float),
            })
            .collect();
        let direct = match &op {
            Op::Math(m)
                if nodes::math::is_channelwise(m)
                    && srcs.len() <= 8
                    && srcs.iter().all(|s| {
                        matches!(s, Source::Constant(_) | Source::Texcoord | Source::Node { channel: None, .. })
                    }) =>
            {
                Some(*m)
            }
            _ => None,
        };
        self.nodes.push(Node {
            name: name.to_string(),
            category: def.category,
            direct,
            op,
            ty,
            inputs: srcs,
            consts,
            reads_gradients: matches!(def.category, "heighttonormal" | "bump"),
            params,
            upstream: std::sync::OnceLock::new(),
            uv_only,
        });
        self.by_name.insert(name.to_string(), id);
        Ok(id)
    }

    /// Adds a named output.
    pub fn add_output(&mut self, name: &str, ty: ValueType, source: Source) -> Result<OutputId, BuildError> {
        if self.out_by_name.contains_key(name) {
            return Err(BuildError::DuplicateName(name.to_string()));
        }
        let found = self.source_type(&source);
        if found != ty && found.channels() != ty.channels() {
            return Err(BuildError::TypeMismatch {
                node: name.to_string(),
                input: "output".into(),
                expected: ty.name().to_string(),
                found,
            });
        }
        let id = OutputId(self.outputs.len() as u32);
        self.outputs.push(GraphOutput { name: name.to_string(), ty, source });
        self.out_by_name.insert(name.to_string(), id);
        Ok(id)
    }

    /// The finished graph.
    pub fn build(self) -> Graph {
        Graph { nodes: self.nodes, outputs: self.outputs, by_name: self.by_name, out_by_name: self.out_by_name }
    }
}
