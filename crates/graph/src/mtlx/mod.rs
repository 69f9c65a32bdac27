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
//!
//! [`Graph`]: crate::graph::Graph
//! [`LoadErrorKind::Unsupported`]: crate::error::LoadErrorKind::Unsupported

mod build;
mod color;
mod document;
mod files;
mod importer;
mod matrices;
mod nodedef;
mod shading;
mod sources;
mod upgrade;

pub use document::Document;
pub use shading::{InputDefault, MaterialBinding, MaterialSource, SHADING_MODELS, SUPPORTED_INPUTS};

use crate::value::{Value, ValueType};
use std::path::PathBuf;

/// How to load a document.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Extra folders to search for referenced files (images, includes).
    pub search_paths: Vec<PathBuf>,
    /// Instead of failing on unsupported nodes, leave out every output that depends on one
    /// (listed by [`Document::skipped`]). Malformed documents still fail.
    pub lenient: bool,
    /// The frame that `frame` and `time` nodes read (1 when not set).
    pub frame: Option<f32>,
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
