//! Transforms: a `<transform>`'s operations composed into one matrix, checked to place an object.

use glam::{Mat3, Mat4, Vec3};

use super::params::{parse_list, parse_xyz};
use super::parser::{Attr, Elem, Parser, Src};
use super::TRANSFORM_OPS;
use crate::error::{Error, Loc, Result};

impl Parser {
    /// Composes the operations of a `<transform>`: each left-multiplies the result so far.
    pub(super) fn transform(&self, src: &Src, node: roxmltree::Node, e: &Elem, name: &str) -> Result<Mat4> {
        let mut m = Mat4::IDENTITY;
        for ch in node.children() {
            match ch.node_type() {
                roxmltree::NodeType::Element => {}
                roxmltree::NodeType::Text => {
                    let t = ch.text().unwrap_or("").trim();
                    if !t.is_empty() {
                        return Err(Error::at(
                            &src.loc(ch.range().start),
                            format!("unexpected text \"{}\" inside <transform name=\"{name}\">", super::excerpt(t)),
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
    use crate::xml::testing::{expect_err, parse, scene};

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
}
