//! Errors: building a graph ([`BuildError`]) and loading a MaterialX document ([`LoadError`]).

use crate::text::excerpt;
use crate::value::ValueType;
use std::fmt;
use std::path::PathBuf;

/// A problem found while building a graph, without source location.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BuildError {
    /// The category is not in the node library.
    #[error("unknown node `{}`; supported nodes: {supported}", excerpt(category))]
    UnknownNode {
        /// The category.
        category: String,
        /// Every supported category.
        supported: String,
    },
    /// The node exists but not with this output type.
    #[error("node `{}`: `{category}` has no {ty} variant", excerpt(node))]
    UnsupportedType {
        /// Node name.
        node: String,
        /// Category.
        category: &'static str,
        /// Requested type.
        ty: ValueType,
    },
    /// An input the node does not have.
    #[error("node `{}` has no input `{}`", excerpt(node), excerpt(input))]
    UnknownInput {
        /// Node name.
        node: String,
        /// Input name.
        input: String,
    },
    /// A connection or value of the wrong type.
    #[error(
        "type mismatch at `{node}{}`: expected {expected}, found {found}",
        if input.is_empty() { String::new() } else { format!(".{input}") }
    )]
    TypeMismatch {
        /// Node name (or the output's qualified name, for a graph output).
        node: String,
        /// Input name (empty for a graph output).
        input: String,
        /// What the input accepts.
        expected: String,
        /// What was given.
        found: ValueType,
    },
    /// Two nodes or outputs with one name.
    #[error("duplicate name `{}`", excerpt(.0))]
    DuplicateName(String),
    /// The graph grew beyond [`crate::MAX_NODES`] (typically node graphs that instantiate each
    /// other many times over).
    #[error(
        "more than {0} nodes once node graphs are instantiated (node graphs that use each other many times over?)"
    )]
    TooManyNodes(usize),
    /// A node-specific rule failed.
    #[error("node `{node}`: {message}")]
    Invalid {
        /// Node name.
        node: String,
        /// What is wrong.
        message: String,
    },
}

/// Where in a file something was found.
#[derive(Debug, Clone, PartialEq)]
pub struct Location {
    /// The file.
    pub file: PathBuf,
    /// 1-based line.
    pub line: u32,
    /// 1-based column.
    pub column: u32,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.file.display(), self.line, self.column)
    }
}

/// What went wrong loading a MaterialX document.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LoadErrorKind {
    /// The file could not be read.
    #[error("cannot read file: {0}")]
    Io(String),
    /// Not well-formed XML.
    #[error("malformed XML: {0}")]
    Xml(String),
    /// A graph rule failed (unknown node, type mismatch, ...).
    #[error(transparent)]
    Build(#[from] BuildError),
    /// The nodes form a cycle.
    #[error("cycle through node `{}`", excerpt(.0))]
    Cycle(String),
    /// A connection names something that does not exist.
    #[error("`{}` connects to `{}`, which does not exist", excerpt(from), excerpt(to))]
    Dangling {
        /// The connecting element.
        from: String,
        /// The missing target.
        to: String,
    },
    /// A referenced file does not exist.
    #[error("missing file `{0}`")]
    MissingFile(PathBuf),
    /// A `value` attribute that does not parse as its type.
    #[error("malformed {} value `{}`", excerpt(ty), excerpt(text))]
    MalformedValue {
        /// Declared type.
        ty: String,
        /// The text.
        text: String,
    },
    /// A required attribute is absent or an element is misplaced.
    #[error("{0}")]
    Structure(String),
    /// Elements the importer cannot evaluate, every one in the document (strict loading).
    #[error("{} unsupported: {}; supported nodes: {supported}", items.len(), list_unsupported(items))]
    Unsupported {
        /// The unsupported elements, in the order they were found.
        items: Vec<Unsupported>,
        /// Every supported node category.
        supported: String,
    },
}

/// A node the importer cannot evaluate: an unknown category, or a known one with a type, input
/// or definition it does not support.
#[derive(Debug, Clone, PartialEq)]
pub struct Unsupported {
    /// The node's category (`noise3d`, ...).
    pub category: String,
    /// The node's qualified name (`nodegraph/node`).
    pub node: String,
    /// What is unsupported beyond the category itself (empty when the category is unknown).
    pub detail: String,
    /// Where the node is.
    pub location: Location,
}

impl fmt::Display for Unsupported {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (category, node) = (excerpt(&self.category), excerpt(&self.node));
        if self.detail.is_empty() {
            write!(f, "`{category}` (node `{node}`) at {}", self.location)
        } else {
            write!(f, "node `{node}` at {}: {}", self.location, self.detail)
        }
    }
}

fn list_unsupported(items: &[Unsupported]) -> String {
    items.iter().map(|u| u.to_string()).collect::<Vec<_>>().join(", ")
}

/// A load error with its file and line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{location}: {kind}")]
pub struct LoadError {
    /// Where.
    pub location: Location,
    /// What.
    pub kind: LoadErrorKind,
}
