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

use std::cell::Cell;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::Arc;

use glam::{Mat3, Mat4, Vec3};

use crate::error::{Error, Loc, Result};

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

/// Deepest `<include>` nesting accepted (guards against recursive includes).
const MAX_INCLUDE_DEPTH: usize = 16;

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
    used: Cell<bool>,
}

impl Param {
    /// Whether a typed getter has read this parameter.
    pub fn is_used(&self) -> bool {
        self.used.get()
    }
}

/// A nested object (declared inside its parent, or brought in with `<ref>`).
#[derive(Debug)]
struct Child {
    /// The name it goes by in the parent: the declared object's `name` attribute, or the
    /// `<ref>`'s.
    name: Option<String>,
    object: Rc<Object>,
    /// Where the nested element or the `<ref>` is.
    loc: Loc,
    via_ref: bool,
    used: Cell<bool>,
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
    params: Vec<Param>,
    children: Vec<Child>,
    /// Set when some `<ref>` (or `<alias>`-ed ref) points at this object.
    referenced: Cell<bool>,
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

/// Parses the scene file at `path`. `defines` are `-D name=value` pairs from the command line:
/// they override the scene's `<default>`s.
pub fn parse_file(path: &Path, defines: &[(String, String)]) -> Result<Rc<Object>> {
    let text =
        std::fs::read_to_string(path).map_err(|e| Error::in_file(path, format!("cannot read scene file: {e}")))?;
    parse_str(&text, path, defines)
}

/// Parses a scene given as text; `virtual_path` names it in messages and is the base for
/// relative `<include>` file names.
pub fn parse_str(text: &str, virtual_path: &Path, defines: &[(String, String)]) -> Result<Rc<Object>> {
    for (name, _) in defines {
        if name.is_empty() || !name.chars().all(is_var_char) {
            return Err(Error::plain(format!("invalid define name '{name}': use letters, digits and '_' only")));
        }
    }
    let mut parser = Parser { defines: defines.to_vec(), defaults: Vec::new(), ids: HashMap::new(), include_depth: 0 };
    let file = Arc::new(virtual_path.to_path_buf());
    let doc = parse_xml(text, &file)?;
    let root = doc.root_element();
    let src = Src { file, doc: &doc, old_format: false };
    let root_loc = src.loc(root.range().start);
    if root.tag_name().name() != "scene" {
        return Err(Error::at(
            &root_loc,
            format!("the root element must be <scene version=\"3.0.0\">, found <{}>", root.tag_name().name()),
        ));
    }
    let old_format = check_version(&src, root, true)?;
    let src = Src { old_format, ..src };
    parser.build_object(&src, root, "scene")
}

fn is_var_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

fn parse_xml<'a>(text: &'a str, file: &Arc<PathBuf>) -> Result<roxmltree::Document<'a>> {
    roxmltree::Document::parse(text).map_err(|e| {
        let pos = e.pos();
        let msg = e.to_string();
        let suffix = format!(" at {pos}");
        let msg = msg.strip_suffix(&suffix).unwrap_or(&msg).to_string();
        Error::at(&Loc::new(file.clone(), pos.row, pos.col), format!("malformed XML: {msg}"))
    })
}

/// Checks the `version` attribute of a `<scene>` element; returns whether the file uses the
/// pre-2.0 format (camelCase parameter names).
fn check_version(src: &Src, node: roxmltree::Node, required: bool) -> Result<bool> {
    let loc = src.loc(node.range().start);
    let Some(attr) = node.attribute_node("version") else {
        if required {
            return Err(Error::at(
                &loc,
                "missing 'version' attribute on <scene> (expected e.g. <scene version=\"3.0.0\">)",
            ));
        }
        return Ok(false);
    };
    let vloc = src.loc(attr.range_value().start);
    let value = attr.value();
    let parts: Vec<&str> = value.trim().split('.').collect();
    let nums: Option<Vec<u32>> = parts.iter().map(|p| p.trim().parse::<u32>().ok()).collect();
    let nums = match nums {
        Some(n) if n.len() == 3 => n,
        _ => {
            return Err(Error::at(
                &vloc,
                format!("invalid scene version '{value}' (expected major.minor.patch, e.g. \"3.0.0\")"),
            ));
        }
    };
    if nums[0] > 3 {
        return Err(Error::at(
            &vloc,
            format!("scene version {value} is newer than the supported Mitsuba 3 format (3.x.x)"),
        ));
    }
    Ok(nums[0] < 2)
}

/// One source file being read.
struct Src<'a, 'input> {
    file: Arc<PathBuf>,
    doc: &'a roxmltree::Document<'input>,
    /// Version < 2.0.0: parameter names are camelCase and get renamed.
    old_format: bool,
}

impl Src<'_, '_> {
    fn loc(&self, byte: usize) -> Loc {
        let p = self.doc.text_pos_at(byte);
        Loc::new(self.file.clone(), p.row, p.col)
    }
}

/// An attribute after `$` substitution.
struct Attr {
    name: String,
    value: String,
    /// Where the value starts.
    loc: Loc,
}

/// An element's tag, location and substituted attributes.
struct Elem {
    tag: String,
    loc: Loc,
    attrs: Vec<Attr>,
}

impl Elem {
    fn get(&self, name: &str) -> Option<&Attr> {
        self.attrs.iter().find(|a| a.name == name)
    }

    fn require(&self, name: &str, example: &str) -> Result<&Attr> {
        self.get(name).ok_or_else(|| {
            Error::at(&self.loc, format!("<{}> requires a '{name}' attribute (e.g. {example})", self.tag))
        })
    }

    fn allow(&self, allowed: &[&str]) -> Result<()> {
        for a in &self.attrs {
            if !allowed.contains(&a.name.as_str()) {
                return Err(Error::at(
                    &a.loc,
                    format!("unexpected attribute '{}' on <{}> (allowed: {})", a.name, self.tag, allowed.join(", ")),
                ));
            }
        }
        Ok(())
    }
}

/// camelCase → snake_case, as Mitsuba's upgrade of version 0.x/1.x scenes does.
fn snake_case(name: &str) -> String {
    let mut out = String::with_capacity(name.len() + 4);
    let mut prev_lower = false;
    for c in name.chars() {
        if c.is_ascii_uppercase() {
            if prev_lower {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
            prev_lower = false;
        } else {
            out.push(c);
            prev_lower = c.is_ascii_lowercase();
        }
    }
    out
}

/// Splits a list of numbers separated by commas and/or whitespace.
fn tokens(s: &str) -> Vec<&str> {
    s.split(|c: char| c == ',' || c.is_whitespace()).filter(|t| !t.is_empty()).collect()
}

fn parse_f32(tok: &str, attr: &Attr, tag: &str) -> Result<f32> {
    let v: f32 = tok.parse().map_err(|_| {
        Error::at(
            &attr.loc,
            format!(
                "invalid number '{tok}' in attribute '{}' of <{tag}> (expected a decimal number such as 0.5)",
                attr.name
            ),
        )
    })?;
    if !v.is_finite() {
        return Err(Error::at(
            &attr.loc,
            format!("number '{tok}' in attribute '{}' of <{tag}> is not finite", attr.name),
        ));
    }
    Ok(v)
}

/// Parses an attribute holding a list of numbers whose count must be one of `counts`.
fn parse_list(attr: &Attr, tag: &str, counts: &[usize]) -> Result<Vec<f32>> {
    let toks = tokens(&attr.value);
    if !counts.contains(&toks.len()) {
        let want: Vec<String> = counts.iter().map(|c| c.to_string()).collect();
        return Err(Error::at(
            &attr.loc,
            format!(
                "attribute '{}' of <{tag}> must hold {} number(s), found {} ('{}')",
                attr.name,
                want.join(" or "),
                toks.len(),
                attr.value
            ),
        ));
    }
    toks.iter().map(|t| parse_f32(t, attr, tag)).collect()
}

/// Reads `value="v"`, `value="x, y, z"` or separate `x`/`y`/`z` attributes (missing ones are
/// `default`).
fn parse_xyz(e: &Elem, default: f32) -> Result<Vec3> {
    if let Some(v) = e.get("value") {
        if let Some(a) = ["x", "y", "z"].iter().find_map(|n| e.get(n)) {
            return Err(Error::at(&a.loc, format!("<{}> cannot mix 'value' with 'x'/'y'/'z' attributes", e.tag)));
        }
        let l = parse_list(v, &e.tag, &[1, 3])?;
        return Ok(if l.len() == 1 { Vec3::splat(l[0]) } else { Vec3::new(l[0], l[1], l[2]) });
    }
    let mut out = Vec3::splat(default);
    for (i, n) in ["x", "y", "z"].iter().enumerate() {
        if let Some(a) = e.get(n) {
            let l = parse_list(a, &e.tag, &[1])?;
            out[i] = l[0];
        }
    }
    Ok(out)
}

/// Builds an object's parameters and children.
#[derive(Default)]
struct Builder {
    params: Vec<Param>,
    children: Vec<Child>,
}

impl Builder {
    fn check_name_free(&self, name: &str, loc: &Loc) -> Result<()> {
        let prev = self
            .params
            .iter()
            .find(|p| p.name == name)
            .map(|p| &p.loc)
            .or_else(|| self.children.iter().find(|c| c.name.as_deref() == Some(name)).map(|c| &c.loc));
        match prev {
            Some(prev) => {
                Err(Error::at(loc, format!("parameter '{name}' is specified more than once (first at {prev})")))
            }
            None => Ok(()),
        }
    }

    fn add_param(&mut self, name: String, value: Value, loc: Loc) -> Result<()> {
        self.check_name_free(&name, &loc)?;
        self.params.push(Param { name, value, loc, used: Cell::new(false) });
        Ok(())
    }

    fn add_child(&mut self, name: Option<String>, object: Rc<Object>, loc: Loc, via_ref: bool) -> Result<()> {
        if let Some(n) = &name {
            self.check_name_free(n, &loc)?;
        }
        self.children.push(Child { name, object, loc, via_ref, used: Cell::new(false) });
        Ok(())
    }
}

struct Parser {
    /// Command-line defines (win over `<default>`s).
    defines: Vec<(String, String)>,
    /// `<default>`s seen so far.
    defaults: Vec<(String, String)>,
    /// Declared ids (and aliases): the object and where the id was declared.
    ids: HashMap<String, (Rc<Object>, Loc)>,
    include_depth: usize,
}

impl Parser {
    fn variable(&self, name: &str) -> Option<&str> {
        self.defines.iter().chain(self.defaults.iter()).find(|(n, _)| n == name).map(|(_, v)| v.as_str())
    }

    /// Replaces `$name` by the value of variable `name`.
    fn substitute(&self, s: &str, loc: &Loc) -> Result<String> {
        if !s.contains('$') {
            return Ok(s.to_string());
        }
        let mut out = String::with_capacity(s.len());
        let mut rest = s;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            let len = after.find(|c: char| !is_var_char(c)).unwrap_or(after.len());
            let name = &after[..len];
            if name.is_empty() {
                return Err(Error::at(loc, format!("'$' not followed by a variable name in \"{s}\"")));
            }
            match self.variable(name) {
                Some(v) => out.push_str(v),
                None => {
                    return Err(Error::at(
                        loc,
                        format!(
                            "undefined variable '${name}' in \"{s}\" (declare it with <default name=\"{name}\" value=\"...\"/> or pass -D {name}=...)"
                        ),
                    ));
                }
            }
            rest = &after[len..];
        }
        out.push_str(rest);
        Ok(out)
    }

    /// Reads an element's tag, location and attributes (with `$` substituted).
    fn elem(&self, src: &Src, node: roxmltree::Node) -> Result<Elem> {
        let mut tag = node.tag_name().name().to_string();
        if src.old_format && tag == "lookAt" {
            tag = "lookat".to_string();
        }
        let loc = src.loc(node.range().start);
        let mut attrs = Vec::new();
        for a in node.attributes() {
            let aloc = src.loc(a.range_value().start);
            let mut value = self.substitute(a.value(), &aloc)?;
            if src.old_format && a.name() == "name" && tag != "default" {
                value = snake_case(&value);
            }
            attrs.push(Attr { name: a.name().to_string(), value, loc: aloc });
        }
        Ok(Elem { tag, loc, attrs })
    }

    fn build_object(&mut self, src: &Src, node: roxmltree::Node, tag: &str) -> Result<Rc<Object>> {
        let e = self.elem(src, node)?;
        let (plugin, id, name) = if tag == "scene" {
            e.allow(&["version"])?;
            (String::new(), None, None)
        } else {
            e.allow(&["type", "id", "name"])?;
            let ty = e.require("type", &format!("<{tag} type=\"...\">, naming the plugin"))?;
            if ty.value.trim().is_empty() {
                return Err(Error::at(&ty.loc, format!("empty 'type' attribute on <{tag}>")));
            }
            let id = match e.get("id") {
                Some(a) if a.value.is_empty() => {
                    return Err(Error::at(&a.loc, format!("empty 'id' attribute on <{tag}>")));
                }
                Some(a) => {
                    if let Some((_, prev)) = self.ids.get(&a.value) {
                        return Err(Error::at(
                            &a.loc,
                            format!("duplicate id '{}' (first declared at {prev})", a.value),
                        ));
                    }
                    Some(a.value.clone())
                }
                None => None,
            };
            (ty.value.clone(), id, e.get("name").map(|a| a.value.clone()))
        };
        let mut b = Builder::default();
        let desc = if tag == "scene" { "<scene>".to_string() } else { format!("<{tag} type=\"{plugin}\">") };
        for ch in node.children() {
            self.child(src, ch, &mut b, &desc)?;
        }
        let obj = Rc::new(Object {
            tag: tag.to_string(),
            plugin,
            id: id.clone(),
            name,
            loc: e.loc.clone(),
            params: b.params,
            children: b.children,
            referenced: Cell::new(false),
        });
        if let Some(id) = id {
            // Re-check: a nested object may have taken the id meanwhile.
            if let Some((_, prev)) = self.ids.get(&id) {
                return Err(Error::at(&e.loc, format!("duplicate id '{id}' (first declared at {prev})")));
            }
            self.ids.insert(id, (obj.clone(), e.loc.clone()));
        }
        Ok(obj)
    }

    /// Handles one child node of an object element.
    fn child(&mut self, src: &Src, node: roxmltree::Node, b: &mut Builder, parent: &str) -> Result<()> {
        match node.node_type() {
            roxmltree::NodeType::Element => {}
            roxmltree::NodeType::Text => {
                let t = node.text().unwrap_or("").trim();
                if !t.is_empty() {
                    let raw = &src.doc.input_text()[node.range()];
                    let lead = raw.len() - raw.trim_start().len();
                    return Err(Error::at(
                        &src.loc(node.range().start + lead),
                        format!("unexpected text \"{t}\" inside {parent}"),
                    ));
                }
                return Ok(());
            }
            _ => return Ok(()),
        }
        let raw_tag = node.tag_name().name();
        if OBJECT_TAGS.contains(&raw_tag) {
            let obj = self.build_object(src, node, raw_tag)?;
            let loc = obj.loc.clone();
            return b.add_child(obj.name.clone(), obj, loc, false);
        }
        let e = self.elem(src, node)?;
        let tag = e.tag.as_str();
        match tag {
            "scene" => Err(Error::at(&e.loc, "<scene> can only be the root element")),
            "ref" => {
                e.allow(&["id", "name"])?;
                let id = e.require("id", "<ref id=\"white\"/>")?;
                let Some((obj, _)) = self.ids.get(&id.value) else {
                    return Err(Error::at(
                        &id.loc,
                        format!(
                            "unknown id '{}' in <ref> (objects must be declared with id=\"{}\" before they are referenced)",
                            id.value, id.value
                        ),
                    ));
                };
                obj.referenced.set(true);
                let obj = obj.clone();
                b.add_child(e.get("name").map(|a| a.value.clone()), obj, e.loc.clone(), true)
            }
            "default" => {
                e.allow(&["name", "value"])?;
                let name = e.require("name", "<default name=\"spp\" value=\"16\"/>")?;
                let value = e.require("value", "<default name=\"spp\" value=\"16\"/>")?;
                if name.value.is_empty() || !name.value.chars().all(is_var_char) {
                    return Err(Error::at(
                        &name.loc,
                        format!("invalid variable name '{}' in <default> (use letters, digits and '_')", name.value),
                    ));
                }
                if self.variable(&name.value).is_none() {
                    self.defaults.push((name.value.clone(), value.value.clone()));
                }
                Ok(())
            }
            "alias" => {
                e.allow(&["id", "as"])?;
                let id = e.require("id", "<alias id=\"a\" as=\"b\"/>")?;
                let to = e.require("as", "<alias id=\"a\" as=\"b\"/>")?;
                let Some((obj, _)) = self.ids.get(&id.value) else {
                    return Err(Error::at(&id.loc, format!("unknown id '{}' in <alias>", id.value)));
                };
                if let Some((_, prev)) = self.ids.get(&to.value) {
                    return Err(Error::at(
                        &to.loc,
                        format!("duplicate id '{}' (first declared at {prev})", to.value),
                    ));
                }
                let obj = obj.clone();
                self.ids.insert(to.value.clone(), (obj, e.loc.clone()));
                Ok(())
            }
            "include" => self.include(src, &e, b, parent),
            "path" => Err(Error::at(&e.loc, "<path> (extra search folders) is not supported")),
            t if PARAM_TAGS.contains(&t) => self.param(src, node, &e, b),
            t if TRANSFORM_OPS.contains(&t) => Err(Error::at(
                &e.loc,
                format!("<{t}> can only appear inside a <transform name=\"...\">"),
            )),
            t => Err(Error::at(
                &e.loc,
                format!(
                    "unknown tag <{t}> inside {parent}; expected a parameter ({}), a nested object ({}), or <ref>, <default>, <alias>, <include>",
                    PARAM_TAGS.join(", "),
                    OBJECT_TAGS.join(", ")
                ),
            )),
        }
    }

    fn include(&mut self, src: &Src, e: &Elem, b: &mut Builder, parent: &str) -> Result<()> {
        e.allow(&["filename"])?;
        let f = e.require("filename", "<include filename=\"part.xml\"/>")?;
        if self.include_depth >= MAX_INCLUDE_DEPTH {
            return Err(Error::at(
                &e.loc,
                format!("<include> nested more than {MAX_INCLUDE_DEPTH} deep (recursive include?)"),
            ));
        }
        let mut path = PathBuf::from(&f.value);
        if path.is_relative() {
            if let Some(dir) = src.file.parent() {
                path = dir.join(path);
            }
        }
        let text = std::fs::read_to_string(&path)
            .map_err(|err| Error::at(&f.loc, format!("cannot read included file '{}': {err}", path.display())))?;
        let file = Arc::new(path);
        let doc = parse_xml(&text, &file)?;
        let root = doc.root_element();
        let inner = Src { file, doc: &doc, old_format: false };
        self.include_depth += 1;
        let result = (|| {
            let rtag = root.tag_name().name();
            if rtag == "scene" {
                let old_format = check_version(&inner, root, false)?;
                let inner = Src { old_format, ..inner };
                for ch in root.children() {
                    self.child(&inner, ch, b, parent)?;
                }
                Ok(())
            } else if OBJECT_TAGS.contains(&rtag) {
                let obj = self.build_object(&inner, root, rtag)?;
                let loc = obj.loc.clone();
                b.add_child(obj.name.clone(), obj, loc, false)
            } else {
                Err(Error::at(
                    &inner.loc(root.range().start),
                    format!("an included file must hold a <scene> or an object, found <{rtag}>"),
                ))
            }
        })();
        self.include_depth -= 1;
        result
    }

    fn param(&mut self, src: &Src, node: roxmltree::Node, e: &Elem, b: &mut Builder) -> Result<()> {
        let tag = e.tag.as_str();
        let example = match tag {
            "float" => "<float name=\"alpha\" value=\"0.1\"/>",
            "integer" => "<integer name=\"max_depth\" value=\"8\"/>",
            "boolean" => "<boolean name=\"hide_emitters\" value=\"true\"/>",
            "string" => "<string name=\"filename\" value=\"mesh.obj\"/>",
            "rgb" => "<rgb name=\"reflectance\" value=\"0.5, 0.5, 0.5\"/>",
            "spectrum" => "<spectrum name=\"reflectance\" value=\"0.5\"/>",
            "point" => "<point name=\"center\" x=\"0\" y=\"1\" z=\"0\"/>",
            "vector" => "<vector name=\"direction\" x=\"0\" y=\"-1\" z=\"0\"/>",
            _ => "<transform name=\"to_world\"> ... </transform>",
        };
        match tag {
            "point" | "vector" => e.allow(&["name", "value", "x", "y", "z"])?,
            "spectrum" => e.allow(&["name", "value", "filename"])?,
            "transform" => e.allow(&["name"])?,
            _ => e.allow(&["name", "value"])?,
        }
        let name = e.require("name", example)?.value.clone();
        if tag != "transform" && tag != "point" && tag != "vector" && tag != "spectrum" {
            e.require("value", example)?;
        }
        // Only <transform> may have element children.
        if let Some(ch) = node.children().find(|c| c.is_element()).filter(|_| tag != "transform") {
            return Err(Error::at(
                &src.loc(ch.range().start),
                format!("<{}> cannot occur inside the parameter <{tag} name=\"{name}\">", ch.tag_name().name()),
            ));
        }
        let value = match tag {
            "float" => {
                let a = e.get("value").expect("checked");
                let t = a.value.trim();
                Value::Float(parse_f32(t, a, tag)?)
            }
            "integer" => {
                let a = e.get("value").expect("checked");
                let t = a.value.trim();
                Value::Integer(t.parse::<i64>().map_err(|_| {
                    Error::at(
                        &a.loc,
                        format!("invalid integer '{t}' for parameter '{name}' (expected a whole number such as 16)"),
                    )
                })?)
            }
            "boolean" => {
                let a = e.get("value").expect("checked");
                match a.value.trim().to_ascii_lowercase().as_str() {
                    "true" => Value::Boolean(true),
                    "false" => Value::Boolean(false),
                    _ => {
                        return Err(Error::at(
                            &a.loc,
                            format!(
                                "invalid boolean '{}' for parameter '{name}' (expected \"true\" or \"false\")",
                                a.value
                            ),
                        ));
                    }
                }
            }
            "string" => Value::String(e.get("value").expect("checked").value.clone()),
            "rgb" => {
                let a = e.get("value").expect("checked");
                let l = parse_list(a, tag, &[1, 3])?;
                Value::Rgb(if l.len() == 1 { Vec3::splat(l[0]) } else { Vec3::new(l[0], l[1], l[2]) })
            }
            "spectrum" => {
                if let Some(f) = e.get("filename") {
                    return Err(Error::at(
                        &f.loc,
                        "spectra read from files are not supported (only a uniform <spectrum value=\"x\"/> or <rgb>)",
                    ));
                }
                let a = e.require("value", example)?;
                let toks = tokens(&a.value);
                if toks.len() != 1 || toks[0].contains(':') {
                    return Err(Error::at(
                        &a.loc,
                        format!(
                            "only uniform spectra (a single value) are supported, found \"{}\"; wavelength:value lists are not supported (use <rgb> instead)",
                            a.value
                        ),
                    ));
                }
                Value::Rgb(Vec3::splat(parse_f32(toks[0], a, tag)?))
            }
            "point" => Value::Point(parse_xyz(e, 0.0)?),
            "vector" => Value::Vector(parse_xyz(e, 0.0)?),
            _ => Value::Transform(self.transform(src, node, e, &name)?),
        };
        b.add_param(name, value, e.loc.clone())
    }

    /// Composes the operations of a `<transform>`: each left-multiplies the result so far.
    fn transform(&self, src: &Src, node: roxmltree::Node, e: &Elem, name: &str) -> Result<Mat4> {
        let mut m = Mat4::IDENTITY;
        for ch in node.children() {
            match ch.node_type() {
                roxmltree::NodeType::Element => {}
                roxmltree::NodeType::Text => {
                    let t = ch.text().unwrap_or("").trim();
                    if !t.is_empty() {
                        return Err(Error::at(
                            &src.loc(ch.range().start),
                            format!("unexpected text \"{t}\" inside <transform name=\"{name}\">"),
                        ));
                    }
                    continue;
                }
                _ => continue,
            }
            let op = self.elem(src, ch)?;
            let t = match op.tag.as_str() {
                "translate" => {
                    op.allow(&["value", "x", "y", "z"])?;
                    Mat4::from_translation(parse_xyz(&op, 0.0)?)
                }
                "scale" => {
                    op.allow(&["value", "x", "y", "z"])?;
                    Mat4::from_scale(parse_xyz(&op, 1.0)?)
                }
                "rotate" => {
                    op.allow(&["value", "x", "y", "z", "angle"])?;
                    let axis = parse_xyz(&op, 0.0)?;
                    let a = op.require("angle", "<rotate y=\"1\" angle=\"45\"/>")?;
                    let angle = parse_list(a, "rotate", &[1])?[0];
                    if axis.length_squared() == 0.0 {
                        return Err(Error::at(
                            &op.loc,
                            "<rotate> needs a non-zero axis (e.g. <rotate y=\"1\" angle=\"45\"/>)",
                        ));
                    }
                    Mat4::from_axis_angle(axis.normalize(), angle.to_radians())
                }
                "matrix" => {
                    op.allow(&["value"])?;
                    let a = op.require("value", "<matrix value=\"1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\"/>")?;
                    let l = parse_list(a, "matrix", &[16, 9])?;
                    let mat = if l.len() == 16 {
                        Mat4::from_cols_slice(&l).transpose()
                    } else {
                        Mat4::from_mat3(Mat3::from_cols_slice(&l).transpose())
                    };
                    if is_singular(&mat) {
                        return Err(Error::at(
                            &a.loc,
                            format!(
                                "<matrix> is singular (determinant {:e}); it cannot place an object",
                                mat.determinant()
                            ),
                        ));
                    }
                    mat
                }
                "lookat" => {
                    op.allow(&["origin", "target", "up"])?;
                    let ex = "<lookat origin=\"0, 0, 5\" target=\"0, 0, 0\" up=\"0, 1, 0\"/>";
                    let vec3 = |a: &Attr| -> Result<Vec3> {
                        let l = parse_list(a, "lookat", &[3])?;
                        Ok(Vec3::new(l[0], l[1], l[2]))
                    };
                    let origin = vec3(op.require("origin", ex)?)?;
                    let target = vec3(op.require("target", ex)?)?;
                    let up = match op.get("up") {
                        Some(a) => Some((vec3(a)?, a.loc.clone())),
                        None => None,
                    };
                    look_at(origin, target, up, &op.loc)?
                }
                t => {
                    return Err(Error::at(
                        &op.loc,
                        format!(
                            "unexpected <{t}> inside <transform name=\"{name}\">; expected one of: {}",
                            TRANSFORM_OPS.join(", ")
                        ),
                    ));
                }
            };
            m = t * m;
        }
        if !m.is_finite() {
            return Err(Error::at(&e.loc, format!("transform '{name}' is not finite")));
        }
        if is_singular(&m) {
            return Err(Error::at(
                &e.loc,
                format!("transform '{name}' is singular (determinant {:e}, e.g. a zero scale)", m.determinant()),
            ));
        }
        Ok(m)
    }
}

/// Whether `m`'s determinant is negligible relative to the size of its entries.
/// For an affine matrix only the 3×3 linear part counts (a translation cannot make it
/// singular), compared with the cube of its largest entry; a projective matrix is judged whole.
fn is_singular(m: &Mat4) -> bool {
    let affine = m.row(3) == glam::Vec4::W;
    let m64 = m.as_dmat4();
    let (det, size, power) = if affine {
        let l = glam::DMat3::from_mat4(m64);
        let size = l.to_cols_array().iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
        (l.determinant(), size, 3)
    } else {
        let size = m64.to_cols_array().iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
        (m64.determinant(), size, 4)
    };
    size == 0.0 || det.abs() <= 1e-10 * size.powi(power)
}

/// Mitsuba's look-at: columns (left, new_up, dir, origin). `up` absent (or zero) picks any
/// vector perpendicular to the viewing direction, as Mitsuba does.
fn look_at(origin: Vec3, target: Vec3, up: Option<(Vec3, Loc)>, loc: &Loc) -> Result<Mat4> {
    let d = target - origin;
    if d.length_squared() == 0.0 {
        return Err(Error::at(loc, "<lookat> origin and target are the same point"));
    }
    let dir = d.normalize();
    let (up, up_loc) = match up {
        Some((u, l)) if u.length_squared() > 0.0 => (u, l),
        _ => (dir.any_orthonormal_vector(), loc.clone()),
    };
    let c = up.normalize().cross(dir);
    if c.length() < 1e-6 {
        return Err(Error::at(
            &up_loc,
            "<lookat> 'up' is parallel to the viewing direction (target - origin); choose another up vector",
        ));
    }
    let left = up.cross(dir).normalize();
    let new_up = dir.cross(left);
    Ok(Mat4::from_cols(left.extend(0.0), new_up.extend(0.0), dir.extend(0.0), origin.extend(1.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> PathBuf {
        PathBuf::from("test.xml")
    }

    fn parse(text: &str) -> Result<Rc<Object>> {
        parse_str(text, &p(), &[])
    }

    fn scene(body: &str) -> String {
        format!("<scene version=\"3.0.0\">\n{body}\n</scene>")
    }

    /// Parses `text`, expects an error whose message contains `line` (as `test.xml:LINE:`) and
    /// every piece of `needles`.
    fn expect_err(text: &str, line: u32, needles: &[&str]) -> String {
        let err = parse(text).expect_err("expected an error").to_string();
        let at = format!("test.xml:{line}:");
        assert!(err.starts_with(&at), "error {err:?} should start with {at:?}");
        for n in needles {
            assert!(err.contains(n), "error {err:?} should contain {n:?}");
        }
        err
    }

    fn first_shape_transform(text: &str) -> Mat4 {
        let s = parse(text).unwrap();
        let shape = s.children("shape").remove(0);
        shape.transform("to_world").unwrap().expect("to_world")
    }

    fn assert_mat_eq(a: Mat4, b: Mat4) {
        assert!(a.abs_diff_eq(b, 1e-5), "\n{a:?}\n!=\n{b:?}");
    }

    #[test]
    fn xml_transform_composition_order() {
        let m = first_shape_transform(&scene(
            r#"<shape type="cube"><transform name="to_world">
                <scale x="2" y="3"/>
                <rotate y="1" angle="90"/>
                <translate value="1, 2, 3"/>
            </transform></shape>"#,
        ));
        let expect = Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0))
            * Mat4::from_rotation_y(90f32.to_radians())
            * Mat4::from_scale(Vec3::new(2.0, 3.0, 1.0));
        assert_mat_eq(m, expect);
        // The reverse order gives a different matrix, so the test can tell them apart.
        let wrong = Mat4::from_scale(Vec3::new(2.0, 3.0, 1.0))
            * Mat4::from_rotation_y(90f32.to_radians())
            * Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0));
        assert!(!m.abs_diff_eq(wrong, 1e-3));
        // A point: scaled, then rotated about y, then translated.
        let q = m.transform_point3(Vec3::new(1.0, 0.0, 0.0));
        assert!(q.abs_diff_eq(Vec3::new(1.0, 2.0, 1.0), 1e-5), "{q:?}");
    }

    #[test]
    fn xml_transform_ops_forms() {
        let m = first_shape_transform(&scene(
            r#"<shape type="cube"><transform name="to_world">
                <rotate value="0 0 2" angle="30"/>
                <scale value="2"/>
                <translate x="1"/>
                <matrix value="1 0 0 5  0 1 0 6  0 0 1 7  0 0 0 1"/>
                <matrix value="0 -1 0, 1 0 0, 0 0 1"/>
            </transform></shape>"#,
        ));
        let expect = Mat4::from_rotation_z(90f32.to_radians())
            * Mat4::from_translation(Vec3::new(5.0, 6.0, 7.0))
            * Mat4::from_translation(Vec3::X)
            * Mat4::from_scale(Vec3::splat(2.0))
            * Mat4::from_rotation_z(30f32.to_radians());
        assert_mat_eq(m, expect);
        // The cbox tall box matrix is row-major: translation in the last column.
        let m = first_shape_transform(&scene(
            r#"<shape type="cube"><transform name="to_world">
              <matrix value="0.281907786 0 0.102606043 -0.33 0 0.6 0 0.6 -0.102606043 0 0.281907786 -0.3 0 0 0 1"/>
            </transform></shape>"#,
        ));
        let expect = Mat4::from_translation(Vec3::new(-0.33, 0.6, -0.3))
            * Mat4::from_rotation_y(20f32.to_radians())
            * Mat4::from_scale(Vec3::new(0.3, 0.6, 0.3));
        assert_mat_eq(m, expect);
    }

    #[test]
    fn xml_lookat_properties() {
        let origin = Vec3::new(1.0, 2.0, 3.0);
        let target = Vec3::new(-1.0, 0.5, 0.0);
        let m = first_shape_transform(&scene(
            r#"<shape type="cube"><transform name="to_world">
                <lookat origin="1, 2, 3" target="-1 0.5 0" up="0, 1, 0"/>
            </transform></shape>"#,
        ));
        let dir = (target - origin).normalize();
        assert!(m.transform_point3(Vec3::ZERO).abs_diff_eq(origin, 1e-5));
        assert!(m.transform_vector3(Vec3::Z).abs_diff_eq(dir, 1e-5));
        let x = m.transform_vector3(Vec3::X);
        let y = m.transform_vector3(Vec3::Y);
        // Orthonormal, right-handed columns; left = up × dir, new up has positive y.
        assert!((x.length() - 1.0).abs() < 1e-5 && (y.length() - 1.0).abs() < 1e-5);
        assert!(x.dot(y).abs() < 1e-5 && x.dot(dir).abs() < 1e-5);
        assert!(x.cross(y).abs_diff_eq(dir, 1e-5));
        assert!(x.abs_diff_eq(Vec3::Y.cross(dir).normalize(), 1e-5));
        assert!(y.y > 0.0);
        assert!((m.determinant() - 1.0).abs() < 1e-5);
        // Without up: still orthonormal with the right direction.
        let m = first_shape_transform(&scene(
            r#"<shape type="cube"><transform name="to_world">
                <lookat origin="0, 0, 0" target="0 -3 0"/>
            </transform></shape>"#,
        ));
        assert!(m.transform_vector3(Vec3::Z).abs_diff_eq(-Vec3::Y, 1e-5));
        assert!((m.determinant() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn xml_lookat_errors() {
        expect_err(
            &scene(
                r#"<sensor type="perspective"><transform name="to_world">
                <lookat origin="0, 0, 0" target="0, 5, 0" up="0, 1, 0"/></transform></sensor>"#,
            ),
            3,
            &["parallel"],
        );
        expect_err(
            &scene(
                r#"<sensor type="perspective"><transform name="to_world">
                <lookat origin="1, 1, 1" target="1, 1, 1" up="0, 1, 0"/></transform></sensor>"#,
            ),
            3,
            &["same point"],
        );
        expect_err(
            &scene(
                r#"<sensor type="perspective"><transform name="to_world">
                <lookat origin="1, 1" target="1, 1, 0"/></transform></sensor>"#,
            ),
            3,
            &["'origin'", "3 number"],
        );
    }

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

    #[test]
    fn xml_defaults_substitution_overrides() {
        let text = scene(
            r#"<default name="spp" value="16"/>
               <default name="res" value="32"/>
               <default name="spp" value="99"/>
               <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
               <film type="hdrfilm"><integer name="width" value="$res"/>
                   <string name="name" value="img_$res_x$spp"/></film>"#,
        );
        // "$res_x" is a variable of its own: undefined unless given on the command line.
        let defines = vec![("spp".to_string(), "4".to_string()), ("res_x".to_string(), "R".to_string())];
        let s = parse_str(&text, &p(), &defines).unwrap();
        assert_eq!(s.children("sampler")[0].int("sample_count", 0).unwrap(), 4);
        assert_eq!(s.children("film")[0].int("width", 0).unwrap(), 32);
        assert_eq!(s.children("film")[0].string("name", "").unwrap(), "img_R4");
        // Without the override the first <default> wins (a later one does not replace it).
        let s = parse_str(&text, &p(), &[("res_x".to_string(), "R".to_string())]).unwrap();
        assert_eq!(s.children("sampler")[0].int("sample_count", 0).unwrap(), 16);
        // Unknown variable -> error naming it, at the attribute.
        expect_err(&text, 7, &["undefined variable '$res_x'"]);
        expect_err(
            &scene(r#"<sampler type="independent"><integer name="sample_count" value="$nope"/></sampler>"#),
            2,
            &["'$nope'"],
        );
        // Substitution works in type/id attributes too.
        let s = parse_str(
            &scene(r#"<default name="kind" value="diffuse"/><bsdf type="$kind"/>"#),
            &p(),
            &[("kind".into(), "conductor".into())],
        )
        .unwrap();
        assert_eq!(s.children("bsdf")[0].plugin, "conductor");
    }

    #[test]
    fn xml_refs_and_names() {
        let s = parse(&scene(
            r#"<bsdf type="diffuse" id="white"/>
               <texture type="checkerboard" id="checks"/>
               <alias id="white" as="blanc"/>
               <shape type="sphere">
                   <ref id="white"/>
               </shape>
               <shape type="sphere">
                   <bsdf type="diffuse"><ref id="checks" name="reflectance"/></bsdf>
                   <ref id="blanc" name="extra"/>
               </shape>"#,
        ))
        .unwrap();
        let bsdfs = s.children("bsdf");
        assert_eq!(bsdfs.len(), 1);
        let shapes = s.children("shape");
        let b0 = shapes[0].children("bsdf").remove(0);
        assert!(Rc::ptr_eq(&b0, &bsdfs[0]));
        let inner = shapes[1].children("bsdf");
        assert_eq!(inner.len(), 2);
        assert_eq!(inner[0].plugin, "diffuse");
        assert!(Rc::ptr_eq(&inner[1], &bsdfs[0]));
        let refl = inner[0].child_named("reflectance").unwrap();
        assert_eq!(refl.plugin, "checkerboard");
        assert!(shapes[1].child_named("extra").is_some());
        // The scene never asked for its textures, but the one declared there is referenced.
        s.check_unused().unwrap();
        // Unknown and forward references, duplicate ids.
        expect_err(&scene(r#"<shape type="sphere"><ref id="nope"/></shape>"#), 2, &["unknown id 'nope'"]);
        expect_err(
            &scene("<shape type=\"sphere\">\n<ref id=\"later\"/></shape>\n<bsdf type=\"diffuse\" id=\"later\"/>"),
            3,
            &["unknown id 'later'", "before"],
        );
        expect_err(
            &scene("<bsdf type=\"diffuse\" id=\"a\"/>\n<bsdf type=\"diffuse\" id=\"a\"/>"),
            3,
            &["duplicate id 'a'", "test.xml:2:"],
        );
        // Duplicate parameter names.
        expect_err(
            &scene("<bsdf type=\"diffuse\">\n<float name=\"x\" value=\"1\"/>\n<rgb name=\"x\" value=\"1\"/></bsdf>"),
            4,
            &["'x' is specified more than once", "test.xml:3:"],
        );
    }

    #[test]
    fn xml_root_and_version_errors() {
        expect_err("<scene>\n</scene>", 1, &["missing 'version'"]);
        expect_err("<scene version=\"4.0.0\">\n</scene>", 1, &["4.0.0", "newer"]);
        expect_err("<scene version=\"three\">\n</scene>", 1, &["invalid scene version 'three'"]);
        expect_err("\n<shape type=\"sphere\"/>", 2, &["root element must be <scene"]);
        expect_err("<scene version=\"3.0.0\">\n  <shape type=\"sphere\">\n</scene>", 3, &["malformed XML"]);
        assert!(parse("<scene version=\"2.1.0\"/>").is_ok());
    }

    #[test]
    fn xml_value_errors() {
        let cases: &[(&str, &[&str])] = &[
            (r#"<float name="a" value="abc"/>"#, &["invalid number 'abc'", "<float>"]),
            (r#"<float name="a" value="nan"/>"#, &["not finite"]),
            (r#"<float name="a" value="1e40"/>"#, &["not finite"]),
            (r#"<float name="a" value="inf"/>"#, &["not finite"]),
            (r#"<integer name="a" value="1.5"/>"#, &["invalid integer '1.5'", "'a'"]),
            (r#"<boolean name="a" value="yes"/>"#, &["invalid boolean 'yes'", "\"true\" or \"false\""]),
            (r#"<rgb name="a" value="1, 2"/>"#, &["1 or 3 number(s), found 2"]),
            (r#"<rgb name="a" value="1, x, 2"/>"#, &["invalid number 'x'"]),
            (r#"<spectrum name="a" value="400:0.1, 700:0.5"/>"#, &["only uniform spectra", "not supported"]),
            (r#"<spectrum name="a" filename="x.spd"/>"#, &["not supported"]),
            (r#"<point name="a" value="1, 2, 3" x="1"/>"#, &["cannot mix"]),
            (r#"<float value="1"/>"#, &["<float> requires a 'name' attribute"]),
            (r#"<float name="a"/>"#, &["<float> requires a 'value' attribute"]),
            (
                r#"<float name="a" value="1" unit="m"/>"#,
                &["unexpected attribute 'unit' on <float>", "allowed: name, value"],
            ),
            (r#"<floot name="a" value="1"/>"#, &["unknown tag <floot>"]),
            (r#"<translate x="1"/>"#, &["<translate> can only appear inside a <transform"]),
            (r#"<bsdf id="x"/>"#, &["<bsdf> requires a 'type' attribute"]),
            (r#"<shape type="sphere" typo="1"/>"#, &["unexpected attribute 'typo'"]),
            (r#"<include filename="does_not_exist.xml"/>"#, &["cannot read included file"]),
            (r#"<path value="."/>"#, &["not supported"]),
            (r#"<scene version="3.0.0"/>"#, &["root element"]),
            (r#"<float name="a" value="1"><float name="b" value="1"/></float>"#, &["cannot occur inside"]),
            ("hello", &["unexpected text \"hello\""]),
        ];
        for (body, needles) in cases {
            let text = format!("<scene version=\"3.0.0\">\n<bsdf type=\"diffuse\">\n\n{body}\n</bsdf></scene>");
            expect_err(&text, 4, needles);
        }
    }

    #[test]
    fn xml_transform_errors() {
        let cases: &[(&str, &[&str])] = &[
            (r#"<matrix value="1 2 3"/>"#, &["16 or 9 number(s), found 3"]),
            (r#"<matrix value="1 0 0 0  0 1 0 0  0 0 0 0  0 0 0 1"/>"#, &["<matrix> is singular"]),
            (r#"<rotate x="1"/>"#, &["<rotate> requires a 'angle' attribute"]),
            (r#"<rotate angle="30"/>"#, &["non-zero axis"]),
            (r#"<translate x="1" w="2"/>"#, &["unexpected attribute 'w' on <translate>"]),
            (r#"<scale value="1, 2"/>"#, &["1 or 3 number(s)"]),
            (r#"<translate x="1,5"/>"#, &["must hold 1 number(s), found 2"]),
            (r#"<shear x="1"/>"#, &["unexpected <shear>", "expected one of"]),
            (r#"<float name="a" value="1"/>"#, &["unexpected <float>"]),
        ];
        for (body, needles) in cases {
            let text = format!(
                "<scene version=\"3.0.0\">\n<shape type=\"cube\">\n<transform name=\"to_world\">\n{body}\n</transform></shape></scene>"
            );
            expect_err(&text, 4, needles);
        }
        // A zero scale makes the whole transform singular: reported at the <transform>.
        expect_err(
            "<scene version=\"3.0.0\">\n<shape type=\"cube\">\n<transform name=\"to_world\">\n<scale x=\"0\"/>\n</transform></shape></scene>",
            3,
            &["transform 'to_world' is singular"],
        );
    }

    #[test]
    fn xml_include() {
        let dir = std::env::temp_dir().join(format!("tessera_xml_include_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("part.xml"),
            "<scene version=\"3.0.0\">\n<bsdf type=\"diffuse\" id=\"inc\">\n<float name=\"x\" value=\"oops\"/></bsdf></scene>",
        )
        .unwrap();
        std::fs::write(dir.join("good.xml"), "<scene version=\"3.0.0\"><bsdf type=\"diffuse\" id=\"inc\"/></scene>")
            .unwrap();
        let main = dir.join("main.xml");
        std::fs::write(&main, "<scene version=\"3.0.0\">\n<include filename=\"good.xml\"/>\n<shape type=\"sphere\"><ref id=\"inc\"/></shape></scene>").unwrap();
        let s = parse_file(&main, &[]).unwrap();
        assert_eq!(s.children("bsdf").len(), 1);
        assert_eq!(s.children("shape")[0].children("bsdf")[0].plugin, "diffuse");
        // An error inside the included file points into that file.
        std::fs::write(&main, "<scene version=\"3.0.0\">\n<include filename=\"part.xml\"/></scene>").unwrap();
        let e = parse_file(&main, &[]).unwrap_err().to_string();
        assert!(e.contains("part.xml:3:") && e.contains("invalid number 'oops'"), "{e}");
        // Recursive include stops.
        std::fs::write(&main, "<scene version=\"3.0.0\">\n<include filename=\"main.xml\"/></scene>").unwrap();
        let e = parse_file(&main, &[]).unwrap_err().to_string();
        assert!(e.contains("main.xml:2:") && e.contains("nested more than"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn xml_old_version_renames() {
        let s = parse("<scene version=\"0.6.0\"><sampler type=\"independent\"><integer name=\"sampleCount\" value=\"4\"/></sampler></scene>").unwrap();
        assert_eq!(s.children("sampler")[0].int("sample_count", 0).unwrap(), 4);
    }

    #[test]
    fn xml_reference_scenes_parse() {
        let dir = Path::new("/work/shared/refs/scenes");
        let mut n = 0;
        for name in ["cbox.xml", "dielectrics.xml", "roughconductors.xml", "textured_mesh.xml"] {
            let path = dir.join(name);
            if !path.exists() {
                eprintln!("skipping {} (not present)", path.display());
                continue;
            }
            let s = parse_file(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(s.tag, "scene");
            assert_eq!(s.children("sensor").len(), 1, "{name}");
            assert_eq!(s.children("integrator").len(), 1, "{name}");
            assert!(!s.children("shape").is_empty(), "{name}");
            let sensor = s.children("sensor").remove(0);
            let m = sensor.transform("to_world").unwrap().unwrap();
            assert!(m.is_finite() && (m.determinant().abs() - 1.0).abs() < 1e-4);
            n += 1;
        }
        let cbox = parse_file(&dir.join("cbox.xml"), &[]);
        if let Ok(cbox) = cbox {
            let shapes = cbox.children("shape");
            let floor = shapes.iter().find(|s| s.id.as_deref() == Some("floor")).unwrap();
            assert!(Rc::ptr_eq(&floor.children("bsdf")[0], &cbox.children("bsdf")[0]));
            // rotate x -90: the rectangle's +z normal becomes +y.
            let m = floor.transform("to_world").unwrap().unwrap();
            assert!(m.transform_vector3(Vec3::Z).abs_diff_eq(Vec3::Y, 1e-6));
        }
        eprintln!("parsed {n} reference scenes");
    }
}
