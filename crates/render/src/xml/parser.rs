//! The parser: XML text to [`Object`]s, with `<default>`s and `$name`, ids and `<ref>`s, `<include>`s.

use std::cell::Cell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::Arc;

use super::object::{Child, Object, Param, Value};
use super::{OBJECT_TAGS, PARAM_TAGS, TRANSFORM_OPS};
use crate::error::{Error, Loc, Result};

/// Deepest `<include>` nesting accepted (guards against recursive includes).
const MAX_INCLUDE_DEPTH: usize = 16;

/// Deepest nesting of objects accepted, includes counted in (a scene nests a few: a shape's
/// two-sided BSDF's blended BSDF's texture). Objects are built recursively: without a limit, a
/// scene nesting 100 000 shapes overflowed the stack.
pub const MAX_OBJECT_DEPTH: usize = 64;

/// The longest a value may grow by `$name` substitution. A default may read earlier defaults, so
/// nine defaults each repeating the previous ten times made a value of 10¹⁰ bytes (15 GB in 20 s
/// before it was stopped); no real value comes near a mebibyte.
pub const MAX_SUBSTITUTED_BYTES: usize = 1 << 20;

/// Parses the scene file at `path`. `defines` are `-D name=value` pairs from the command line:
/// they override the scene's `<default>`s.
pub fn parse_file(path: &Path, defines: &[(String, String)]) -> Result<Rc<Object>> {
    parse_file_with_includes(path, defines).map(|(root, _)| root)
}

/// [`parse_file`], with the files its `<include>`s read (in the order they were read).
pub(crate) fn parse_file_with_includes(
    path: &Path,
    defines: &[(String, String)],
) -> Result<(Rc<Object>, Vec<PathBuf>)> {
    let text = read_text(path).map_err(|e| match e {
        Ok(io) => Error::in_file(path, format!("cannot read scene file: {io}")),
        Err(at) => at,
    })?;
    parse_with_includes(&text, path, defines)
}

/// Parses a scene given as text; `virtual_path` names it in messages and is the base for
/// relative `<include>` file names.
pub fn parse_str(text: &str, virtual_path: &Path, defines: &[(String, String)]) -> Result<Rc<Object>> {
    parse_with_includes(text, virtual_path, defines).map(|(root, _)| root)
}

/// [`parse_str`], with the files its `<include>`s read.
pub(crate) fn parse_with_includes(
    text: &str,
    virtual_path: &Path,
    defines: &[(String, String)],
) -> Result<(Rc<Object>, Vec<PathBuf>)> {
    for (name, _) in defines {
        if name.is_empty() || !name.chars().all(is_var_char) {
            return Err(Error::plain(format!("invalid define name '{name}': use letters, digits and '_' only")));
        }
    }
    let mut parser = Parser {
        defines: defines.to_vec(),
        defaults: Vec::new(),
        ids: HashMap::new(),
        include_depth: 0,
        read_vars: Default::default(),
        includes: Vec::new(),
        object_depth: 0,
    };
    let file = Arc::new(virtual_path.to_path_buf());
    let doc = parse_xml(text, &file)?;
    let root = doc.root_element();
    let src = Src::new(file, &doc);
    let root_loc = src.loc(root.range().start);
    if root.tag_name().name() != "scene" {
        return Err(Error::at(
            &root_loc,
            format!("the root element must be <scene version=\"3.0.0\">, found <{}>", root.tag_name().name()),
        ));
    }
    let old_format = check_version(&src, root, true)?;
    let src = Src { old_format, ..src };
    let scene = parser.build_object(&src, root, "scene")?;
    for name in unused_defines(&parser) {
        eprintln!(
            "warning: {}: -D {name}=… has no effect: the scene neither declares <default name=\"{name}\"> nor reads ${name}",
            virtual_path.display()
        );
    }
    Ok((scene, parser.includes))
}

/// The command-line defines that no `<default>` of the scene (or its includes) declares and
/// no `$name` reads: a misspelt `-D` would otherwise change nothing, silently.
fn unused_defines(parser: &Parser) -> Vec<&str> {
    let read = parser.read_vars.borrow();
    parser
        .defines
        .iter()
        .map(|(n, _)| n.as_str())
        .filter(|n| !parser.defaults.iter().any(|(d, _)| d == n) && !read.contains(*n))
        .collect()
}

/// The text of the XML file at `path`: `Err(Ok(io))` when it cannot be read, `Err(Err(e))`
/// when it is not UTF-8 (`e` names the line and column of the first bad byte).
fn read_text(path: &Path) -> std::result::Result<String, std::result::Result<std::io::Error, Error>> {
    let bytes = std::fs::read(path).map_err(Ok)?;
    graph::text::utf8_text(bytes)
        .map_err(|e| Err(Error::at(&Loc::new(Arc::new(path.to_path_buf()), e.line, e.column), e.message)))
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
                format!(
                    "invalid scene version '{}' (expected major.minor.patch, e.g. \"3.0.0\")",
                    super::excerpt(value)
                ),
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
pub(super) struct Src<'a, 'input> {
    file: Arc<PathBuf>,
    doc: &'a roxmltree::Document<'input>,
    /// Version < 2.0.0: parameter names are camelCase and get renamed.
    old_format: bool,
    /// Byte offsets of the text's line starts (locating an element is then a binary search:
    /// `roxmltree`'s `text_pos_at` rescans the text from its start, and doing that for every
    /// element made loading quadratic, 9.5 s for a 1.4 MB scene of 8000 shapes).
    lines: Rc<[usize]>,
}

impl<'a, 'input> Src<'a, 'input> {
    fn new(file: Arc<PathBuf>, doc: &'a roxmltree::Document<'input>) -> Self {
        let text = doc.input_text();
        let lines = std::iter::once(0).chain(text.match_indices('\n').map(|(i, _)| i + 1)).collect();
        Src { file, doc, old_format: false, lines }
    }

    /// The line and column (1-based, in characters) of byte `byte` of the text.
    pub(super) fn loc(&self, byte: usize) -> Loc {
        let text = self.doc.input_text();
        let byte = byte.min(text.len());
        let line = self.lines.partition_point(|&start| start <= byte).max(1);
        let start = self.lines[line - 1];
        let col = text.get(start..byte).map_or(byte - start, |s| s.chars().count()) + 1;
        Loc::new(self.file.clone(), line as u32, col as u32)
    }
}

/// An attribute after `$` substitution.
pub(super) struct Attr {
    pub(super) name: String,
    pub(super) value: String,
    /// Where the value starts.
    pub(super) loc: Loc,
}

/// An element's tag, location and substituted attributes.
pub(super) struct Elem {
    pub(super) tag: String,
    pub(super) loc: Loc,
    pub(super) attrs: Vec<Attr>,
}

impl Elem {
    pub(super) fn get(&self, name: &str) -> Option<&Attr> {
        self.attrs.iter().find(|a| a.name == name)
    }

    pub(super) fn require(&self, name: &str, example: &str) -> Result<&Attr> {
        self.get(name).ok_or_else(|| {
            Error::at(&self.loc, format!("<{}> requires a '{name}' attribute (e.g. {example})", self.tag))
        })
    }

    pub(super) fn allow(&self, allowed: &[&str]) -> Result<()> {
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

/// Builds an object's parameters and children.
#[derive(Default)]
pub(super) struct Builder {
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

    pub(super) fn add_param(&mut self, name: String, value: Value, loc: Loc) -> Result<()> {
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

pub(super) struct Parser {
    /// Command-line defines (win over `<default>`s).
    defines: Vec<(String, String)>,
    /// `<default>`s seen so far.
    defaults: Vec<(String, String)>,
    /// Declared ids (and aliases): the object and where the id was declared.
    ids: HashMap<String, (Rc<Object>, Loc)>,
    include_depth: usize,
    /// The variables `$name` substitutions read (a define none reads nor declares is reported).
    read_vars: std::cell::RefCell<std::collections::HashSet<String>>,
    /// The files `<include>`s read.
    includes: Vec<PathBuf>,
    /// How many objects enclose the one being built.
    object_depth: usize,
}

impl Parser {
    fn variable(&self, name: &str) -> Option<&str> {
        if !self.read_vars.borrow().contains(name) {
            self.read_vars.borrow_mut().insert(name.to_string());
        }
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
                return Err(Error::at(
                    loc,
                    format!("'$' not followed by a variable name in \"{}\"", super::excerpt(s)),
                ));
            }
            match self.variable(name) {
                Some(v) if out.len() + v.len() > MAX_SUBSTITUTED_BYTES => {
                    return Err(Error::at(
                        loc,
                        format!(
                            "\"{}\" grows beyond {} MiB as its variables are substituted (defaults that repeat each other?)",
                            super::excerpt(s),
                            MAX_SUBSTITUTED_BYTES >> 20
                        ),
                    ));
                }
                Some(v) => out.push_str(v),
                None => {
                    return Err(Error::at(
                        loc,
                        format!(
                            "undefined variable '${name}' in \"{}\" (declare it with <default name=\"{name}\" value=\"...\"/> or pass -D {name}=...)",
                            super::excerpt(s)
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
    pub(super) fn elem(&self, src: &Src, node: roxmltree::Node) -> Result<Elem> {
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
        if self.object_depth >= MAX_OBJECT_DEPTH {
            return Err(Error::at(
                &src.loc(node.range().start),
                format!("<{tag}> is nested more than {MAX_OBJECT_DEPTH} objects deep"),
            ));
        }
        self.object_depth += 1;
        let result = self.build_object_at_depth(src, node, tag);
        self.object_depth -= 1;
        result
    }

    fn build_object_at_depth(&mut self, src: &Src, node: roxmltree::Node, tag: &str) -> Result<Rc<Object>> {
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
                        format!("unexpected text \"{}\" inside {parent}", super::excerpt(t)),
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
        let text = read_text(&path).map_err(|e| match e {
            Ok(io) => Error::at(&f.loc, format!("cannot read included file '{}': {io}", path.display())),
            Err(at) => at,
        })?;
        self.includes.push(path.clone());
        let file = Arc::new(path);
        let doc = parse_xml(&text, &file)?;
        let root = doc.root_element();
        let inner = Src::new(file, &doc);
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
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::xml::testing::{expect_err, p, parse, scene};

    /// Locations from the line index are `roxmltree`'s own (1-based line, column in
    /// characters), at every byte of a text with multi-byte characters and `\r\n` endings.
    #[test]
    fn line_index_locations_match_the_xml_parser() {
        let text = "<scene version=\"3.0.0\">\r\n  <!-- café ✓ -->\n\n<shape type=\"sphere\"/>\n</scene>";
        let doc = roxmltree::Document::parse(text).unwrap();
        let src = Src::new(Arc::new(p()), &doc);
        for byte in (0..=text.len()).filter(|&b| text.is_char_boundary(b)) {
            let want = doc.text_pos_at(byte);
            let got = src.loc(byte);
            assert_eq!((got.line, got.col), (want.row, want.col), "byte {byte}");
        }
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
        // `spp` is declared and `res_x` read: neither is unused; a misspelt define is.
        let scene_text = scene(
            r#"<default name="spp" value="16"/>
               <film type="hdrfilm"><string name="name" value="img_$res_x"/></film>"#,
        );
        let mut parser = Parser {
            defines: vec![("spp".into(), "4".into()), ("res_x".into(), "R".into()), ("sp".into(), "8".into())],
            defaults: Vec::new(),
            ids: HashMap::new(),
            include_depth: 0,
            read_vars: Default::default(),
            includes: Vec::new(),
            object_depth: 0,
        };
        let file = Arc::new(p());
        let xml = parse_xml(&scene_text, &file).unwrap();
        let src = Src::new(file, &xml);
        parser.build_object(&src, xml.root_element(), "scene").unwrap();
        assert_eq!(unused_defines(&parser), ["sp"]);
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
