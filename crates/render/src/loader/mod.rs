//! Builds a [`Scene`] from a Mitsuba 3 XML document.
//!
//! The XML reader ([`crate::xml`]) gives typed, located parameters; this module knows the
//! plugins. Every plugin reads its parameters by name and then asks the reader whether anything
//! was left unused, so a misspelt parameter is an error at its line, as in Mitsuba.
//!
//! Each BSDF's parameters are listed in its model's file under [`crate::bsdf`], the emitters'
//! in [`crate::emitter`], and the shapes' below.
//!
//! # Shapes
//!
//! The loader reads the `<shape>` elements placed directly in the `<scene>` (or brought there by
//! an `<include>`). It accepts the types `obj`, `ply`, `rectangle`, `cube`, `sphere` and
//! `disk`; any other type is an error that lists these six. Every shape reads the following:
//!
//! | parameter        | type      | default         | meaning                                 |
//! |------------------|-----------|-----------------|-----------------------------------------|
//! | `to_world`       | transform | identity        | places the shape in the world           |
//! | `flip_normals`   | boolean   | `false`         | turns the normals to the other side     |
//! | a `<bsdf>`       | object    | `diffuse`, 0.5  | the surface material, nested or `<ref>` |
//! | an `<emitter>`   | object    | none            | an `area` light on this shape           |
//!
//! A `to_world` that is singular or not finite is an error. `flip_normals` reverses both the
//! geometric and the shading normal, which decides the front of one-sided BSDFs and the side an
//! area light emits from. Without a `<bsdf>` the shape gets a `diffuse` BSDF with reflectance
//! 0.5, Mitsuba's default. A `<ref id="..."/>` to a `<bsdf>` declared earlier shares one
//! material among all the shapes that refer to it. A shape takes at most one `<bsdf>` and one
//! `<emitter>`, and the emitter must be of type `area` (its `radiance` is described in
//! [`crate::emitter`]); anything else is an error. Every other parameter or nested object,
//! including a `<medium>`, is reported as unused and stops the load, so media are not
//! supported. The shape's `id`, or else its type, names it in messages.
//!
//! ## `obj` and `ply`
//!
//! A triangle mesh read from a file.
//!
//! | parameter         | type    | default                     | meaning                        |
//! |-------------------|---------|-----------------------------|--------------------------------|
//! | `filename`        | string  | required                    | the mesh file                  |
//! | `face_normals`    | boolean | `false`                     | ignores the file's normals     |
//! | `flip_tex_coords` | boolean | `true` (obj), `false` (ply) | replaces each v by 1 − v       |
//!
//! A relative `filename` is taken from the scene file's folder. Leaving it out is an error
//! ("obj needs a 'filename'", or the same with ply), and so is naming a file that does not
//! exist ("mesh file '...' not found"). In an OBJ file all objects and groups become one mesh,
//! faces with more than three corners are split into a fan of triangles, and materials are
//! ignored ([`crate::mesh::load_obj`]). A PLY file may be ASCII or binary of either byte order
//! ([`crate::mesh::load_ply`]).
//!
//! The mesh is then checked ([`TriangleMesh::validate`]): it is an error if it has no
//! triangles, an index out of range, a different number of normals or texture coordinates than
//! positions, or a NaN or infinite position, normal or texture coordinate. Triangles with
//! exactly zero area in the file's coordinates are removed, with one warning on standard error;
//! if every triangle has zero area, that is an error. Triangles that repeat an earlier one (the
//! same three vertices, wound the same way) are removed too, with one warning. Positions are transformed by `to_world`,
//! and normals by its inverse transpose and then renormalised. A mesh whose area in the world
//! is zero or not finite is an error ("shape has zero surface area").
//!
//! Shading uses the interpolated vertex normals when the file has them and `face_normals` is
//! `false`; otherwise it uses the triangle's own normal, which faces the side from which its
//! corners run counter-clockwise. A mesh without texture coordinates gives each triangle's
//! corners the uv values (0, 0), (1, 0) and (0, 1).
//!
//! ## `rectangle` and `cube`
//!
//! Built-in meshes with no parameters beyond the common ones (`face_normals` and
//! `flip_tex_coords` are not read, so giving them is an error). `rectangle` is the square
//! [−1, 1]² in the object's z = 0 plane, with normal +z and uv = ((x + 1)/2, (y + 1)/2).
//! `cube` is [−1, 1]³ with outward normals, each face covering the whole uv square.
//!
//! ## `sphere`
//!
//! An exact sphere (not tessellated).
//!
//! | parameter | type  | default   | meaning                                                 |
//! |-----------|-------|-----------|---------------------------------------------------------|
//! | `center`  | point | (0, 0, 0) | centre in object space (a `<vector>` is accepted too)   |
//! | `radius`  | float | 1         | radius in object space; must be finite and positive     |
//!
//! `to_world` moves the centre and multiplies the radius by its scale, which must be the same
//! along the three axes (to a relative tolerance of 10⁻³); a non-uniform scale is an error. A
//! centre that is not finite is an error too. The normal points outwards. The uv is
//! (φ/2π, θ/π), with θ measured from the object's +z axis and φ around it from +x, so
//! `to_world`'s rotation turns the texture with the sphere.
//!
//! ## `disk`
//!
//! The exact unit disk in the object's z = 0 plane, with normal +z and uv = (r, φ/2π), where r
//! is the distance from the centre and φ the angle from +x. It has no parameters beyond the
//! common ones; `to_world` places, scales and shears it, and its normal follows by the
//! inverse transpose.
//!
//! ## Example
//!
//! ```xml
//! <bsdf type="diffuse" id="white">
//!     <rgb name="reflectance" value="0.8, 0.8, 0.8"/>
//! </bsdf>
//!
//! <shape type="obj">
//!     <string name="filename" value="meshes/bunny.obj"/>
//!     <boolean name="face_normals" value="true"/>
//!     <transform name="to_world">
//!         <scale value="2"/>
//!         <translate x="-0.5"/>
//!     </transform>
//!     <ref id="white"/>
//! </shape>
//!
//! <shape type="sphere">
//!     <point name="center" x="0" y="3" z="0"/>
//!     <float name="radius" value="0.25"/>
//!     <emitter type="area">
//!         <rgb name="radiance" value="20, 20, 20"/>
//!     </emitter>
//! </shape>
//!
//! <shape type="disk">
//!     <transform name="to_world">
//!         <rotate x="1" angle="-90"/>
//!         <scale value="5"/>
//!     </transform>
//!     <bsdf type="twosided">
//!         <bsdf type="diffuse"/>
//!     </bsdf>
//! </shape>
//! ```

use crate::emitter::Emitter;
use crate::error::Result;
use crate::geometry::Shape;
use crate::material::{Material, SceneGraph};
use crate::scene::{PathSettings, Scene};
use crate::texture::Bitmap;
use crate::xml::{self, Object};
use glam::{Affine2, Affine3A, Mat4, Vec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

mod emitter;
mod material;
mod sensor;
mod shape;
mod texture;

/// Largest image accepted, in pixels (a 16k × 16k image).
pub const MAX_PIXELS: u64 = 1 << 28;

/// Loads a scene file; `defines` override its `<default>` values.
pub fn load_file(path: &Path, defines: &[(String, String)]) -> Result<Scene> {
    if path.is_dir() {
        return Err(crate::error::Error::in_file(path, "is a folder, not a scene file"));
    }
    if !path.is_file() {
        return Err(crate::error::Error::in_file(path, "scene file not found"));
    }
    let (root, includes) = xml::parse_file_with_includes(path, defines)?;
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut b = Builder::new(base);
    b.mtlx.frame = mtlx_frame(defines);
    b.files.push(path.to_path_buf());
    b.files.extend(includes);
    b.build(&root)
}

/// Loads a scene from text; relative file names resolve against `base_dir`.
pub fn load_str(text: &str, virtual_path: &Path, base_dir: &Path, defines: &[(String, String)]) -> Result<Scene> {
    load_str_with_files(text, virtual_path, base_dir, defines, &[])
}

/// [`load_str`] with some files supplied in memory, by the name the scene uses (for scenes
/// embedded in a binary together with their MaterialX documents).
pub fn load_str_with_files(
    text: &str,
    virtual_path: &Path,
    base_dir: &Path,
    defines: &[(String, String)],
    files: &[(&str, &str)],
) -> Result<Scene> {
    let (root, includes) = xml::parse_with_includes(text, virtual_path, defines)?;
    let mut b = Builder::new(base_dir.to_path_buf());
    b.mtlx.frame = mtlx_frame(defines);
    b.files.extend(includes);
    b.embedded = files.iter().map(|(n, t)| (n.to_string(), t.to_string())).collect();
    b.build(&root)
}

/// The frame MaterialX's `frame` and `time` nodes read: the define `frame` where it is a number
/// (`-D frame=12`, as `render_frames` and the farm's frame template pass it), else their
/// default.
fn mtlx_frame(defines: &[(String, String)]) -> Option<f32> {
    defines
        .iter()
        .rev()
        .find(|(k, _)| k == "frame")
        .and_then(|(_, v)| v.trim().parse::<f32>().ok())
        .filter(|f| f.is_finite())
}

struct Builder {
    base: PathBuf,
    /// How MaterialX documents are read: leniently (an unsupported or broken node fails only
    /// the outputs and material inputs that need it), with the frame their `frame` and `time`
    /// nodes see.
    mtlx: graph::LoadOptions,
    shapes: Vec<Shape>,
    materials: Vec<Material>,
    /// Procedural graphs, one per MaterialX document, and the documents by resolved path.
    graphs: Vec<SceneGraph>,
    documents: HashMap<PathBuf, (u32, Arc<graph::Document>)>,
    /// Graph outputs requested by the textures of the material being built: (graph, output,
    /// scalar); a texture's slot is its index here.
    pending_outputs: Vec<(u32, graph::OutputId)>,
    /// Files supplied in memory, by the name the scene refers to them with.
    embedded: HashMap<String, String>,
    /// The graph-output slot of the material being built's shading normal, if any.
    pending_normal: Option<u32>,
    /// Materials already built, keyed by the address of their XML object (shared `<ref>`s).
    material_ids: HashMap<*const Object, u32>,
    emitters: Vec<Emitter>,
    bitmaps: HashMap<(PathBuf, bool), Arc<Bitmap>>,
    /// Every file read so far ([`Scene::files`]).
    files: Vec<PathBuf>,
}

fn mat4_to_affine(m: Mat4) -> Affine3A {
    Affine3A::from_mat4(m)
}

/// The uv transform of a `to_uv` (the 2D affine part of the 4×4 matrix).
fn to_uv_affine(m: Mat4) -> Affine2 {
    Affine2::from_cols_array(&[m.x_axis.x, m.x_axis.y, m.y_axis.x, m.y_axis.y, m.w_axis.x, m.w_axis.y])
}

fn check_finite_positive(obj: &Object, name: &str, v: f32, allow_zero: bool) -> Result<f32> {
    if !v.is_finite() || v < 0.0 || (!allow_zero && v == 0.0) {
        return Err(obj.error(format!(
            "parameter '{name}' must be a finite {} number, got {v}",
            if allow_zero { "non-negative" } else { "positive" }
        )));
    }
    Ok(v)
}

fn check_rgb(obj: &Object, name: &str, v: Vec3) -> Result<Vec3> {
    if !v.is_finite() || v.min_element() < 0.0 {
        return Err(obj.error(format!("parameter '{name}' must be finite and non-negative, got {v}")));
    }
    Ok(v)
}

impl Builder {
    fn new(base: PathBuf) -> Self {
        Builder {
            base,
            mtlx: graph::LoadOptions { lenient: true, ..graph::LoadOptions::default() },
            shapes: Vec::new(),
            materials: Vec::new(),
            graphs: Vec::new(),
            documents: HashMap::new(),
            pending_outputs: Vec::new(),
            embedded: HashMap::new(),
            pending_normal: None,
            material_ids: HashMap::new(),
            emitters: Vec::new(),
            bitmaps: HashMap::new(),
            files: Vec::new(),
        }
    }

    fn resolve(&self, file: &str) -> PathBuf {
        let p = Path::new(file);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base.join(p)
        }
    }

    fn build(mut self, root: &Object) -> Result<Scene> {
        let sensors = root.children("sensor");
        let sensor = match sensors.as_slice() {
            [s] => s.clone(),
            [] => return Err(root.error("the scene has no <sensor>; add a perspective sensor")),
            [_, s, ..] => return Err(s.error("only one <sensor> per scene is supported")),
        };
        let (camera, rfilter, spp, seed) = self.sensor(&sensor)?;
        let integrator = match root.children("integrator").as_slice() {
            [] => PathSettings { max_depth: u32::MAX, rr_depth: 5 },
            [i] => self.integrator(i)?,
            [_, i, ..] => return Err(i.error("only one <integrator> per scene is supported")),
        };
        for shape in root.children("shape") {
            self.shape(&shape)?;
        }
        for emitter in root.children("emitter") {
            let e = self.emitter(&emitter)?;
            self.emitters.push(e);
        }
        for bsdf in root.children("bsdf") {
            // Declared at top level for later <ref>s: validate it even if nothing uses it.
            self.material(&bsdf)?;
        }
        for tex in root.children("texture") {
            self.texture(&tex)?;
        }
        root.check_unused()?;
        if self.shapes.iter().all(|s| s.emitter.is_none()) && self.emitters.is_empty() {
            // Mitsuba renders black without lights; so do we, but say so.
            eprintln!("warning: {}: the scene has no emitters; the image will be black", root.loc);
        }
        let accel =
            crate::accel::build_intersector(&self.shapes, crate::accel::backend()).map_err(|e| root.error(e))?;
        let footprints_needed = self.materials.iter().any(|m| !m.graphs.is_empty());
        let masked = self.materials.iter().any(|m| m.bsdf.is_masked());
        for (k, mg) in self.materials.iter_mut().flat_map(|m| m.graphs.iter_mut()).enumerate() {
            mg.stream = k as u32;
        }
        let infinite =
            self.emitters.iter().enumerate().filter(|(_, e)| e.is_infinite()).map(|(i, _)| i as u32).collect();
        Ok(Scene {
            shapes: self.shapes,
            accel,
            materials: self.materials,
            graphs: self.graphs,
            emitters: self.emitters,
            infinite,
            camera,
            rfilter,
            integrator,
            spp,
            seed,
            // Procedural graphs are filtered by footprint; Mitsuba's bitmaps are not mip-mapped.
            footprints_needed,
            masked,
            files: {
                let mut seen = std::collections::HashSet::new();
                self.files.into_iter().filter(|f| seen.insert(f.clone())).collect()
            },
        })
    }
}
