//! Mitsuba 3 XML reading.
//!
//! [`parse_file`] / [`parse_str`] turn a Mitsuba 3 scene file into a tree of plugin [`Object`]s
//! (`<scene>`, `<shape>`, `<bsdf>`, ...) with typed, located parameters. This module knows
//! nothing of the renderer's scene types: the scene builder asks each object for the
//! parameters it understands ([`Object::float`], [`Object::rgb`], [`Object::child_named`], ...),
//! which marks them used, and then calls [`Object::check_unused`] so that misspelt or
//! unsupported parameters are reported, as Mitsuba does.
//!
//! Supported: `<default>` and `$name` substitution (command-line defines win), `id`/`<ref>`
//! (references to objects declared earlier in the file), `<alias>`, `<include>`, all typed
//! parameters (`float`, `integer`, `boolean`, `string`, `rgb`, uniform `spectrum`, `point`,
//! `vector`, `transform` with `translate`/`rotate`/`scale`/`matrix`/`lookat`), and the
//! camelCase-to-snake_case parameter renaming Mitsuba applies to version 0.x/1.x files.
//! Not supported (clear errors): `<path>`, spectra given as wavelength lists or files.

mod object;
mod params;
mod parser;
mod transform;

pub use object::{Object, Param, Value};
pub use parser::{parse_file, parse_str, MAX_OBJECT_DEPTH, MAX_SUBSTITUTED_BYTES};
pub(crate) use parser::{parse_file_with_includes, parse_with_includes};

pub use graph::text::{excerpt, EXCERPT_CHARS};

/// The tags that create plugin objects (besides the root `<scene>`).
pub const OBJECT_TAGS: &[&str] = &[
    "shape",
    "bsdf",
    "texture",
    "emitter",
    "sensor",
    "film",
    "sampler",
    "integrator",
    "rfilter",
    "medium",
    "phase",
    "volume",
];

/// The tags that define a typed parameter.
const PARAM_TAGS: &[&str] =
    &["float", "integer", "boolean", "string", "rgb", "spectrum", "point", "vector", "transform"];

/// The operations allowed inside `<transform>`.
const TRANSFORM_OPS: &[&str] = &["translate", "rotate", "scale", "matrix", "lookat"];

#[cfg(test)]
mod testing {
    //! What the unit tests of every file here share: a scene around a body, and its errors.

    use std::path::PathBuf;
    use std::rc::Rc;

    use super::{parse_str, Object};
    use crate::error::Result;

    pub(super) fn p() -> PathBuf {
        PathBuf::from("test.xml")
    }

    pub(super) fn parse(text: &str) -> Result<Rc<Object>> {
        parse_str(text, &p(), &[])
    }

    pub(super) fn scene(body: &str) -> String {
        format!("<scene version=\"3.0.0\">\n{body}\n</scene>")
    }

    /// Parses `text`, expects an error whose message contains `line` (as `test.xml:LINE:`) and
    /// every piece of `needles`.
    pub(super) fn expect_err(text: &str, line: u32, needles: &[&str]) -> String {
        let err = parse(text).expect_err("expected an error").to_string();
        let at = format!("test.xml:{line}:");
        assert!(err.starts_with(&at), "error {err:?} should start with {at:?}");
        for n in needles {
            assert!(err.contains(n), "error {err:?} should contain {n:?}");
        }
        err
    }
}

#[cfg(test)]
mod excerpt_tests {
    #[test]
    fn long_values_are_cut_and_short_ones_kept() {
        assert_eq!(super::excerpt("0.5"), "0.5");
        let long = "x".repeat(50_000_000);
        let e = super::excerpt(&long);
        assert!(e.len() < 100 && e.ends_with("(50000000 bytes)"), "{e}");
        // Cuts fall on character boundaries.
        let wide = "é".repeat(100);
        assert!(super::excerpt(&wide).starts_with(&"é".repeat(super::EXCERPT_CHARS)));
    }
}
