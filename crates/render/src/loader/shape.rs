//! Shapes, with their BSDF and area light; their parameters are listed in the "Shapes" section
//! of [the loader's docs](super).

use super::{check_finite_positive, check_rgb, mat4_to_affine, Builder};
use crate::emitter::Emitter;
use crate::error::Result;
use crate::geometry::{mesh_area_distribution, Shape, ShapeGeometry};
use crate::mesh::{cube_mesh, rectangle_mesh, TriangleMesh};
use crate::xml::Object;
use glam::{Mat3, Mat4, Vec3};

impl Builder {
    /// Builds one `<shape>` with its BSDF and area light; its parameters are listed in the
    /// module docs' "Shapes" section.
    pub(super) fn shape(&mut self, obj: &Object) -> Result<()> {
        let to_world = obj.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
        if to_world.determinant().abs() < 1e-12 || !to_world.is_finite() {
            return Err(obj.error("to_world is singular or not finite"));
        }
        let flip_normals = obj.bool("flip_normals", false)?;
        let name = obj.id.clone().unwrap_or_else(|| obj.plugin.clone());
        let mut face_normals = false;
        let geometry = match obj.plugin.as_str() {
            "rectangle" => mesh_geometry(obj, rectangle_mesh(), to_world)?,
            "cube" => mesh_geometry(obj, cube_mesh(), to_world)?,
            "obj" | "ply" => {
                let file = obj
                    .opt_string("filename")?
                    .ok_or_else(|| obj.error(format!("{} needs a 'filename'", obj.plugin)))?;
                let path = self.resolve(&file);
                if !path.exists() {
                    return Err(obj.error(format!("mesh file '{}' not found", path.display())));
                }
                face_normals = obj.bool("face_normals", false)?;
                let mut mesh = if obj.plugin == "obj" {
                    crate::mesh::load_obj(&path, obj.bool("flip_tex_coords", true)?)?
                } else {
                    crate::mesh::load_ply(&path, obj.bool("flip_tex_coords", false)?)?
                };
                self.files.push(path.clone());
                for w in mesh.validate(&path)? {
                    eprintln!("warning: {w}");
                }
                mesh_geometry(obj, mesh, to_world)?
            }
            "sphere" => {
                let center = obj.point("center", Vec3::ZERO)?;
                let radius = obj.float("radius", 1.0)?;
                check_finite_positive(obj, "radius", radius, false)?;
                if !center.is_finite() {
                    return Err(obj.error("sphere center must be finite"));
                }
                // The transform's linear part must be a similarity (uniform scale).
                let lin = Mat3::from_mat4(to_world);
                let scales = Vec3::new(lin.x_axis.length(), lin.y_axis.length(), lin.z_axis.length());
                if (scales.max_element() - scales.min_element()) > 1e-3 * scales.max_element() {
                    return Err(obj.error("sphere to_world must scale uniformly (got a non-uniform scale)"));
                }
                let s = scales.x;
                let rotation = Mat3::from_cols(lin.x_axis / s, lin.y_axis / s, lin.z_axis / s);
                let rotation = if rotation.determinant() < 0.0 { -rotation } else { rotation };
                ShapeGeometry::Sphere { center: to_world.transform_point3(center), radius: radius * s, rotation }
            }
            "disk" => {
                let tw = mat4_to_affine(to_world);
                let lin = Mat3::from(tw.matrix3);
                let normal = (lin.inverse().transpose() * Vec3::Z).normalize();
                let area = std::f32::consts::PI * lin.x_axis.cross(lin.y_axis).length();
                ShapeGeometry::Disk { to_world: tw, to_object: tw.inverse(), normal, area }
            }
            other => {
                return Err(
                    obj.error(format!("unknown shape '{other}' (supported: rectangle, disk, cube, sphere, obj, ply)"))
                )
            }
        };
        let material = match obj.children("bsdf").as_slice() {
            [] => self.default_material(),
            [b] => self.material(b)?,
            [_, b, ..] => return Err(b.error("a shape takes one <bsdf>")),
        };
        let shape_index = self.shapes.len() as u32;
        let emitter = match obj.children("emitter").as_slice() {
            [] => None,
            [e] => {
                if e.plugin != "area" {
                    return Err(e.error(format!("a shape's emitter must be 'area', got '{}'", e.plugin)));
                }
                let radiance = check_rgb(e, "radiance", e.rgb("radiance", Vec3::ONE)?)?;
                e.check_unused()?;
                self.emitters.push(Emitter::Area { shape: shape_index, radiance });
                Some(self.emitters.len() as u32 - 1)
            }
            [_, e, ..] => return Err(e.error("a shape takes one <emitter>")),
        };
        obj.check_unused()?;
        let shape = Shape { geometry, material, emitter, flip_normals, face_normals, name };
        let extent = shape.extent();
        if !(extent <= crate::geometry::MAX_EXTENT) {
            return Err(obj.error(format!(
                "the shape reaches coordinates of {extent:e}; world coordinates beyond ±{:e} are not supported (check its to_world scale)",
                crate::geometry::MAX_EXTENT
            )));
        }
        self.shapes.push(shape);
        Ok(())
    }
}

/// Transforms a mesh to world space (normals by the inverse transpose) and checks it has area.
fn mesh_geometry(obj: &Object, mut mesh: TriangleMesh, to_world: Mat4) -> Result<ShapeGeometry> {
    let normal_m = Mat3::from_mat4(to_world).inverse().transpose();
    for p in &mut mesh.positions {
        *p = to_world.transform_point3(*p);
    }
    if let Some(ns) = &mut mesh.normals {
        for n in ns.iter_mut() {
            *n = (normal_m * *n).normalize_or_zero();
        }
    }
    let area = mesh_area_distribution(&mesh).ok_or_else(|| obj.error("shape has zero surface area"))?;
    Ok(ShapeGeometry::mesh(mesh, area))
}
