//! Versions: elements of MaterialX 1.36 to 1.38 read as 1.39 writes them.

use super::importer::{Fail, Importer};
use crate::error::LoadErrorKind;
use crate::graph::Source;
use crate::value::{Value, ValueType};
use roxmltree::Node as XNode;

/// The newest version read, and the oldest upgraded.
pub(super) const NEWEST: (u32, u32) = (1, 39);
pub(super) const OLDEST: (u32, u32) = (1, 36);

pub(super) fn parse_version(s: &str) -> Option<(u32, u32)> {
    let mut it = s.trim().split('.');
    let major = it.next()?.parse().ok()?;
    let minor = it.next()?.parse().ok()?;
    Some((major, minor))
}

impl<'a, 'i> Importer<'a, 'i> {
    /// The type attribute, upgraded (`color2` was `vector2` before 1.38).
    pub(super) fn type_name(&self, el: XNode<'a, 'i>) -> Option<&'a str> {
        match el.attribute("type") {
            Some("color2") if self.version(el) < (1, 38) => Some("vector2"),
            t => t,
        }
    }

    pub(super) fn value_type(&self, el: XNode<'a, 'i>) -> Option<ValueType> {
        self.type_name(el).and_then(ValueType::from_name)
    }

    /// The input elements of a node (`parameter`s too before 1.38; `bindinput`/`bindparam` of a
    /// legacy `shaderref`).
    pub(super) fn inputs_of(&self, el: XNode<'a, 'i>) -> Vec<XNode<'a, 'i>> {
        let legacy = self.version(el) < (1, 38);
        el.children()
            .filter(|c| {
                c.is_element()
                    && match c.tag_name().name() {
                        "input" => true,
                        "parameter" | "bindinput" | "bindparam" => legacy,
                        _ => false,
                    }
            })
            .collect()
    }

    /// A node's category, upgraded to 1.39.
    pub(super) fn category(&self, el: XNode<'a, 'i>) -> &'a str {
        let c = el.tag_name().name();
        if self.version(el) >= (1, 37) {
            return c;
        }
        let has = |n: &str| self.inputs_of(el).iter().any(|i| i.attribute("name") == Some(n));
        match c {
            "rotate" => {
                if self.type_name(el) == Some("vector2") {
                    "rotate2d"
                } else {
                    "rotate3d"
                }
            }
            "compare" => "ifgreatereq",
            "geomattrvalue" => "geompropvalue",
            "combine" => {
                if has("in4") {
                    "combine4"
                } else if has("in3") {
                    "combine3"
                } else {
                    "combine2"
                }
            }
            "separate" => {
                let t = self.inputs_of(el).into_iter().find(|i| i.attribute("name") == Some("in"));
                match t.and_then(|i| self.value_type(i)).map(|t| t.channels()) {
                    Some(4) => "separate4",
                    Some(3) => "separate3",
                    _ => "separate2",
                }
            }
            "transformpoint" | "transformvector" | "transformnormal" if !has("fromspace") && !has("tospace") => {
                "transformmatrix"
            }
            _ => c,
        }
    }

    /// An input's name, upgraded to 1.39.
    pub(super) fn input_name(&self, node: XNode<'a, 'i>, category: &str, inp: XNode<'a, 'i>) -> &'a str {
        let n = inp.attribute("name").unwrap_or("");
        let v = self.version(node);
        if v >= (1, 39) {
            return n;
        }
        let original = node.tag_name().name();
        match (original, category, n) {
            ("compare", _, "intest") if v < (1, 37) => "value1",
            ("compare", _, "cutoff") if v < (1, 37) => "value2",
            ("compare", _, "in1") if v < (1, 37) => "in2",
            ("compare", _, "in2") if v < (1, 37) => "in1",
            // 1.37 → 1.38 swaps in1 and in2; 1.38 → 1.39 renames in1 → iny, in2 → inx.
            (_, "atan2", "in1") => {
                if v < (1, 38) {
                    "inx"
                } else {
                    "iny"
                }
            }
            (_, "atan2", "in2") => {
                if v < (1, 38) {
                    "iny"
                } else {
                    "inx"
                }
            }
            _ => n,
        }
    }

    /// `src` reordered by a `channels` string (`"rgb"`, `"xxx"`, `"x0y1"`, ...) into type `dest`:
    /// MaterialX's `swizzle` / `channels` semantics up to 1.38.
    pub(super) fn swizzle(
        &mut self,
        q: &str,
        src: Source,
        channels: &str,
        dest: ValueType,
        at: XNode<'a, 'i>,
    ) -> Result<Source, Fail> {
        let src_ty = self.builder.source_type(&src);
        let n_src = src_ty.channels();
        let chars: Vec<char> = channels.chars().filter(|c| !c.is_whitespace()).collect();
        let mut parts = Vec::with_capacity(4);
        for i in 0..dest.channels() {
            let c = chars.get(i).copied().unwrap_or('x');
            let part = match c {
                '0' => Source::Constant(Value::float(0.0)),
                '1' => Source::Constant(Value::float(1.0)),
                _ => {
                    let k = match c {
                        'r' | 'x' => 0,
                        'g' | 'y' => 1,
                        'b' | 'z' => 2,
                        // `a` of a former color2 is its second channel.
                        'a' if n_src == 2 => 1,
                        'a' | 'w' => 3,
                        _ => {
                            return Err(self.hard(
                                at,
                                LoadErrorKind::Structure(format!("unknown channel `{c}` in channels `{channels}`")),
                            ))
                        }
                    };
                    if k >= n_src && n_src > 1 {
                        return Err(self.hard(
                            at,
                            LoadErrorKind::Structure(format!(
                                "channel `{c}` of `{channels}` is out of range for {src_ty}"
                            )),
                        ));
                    }
                    self.pick(&src, k, at)?
                }
            };
            parts.push(part);
        }
        if parts.len() == 1 {
            return Ok(parts.pop().unwrap_or(src));
        }
        if let Some(id) = self.builder.node_id(q) {
            return Ok(Source::Node { node: id, channel: None });
        }
        let names = ["in1", "in2", "in3", "in4"];
        let inputs: Vec<(&str, Source)> = names.iter().copied().zip(parts).collect();
        let id = self
            .builder
            .add_node(q, &format!("combine{}", inputs.len()), dest, &inputs, vec![])
            .map_err(|e| self.hard(at, e.into()))?;
        Ok(Source::Node { node: id, channel: None })
    }

    /// A ≤ 1.38 `swizzle` node.
    pub(super) fn legacy_swizzle(&mut self, scope: usize, q: &str, el: XNode<'a, 'i>) -> Result<Source, Fail> {
        let Some(dest) = self.value_type(el) else {
            let t = self.type_name(el).unwrap_or("").to_string();
            return Err(self.unsupported("swizzle", q, format!("type `{t}`"), el));
        };
        let mut src = None;
        let mut channels = String::new();
        for inp in self.inputs_of(el) {
            match inp.attribute("name") {
                Some("in") => {
                    src = self.input_source(scope, inp)?;
                    if src.is_none() {
                        let t = self.value_type(inp).unwrap_or(ValueType::Float);
                        src = Some(Source::Constant(Value::splat(t, 0.0)));
                    }
                }
                Some("channels") => channels = inp.attribute("value").unwrap_or("").to_string(),
                _ => {}
            }
        }
        let src = src.unwrap_or(Source::Constant(Value::float(0.0)));
        self.swizzle(q, src, &channels, dest, el)
    }
}
