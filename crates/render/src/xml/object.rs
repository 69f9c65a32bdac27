//! The scene tree's plugin objects and their typed getters, which mark what the scene builder read.

use std::cell::Cell;
use std::collections::HashSet;
use std::rc::Rc;

use glam::{Mat4, Vec3};

use crate::error::{Error, Loc, Result};

/// The value of a typed parameter.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `<float>`.
    Float(f32),
    /// `<integer>`.
    Integer(i64),
    /// `<boolean>`.
    Boolean(bool),
    /// `<string>`.
    String(String),
    /// `<rgb>`, or a uniform `<spectrum value="x">` (stored as `(x, x, x)`).
    Rgb(Vec3),
    /// `<point>`.
    Point(Vec3),
    /// `<vector>`.
    Vector(Vec3),
    /// `<transform>`: the composed matrix.
    Transform(Mat4),
}

impl Value {
    /// The XML tag name of this kind of value ("float", "rgb", ...), for messages.
    pub fn kind(&self) -> &'static str {
        match self {
            Value::Float(_) => "float",
            Value::Integer(_) => "integer",
            Value::Boolean(_) => "boolean",
            Value::String(_) => "string",
            Value::Rgb(_) => "rgb",
            Value::Point(_) => "point",
            Value::Vector(_) => "vector",
            Value::Transform(_) => "transform",
        }
    }
}

/// A named, typed parameter of an object, with where it was written.
#[derive(Debug)]
pub struct Param {
    /// The `name` attribute.
    pub name: String,
    /// The parsed value.
    pub value: Value,
    /// Where the parameter's element starts.
    pub loc: Loc,
    pub(super) used: Cell<bool>,
}

impl Param {
    /// Whether a typed getter has read this parameter.
    pub fn is_used(&self) -> bool {
        self.used.get()
    }
}

/// A nested object (declared inside its parent, or brought in with `<ref>`).
#[derive(Debug)]
pub(super) struct Child {
    /// The name it goes by in the parent: the declared object's `name` attribute, or the
    /// `<ref>`'s.
    pub(super) name: Option<String>,
    pub(super) object: Rc<Object>,
    /// Where the nested element or the `<ref>` is.
    pub(super) loc: Loc,
    pub(super) via_ref: bool,
    pub(super) used: Cell<bool>,
}

/// One plugin object of the scene tree.
#[derive(Debug)]
pub struct Object {
    /// "scene", "shape", "bsdf", "texture", "emitter", "sensor", "film", "sampler",
    /// "integrator", "rfilter" (also "medium", "phase", "volume").
    pub tag: String,
    /// The `type` attribute ("" for the scene).
    pub plugin: String,
    /// The `id` attribute.
    pub id: Option<String>,
    /// The `name` attribute when nested as a named parameter, e.g.
    /// `<texture name="reflectance" ...>`.
    pub name: Option<String>,
    /// Where the object's element starts.
    pub loc: Loc,
    pub(super) params: Vec<Param>,
    pub(super) children: Vec<Child>,
    /// Set when some `<ref>` (or `<alias>`-ed ref) points at this object.
    pub(super) referenced: Cell<bool>,
}

impl Object {
    /// `bsdf 'diffuse' (id 'white')`, for messages.
    pub fn describe(&self) -> String {
        let mut s = if self.tag == "scene" { "scene".to_string() } else { format!("{} '{}'", self.tag, self.plugin) };
        if let Some(id) = &self.id {
            s.push_str(&format!(" (id '{id}')"));
        }
        s
    }

    /// An error at this object's element.
    pub fn error(&self, msg: impl Into<String>) -> Error {
        Error::at(&self.loc, msg)
    }

    /// An error at the parameter or named child `name` if present (else at the object).
    pub fn error_at(&self, name: &str, msg: impl Into<String>) -> Error {
        Error::at(self.loc_of(name), msg)
    }

    /// Where the parameter or named child `name` is written, or the object's own location.
    pub fn loc_of(&self, name: &str) -> &Loc {
        if let Some(p) = self.params.iter().find(|p| p.name == name) {
            &p.loc
        } else if let Some(c) = self.children.iter().find(|c| c.name.as_deref() == Some(name)) {
            &c.loc
        } else {
            &self.loc
        }
    }

    /// All parameters in document order (does not mark them used).
    pub fn params(&self) -> &[Param] {
        &self.params
    }

    /// The parameter `name`, without marking it used.
    pub fn param(&self, name: &str) -> Option<&Param> {
        self.params.iter().find(|p| p.name == name)
    }

    /// All nested objects in document order with the name each goes by here (does not mark
    /// them used).
    pub fn nested(&self) -> impl Iterator<Item = (Option<&str>, &Rc<Object>)> {
        self.children.iter().map(|c| (c.name.as_deref(), &c.object))
    }

    /// Whether a parameter or a named nested object `name` is present (does not mark it used).
    pub fn has(&self, name: &str) -> bool {
        self.params.iter().any(|p| p.name == name) || self.children.iter().any(|c| c.name.as_deref() == Some(name))
    }

    /// Finds parameter `name` and marks it used. A nested object of that name is not a
    /// parameter: it gives `None` here (ask [`Object::child_named`] for it).
    fn lookup(&self, name: &str) -> Option<&Param> {
        let p = self.params.iter().find(|p| p.name == name)?;
        p.used.set(true);
        Some(p)
    }

    fn type_error(p: &Param, expected: &str) -> Error {
        Error::at(&p.loc, format!("parameter '{}' must be {expected}, found {}", p.name, p.value.kind()))
    }

    /// Float parameter `name` (an `<integer>` is accepted too), or `default`.
    pub fn float(&self, name: &str, default: f32) -> Result<f32> {
        Ok(self.opt_float(name)?.unwrap_or(default))
    }

    /// Float parameter `name` (an `<integer>` is accepted too), if given.
    pub fn opt_float(&self, name: &str) -> Result<Option<f32>> {
        match self.lookup(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Float(f) => Ok(Some(f)),
                Value::Integer(i) => Ok(Some(i as f32)),
                _ => Err(Self::type_error(p, "a float")),
            },
        }
    }

    /// Integer parameter `name`, or `default`.
    pub fn int(&self, name: &str, default: i64) -> Result<i64> {
        Ok(self.opt_int(name)?.unwrap_or(default))
    }

    /// Integer parameter `name`, if given.
    pub fn opt_int(&self, name: &str) -> Result<Option<i64>> {
        match self.lookup(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Integer(i) => Ok(Some(i)),
                _ => Err(Self::type_error(p, "an integer")),
            },
        }
    }

    /// Boolean parameter `name`, or `default`.
    pub fn bool(&self, name: &str, default: bool) -> Result<bool> {
        match self.lookup(name) {
            None => Ok(default),
            Some(p) => match p.value {
                Value::Boolean(b) => Ok(b),
                _ => Err(Self::type_error(p, "a boolean")),
            },
        }
    }

    /// String parameter `name`, or `default`.
    pub fn string(&self, name: &str, default: &str) -> Result<String> {
        Ok(self.opt_string(name)?.unwrap_or_else(|| default.to_string()))
    }

    /// String parameter `name`, if given.
    pub fn opt_string(&self, name: &str) -> Result<Option<String>> {
        match self.lookup(name) {
            None => Ok(None),
            Some(p) => match &p.value {
                Value::String(s) => Ok(Some(s.clone())),
                _ => Err(Self::type_error(p, "a string")),
            },
        }
    }

    /// Colour parameter `name` or `default`: an `<rgb>`, a uniform `<spectrum>`, or a `<float>`
    /// (broadcast to all three channels). A nested `<texture name="...">` is not a colour:
    /// ask [`Object::child_named`] for it (this then returns `default`).
    pub fn rgb(&self, name: &str, default: Vec3) -> Result<Vec3> {
        Ok(self.opt_rgb(name)?.unwrap_or(default))
    }

    /// Colour parameter `name`, if given (see [`Object::rgb`]).
    pub fn opt_rgb(&self, name: &str) -> Result<Option<Vec3>> {
        match self.lookup(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Rgb(c) => Ok(Some(c)),
                Value::Float(f) => Ok(Some(Vec3::splat(f))),
                _ => Err(Self::type_error(p, "an rgb colour (or a float)")),
            },
        }
    }

    /// Point parameter `name` (a `<vector>` is accepted too, as in Mitsuba), or `default`.
    pub fn point(&self, name: &str, default: Vec3) -> Result<Vec3> {
        Ok(self.opt_point(name)?.unwrap_or(default))
    }

    /// Point parameter `name`, if given (see [`Object::point`]).
    pub fn opt_point(&self, name: &str) -> Result<Option<Vec3>> {
        match self.lookup(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Point(v) | Value::Vector(v) => Ok(Some(v)),
                _ => Err(Self::type_error(p, "a point")),
            },
        }
    }

    /// Vector parameter `name` (a `<point>` is accepted too, as in Mitsuba), or `default`.
    pub fn vector(&self, name: &str, default: Vec3) -> Result<Vec3> {
        Ok(self.opt_vector(name)?.unwrap_or(default))
    }

    /// Vector parameter `name`, if given (see [`Object::vector`]).
    pub fn opt_vector(&self, name: &str) -> Result<Option<Vec3>> {
        match self.lookup(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Point(v) | Value::Vector(v) => Ok(Some(v)),
                _ => Err(Self::type_error(p, "a vector")),
            },
        }
    }

    /// Transform parameter `name`, if given.
    pub fn transform(&self, name: &str) -> Result<Option<Mat4>> {
        match self.lookup(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Transform(m) => Ok(Some(m)),
                _ => Err(Self::type_error(p, "a transform")),
            },
        }
    }

    /// The nested objects (named or not, declared here or referenced) whose tag is `tag`, in
    /// document order; marks them used.
    pub fn children(&self, tag: &str) -> Vec<Rc<Object>> {
        self.children
            .iter()
            .filter(|c| c.object.tag == tag)
            .map(|c| {
                c.used.set(true);
                c.object.clone()
            })
            .collect()
    }

    /// The nested object (declared here or referenced) going by `name` here; marks it used.
    pub fn child_named(&self, name: &str) -> Option<Rc<Object>> {
        let c = self.children.iter().find(|c| c.name.as_deref() == Some(name))?;
        c.used.set(true);
        Some(c.object.clone())
    }

    /// Error naming the first (in document order) parameter or nested object that no getter
    /// asked for. A nested object declared here with an `id` that some `<ref>` points at counts
    /// as used (e.g. top-level `<bsdf id="white">` in the scene).
    pub fn check_unused(&self) -> Result<()> {
        let me = self.describe();
        let mut unused: Vec<(&Loc, String)> = Vec::new();
        for p in self.params.iter().filter(|p| !p.used.get()) {
            unused.push((&p.loc, format!("unused parameter '{}' in {me}", p.name)));
        }
        for c in &self.children {
            if c.used.get() || (!c.via_ref && c.object.referenced.get()) {
                continue;
            }
            let what = if c.via_ref { format!("reference to {}", c.object.describe()) } else { c.object.describe() };
            let msg = match &c.name {
                Some(n) => format!("unused {what} (as '{n}') in {me}"),
                None => format!("unused {what} in {me}"),
            };
            unused.push((&c.loc, msg));
        }
        // First in document order (items from an <include>d file sort by their own lines).
        match unused.into_iter().min_by_key(|(l, _)| (l.line, l.col)) {
            None => Ok(()),
            Some((loc, msg)) => Err(Error::at(loc, msg)),
        }
    }

    /// [`Object::check_unused`] on this object and, recursively, on every nested object that
    /// counts as used (each shared object once).
    pub fn check_unused_tree(&self) -> Result<()> {
        let mut seen = HashSet::new();
        self.check_tree(&mut seen)
    }

    fn check_tree(&self, seen: &mut HashSet<*const Object>) -> Result<()> {
        if !seen.insert(self as *const Object) {
            return Ok(());
        }
        self.check_unused()?;
        for c in &self.children {
            if c.used.get() || (!c.via_ref && c.object.referenced.get()) {
                c.object.check_tree(seen)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::xml::testing::{parse, scene};

    #[test]
    fn xml_params_and_getters() {
        let s = parse(&scene(
            r#"<bsdf type="roughconductor" id="b">
                <float name="alpha" value=" 0.25 "/>
                <integer name="n" value="-7"/>
                <boolean name="flag" value="TRUE"/>
                <string name="distribution" value="ggx"/>
                <rgb name="eta" value="1,2 3"/>
                <rgb name="k" value="0.5"/>
                <spectrum name="spec" value="0.25"/>
                <float name="fl" value="2"/>
                <point name="c" value="1, 2, 3"/>
                <point name="c2" y="5"/>
                <vector name="d" value="4"/>
            </bsdf>"#,
        ))
        .unwrap();
        let b = s.children("bsdf").remove(0);
        assert_eq!(b.plugin, "roughconductor");
        assert_eq!(b.id.as_deref(), Some("b"));
        assert_eq!(b.loc.line, 2);
        assert_eq!(b.float("alpha", 0.0).unwrap(), 0.25);
        assert_eq!(b.float("missing", 1.5).unwrap(), 1.5);
        assert_eq!(b.opt_float("missing2").unwrap(), None);
        assert_eq!(b.int("n", 0).unwrap(), -7);
        assert!(b.bool("flag", false).unwrap());
        assert_eq!(b.string("distribution", "beckmann").unwrap(), "ggx");
        assert_eq!(b.rgb("eta", Vec3::ZERO).unwrap(), Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(b.rgb("k", Vec3::ZERO).unwrap(), Vec3::splat(0.5));
        assert_eq!(b.rgb("spec", Vec3::ZERO).unwrap(), Vec3::splat(0.25));
        assert_eq!(b.rgb("fl", Vec3::ZERO).unwrap(), Vec3::splat(2.0));
        assert_eq!(b.point("c", Vec3::ZERO).unwrap(), Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(b.point("c2", Vec3::ONE).unwrap(), Vec3::new(0.0, 5.0, 0.0));
        assert_eq!(b.vector("d", Vec3::ZERO).unwrap(), Vec3::splat(4.0));
        b.check_unused().unwrap();
        // Wrong type: error at the parameter's line with a clear message.
        let e = b.int("alpha", 0).unwrap_err().to_string();
        assert!(e.starts_with("test.xml:3:") && e.contains("parameter 'alpha' must be an integer, found float"), "{e}");
        let e = b.float("distribution", 0.0).unwrap_err().to_string();
        assert!(
            e.starts_with("test.xml:6:") && e.contains("parameter 'distribution' must be a float, found string"),
            "{e}"
        );
    }

    #[test]
    fn xml_unused_detection() {
        let s = parse(&scene(
            r#"<bsdf type="diffuse">
                <rgb name="reflectance" value="0.5"/>
                <float name="foo" value="1"/>
                <texture type="bitmap" name="bar">
                    <string name="filename" value="a.png"/>
                </texture>
            </bsdf>"#,
        ))
        .unwrap();
        let b = s.children("bsdf").remove(0);
        assert!(b.has("foo") && b.has("bar") && !b.has("baz"));
        b.rgb("reflectance", Vec3::ZERO).unwrap();
        let e = b.check_unused().unwrap_err().to_string();
        assert!(e.starts_with("test.xml:4:"), "{e}");
        assert!(e.contains("unused parameter 'foo' in bsdf 'diffuse'"), "{e}");
        b.float("foo", 0.0).unwrap();
        let e = b.check_unused().unwrap_err().to_string();
        assert!(
            e.starts_with("test.xml:5:") && e.contains("unused texture 'bitmap' (as 'bar') in bsdf 'diffuse'"),
            "{e}"
        );
        let t = b.child_named("bar").unwrap();
        b.check_unused().unwrap();
        // The tree check goes into the texture, whose filename is still unread.
        let e = s.check_unused_tree().unwrap_err().to_string();
        assert!(e.starts_with("test.xml:6:") && e.contains("unused parameter 'filename' in texture 'bitmap'"), "{e}");
        t.string("filename", "").unwrap();
        s.check_unused_tree().unwrap();
        // The scene itself: the bsdf was asked for above.
        s.check_unused().unwrap();
    }
}
