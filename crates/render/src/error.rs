//! The renderer's error type: every error says where (file, line, column when known) and what
//! was expected.

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A place in an input file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Loc {
    /// The file (scene, mesh, image...).
    pub file: Arc<PathBuf>,
    /// 1-based line, 0 when unknown.
    pub line: u32,
    /// 1-based column, 0 when unknown.
    pub col: u32,
}

impl Loc {
    /// A location at a line and column of `file`.
    pub fn new(file: Arc<PathBuf>, line: u32, col: u32) -> Self {
        Loc { file, line, col }
    }

    /// The whole of `file`, no line known.
    pub fn file(file: &Path) -> Self {
        Loc { file: Arc::new(file.to_path_buf()), line: 0, col: 0 }
    }
}

impl fmt::Display for Loc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if self.line > 0 {
            write!(f, ":{}", self.line)?;
            if self.col > 0 {
                write!(f, ":{}", self.col)?;
            }
        }
        Ok(())
    }
}

/// An error in a scene or in a file it refers to.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Error {
    /// Something wrong at a known place in an input file.
    #[error("{loc}: {msg}")]
    At {
        /// Where.
        loc: Loc,
        /// What was wrong and what was expected.
        msg: String,
    },
    /// Something wrong with no file to point at (command-line values, an embedded scene).
    #[error("{0}")]
    Plain(String),
}

impl Error {
    /// An error at `loc`.
    pub fn at(loc: &Loc, msg: impl Into<String>) -> Self {
        Error::At { loc: loc.clone(), msg: msg.into() }
    }

    /// An error about a whole file.
    pub fn in_file(path: &Path, msg: impl Into<String>) -> Self {
        Error::At { loc: Loc::file(path), msg: msg.into() }
    }

    /// An error with no location.
    pub fn plain(msg: impl Into<String>) -> Self {
        Error::Plain(msg.into())
    }
}

/// Result with the renderer's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
