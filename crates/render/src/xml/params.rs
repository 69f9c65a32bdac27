//! Typed parameters: `<float>`, `<rgb>`, `<point>` and the others read into [`Value`]s, with their numbers.

use glam::Vec3;

use super::object::Value;
use super::parser::{Attr, Builder, Elem, Parser, Src};
use crate::error::{Error, Result};

/// Splits a list of numbers separated by commas and/or whitespace.
fn tokens(s: &str) -> Vec<&str> {
    s.split(|c: char| c == ',' || c.is_whitespace()).filter(|t| !t.is_empty()).collect()
}

fn parse_f32(tok: &str, attr: &Attr, tag: &str) -> Result<f32> {
    let v: f32 = tok.parse().map_err(|_| {
        Error::at(
            &attr.loc,
            format!(
                "invalid number '{}' in attribute '{}' of <{tag}> (expected a decimal number such as 0.5)",
                super::excerpt(tok),
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
pub(super) fn parse_list(attr: &Attr, tag: &str, counts: &[usize]) -> Result<Vec<f32>> {
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
pub(super) fn parse_xyz(e: &Elem, default: f32) -> Result<Vec3> {
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

impl Parser {
    pub(super) fn param(&mut self, src: &Src, node: roxmltree::Node, e: &Elem, b: &mut Builder) -> Result<()> {
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
                            super::excerpt(&a.value)
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
}

#[cfg(test)]
mod tests {
    use crate::xml::testing::expect_err;

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
}
