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

use crate::bsdf::{conductor_preset, BsdfDesc, MicrofacetKind};
use crate::camera::{Camera, FovAxis, Rfilter};
use crate::emitter::{Emitter, EnvMap};
use crate::error::Result;
use crate::geometry::{mesh_area_distribution, Accel, Shape, ShapeGeometry};
use crate::material::{Material, MaterialGraph, SceneGraph};
use crate::mesh::{cube_mesh, rectangle_mesh, TriangleMesh};
use crate::scene::{PathSettings, Scene};
use crate::texture::{Bitmap, Texture, WrapMode};
use crate::xml::{self, Object};
use glam::{Affine2, Affine3A, Mat3, Mat4, Vec2, Vec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::Arc;

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
        let accel: Box<dyn crate::geometry::Intersector> =
            Box::new(Accel::build(&self.shapes).map_err(|e| root.error(e))?);
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

    fn integrator(&mut self, obj: &Object) -> Result<PathSettings> {
        if obj.plugin != "path" {
            return Err(obj.error(format!("unknown integrator '{}' (supported: path)", obj.plugin)));
        }
        let max_depth = obj.int("max_depth", -1)?;
        let rr_depth = obj.int("rr_depth", 5)?;
        if max_depth < -1 || max_depth == 0 {
            return Err(obj.error(format!("max_depth must be -1 (unbounded) or at least 1, got {max_depth}")));
        }
        if rr_depth < 1 {
            return Err(obj.error(format!("rr_depth must be at least 1, got {rr_depth}")));
        }
        if obj.bool("hide_emitters", false)? {
            return Err(obj.error("hide_emitters=true is not supported"));
        }
        obj.check_unused()?;
        Ok(PathSettings {
            max_depth: if max_depth < 0 { u32::MAX } else { max_depth.min(u32::MAX as i64) as u32 },
            rr_depth: rr_depth.min(u32::MAX as i64) as u32,
        })
    }

    fn sensor(&mut self, obj: &Object) -> Result<(Camera, Rfilter, u32, u64)> {
        if obj.plugin != "perspective" {
            return Err(obj.error(format!("unknown sensor '{}' (supported: perspective)", obj.plugin)));
        }
        let fov = match (obj.opt_float("fov")?, obj.opt_string("focal_length")?) {
            (Some(f), None) => f,
            (None, Some(fl)) => {
                let mm: f32 = fl
                    .trim_end_matches("mm")
                    .trim()
                    .parse()
                    .map_err(|_| obj.error(format!("focal_length must be like '50mm', got '{fl}'")))?;
                2.0 * (36.0f32 / (2.0 * mm)).atan().to_degrees()
            }
            (None, None) => 2.0 * (36.0f32 / 100.0).atan().to_degrees(),
            (Some(_), Some(_)) => return Err(obj.error("give either fov or focal_length, not both")),
        };
        if !(fov > 0.0 && fov < 180.0) {
            return Err(obj.error(format!("fov must be in (0, 180) degrees, got {fov}")));
        }
        let axis = match obj.string("fov_axis", "x")?.as_str() {
            "x" => FovAxis::X,
            "y" => FovAxis::Y,
            "diagonal" => FovAxis::Diagonal,
            "smaller" => FovAxis::Smaller,
            "larger" => FovAxis::Larger,
            other => {
                return Err(obj.error(format!("fov_axis must be x, y, diagonal, smaller or larger, got '{other}'")))
            }
        };
        let near = obj.float("near_clip", 1e-2)?;
        let far = obj.float("far_clip", 1e4)?;
        if !(near > 0.0 && far > near && far.is_finite()) {
            return Err(obj.error(format!("need 0 < near_clip < far_clip, got {near} and {far}")));
        }
        let to_world = obj.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
        let (mut width, mut height, mut rfilter) = (768u32, 576u32, Rfilter::Gaussian { stddev: 0.5 });
        match obj.children("film").as_slice() {
            [] => {}
            [film] => (width, height, rfilter) = self.film(film)?,
            [_, f, ..] => return Err(f.error("only one <film> per sensor")),
        }
        let (mut spp, mut seed) = (4u32, 0u64);
        match obj.children("sampler").as_slice() {
            [] => {}
            [s] => (spp, seed) = self.sampler(s)?,
            [_, s, ..] => return Err(s.error("only one <sampler> per sensor")),
        }
        obj.check_unused()?;
        let camera = Camera::new(mat4_to_affine(to_world), fov, axis, width, height, near, far);
        Ok((camera, rfilter, spp, seed))
    }

    fn film(&mut self, obj: &Object) -> Result<(u32, u32, Rfilter)> {
        if obj.plugin != "hdrfilm" {
            return Err(obj.error(format!("unknown film '{}' (supported: hdrfilm)", obj.plugin)));
        }
        let width = obj.int("width", 768)?;
        let height = obj.int("height", 576)?;
        if width < 1 || height < 1 {
            return Err(obj.error(format!("film size must be at least 1×1, got {width}×{height}")));
        }
        if (width as u64).saturating_mul(height as u64) > MAX_PIXELS {
            return Err(obj.error(format!("film size {width}×{height} exceeds the limit of {MAX_PIXELS} pixels")));
        }
        // Output format parameters are accepted: tessera picks the format from --out.
        for name in ["pixel_format", "component_format", "file_format"] {
            let _ = obj.opt_string(name)?;
        }
        let _ = obj.bool("banner", false)?;
        let rfilter = match obj.children("rfilter").as_slice() {
            [] => Rfilter::Gaussian { stddev: 0.5 },
            [f] => {
                let r = match f.plugin.as_str() {
                    "box" => Rfilter::Box,
                    "gaussian" => Rfilter::Gaussian {
                        stddev: check_finite_positive(f, "stddev", f.float("stddev", 0.5)?, false)?,
                    },
                    "tent" => {
                        Rfilter::Tent { radius: check_finite_positive(f, "radius", f.float("radius", 1.0)?, false)? }
                    }
                    other => return Err(f.error(format!("unknown rfilter '{other}' (supported: box, gaussian, tent)"))),
                };
                f.check_unused()?;
                r
            }
            [_, f, ..] => return Err(f.error("only one <rfilter> per film")),
        };
        obj.check_unused()?;
        Ok((width as u32, height as u32, rfilter))
    }

    fn sampler(&mut self, obj: &Object) -> Result<(u32, u64)> {
        match obj.plugin.as_str() {
            "independent" => {}
            "stratified" | "multijitter" | "orthogonal" | "ldsampler" => {
                eprintln!("warning: {}: sampler '{}' is rendered with independent samples", obj.loc, obj.plugin);
                let _ = obj.bool("jitter", true)?;
                let _ = obj.int("strength", 2)?;
            }
            other => return Err(obj.error(format!("unknown sampler '{other}' (supported: independent)"))),
        }
        let spp = obj.int("sample_count", 4)?;
        let seed = obj.int("seed", 0)?;
        if !(1..=1 << 24).contains(&spp) {
            return Err(obj.error(format!("sample_count must be between 1 and {}, got {spp}", 1 << 24)));
        }
        if seed < 0 {
            return Err(obj.error(format!("seed must be non-negative, got {seed}")));
        }
        obj.check_unused()?;
        Ok((spp as u32, seed as u64))
    }

    fn bitmap(&mut self, obj: &Object, file: &str, raw: bool) -> Result<Arc<Bitmap>> {
        let path = self.resolve(file);
        if let Some(b) = self.bitmaps.get(&(path.clone(), raw)) {
            return Ok(b.clone());
        }
        if !path.exists() {
            return Err(obj.error(format!("image file '{}' not found", path.display())));
        }
        let b = Arc::new(Bitmap::load(&path, raw)?);
        self.files.push(path.clone());
        self.bitmaps.insert((path, raw), b.clone());
        Ok(b)
    }

    /// A texture object (`bitmap`, `checkerboard`).
    fn texture(&mut self, obj: &Object) -> Result<Texture> {
        let to_uv = if obj.plugin == "mtlx" {
            Affine2::IDENTITY
        } else {
            obj.transform("to_uv")?.map(to_uv_affine).unwrap_or(Affine2::IDENTITY)
        };
        let tex = match obj.plugin.as_str() {
            "bitmap" => {
                let file = obj.opt_string("filename")?.ok_or_else(|| obj.error("bitmap needs a 'filename'"))?;
                let raw = obj.bool("raw", false)?;
                let wrap = match obj.string("wrap_mode", "repeat")?.as_str() {
                    "repeat" => WrapMode::Repeat,
                    "mirror" => WrapMode::Mirror,
                    "clamp" => WrapMode::Clamp,
                    other => return Err(obj.error(format!("wrap_mode must be repeat, mirror or clamp, got '{other}'"))),
                };
                let filter = obj.string("filter_type", "bilinear")?;
                if filter != "bilinear" {
                    return Err(obj.error(format!("filter_type '{filter}' is not supported (supported: bilinear)")));
                }
                Texture::Bitmap { image: self.bitmap(obj, &file, raw)?, to_uv, wrap }
            }
            "checkerboard" => Texture::Checkerboard {
                color0: check_rgb(obj, "color0", obj.rgb("color0", Vec3::splat(0.4))?)?,
                color1: check_rgb(obj, "color1", obj.rgb("color1", Vec3::splat(0.2))?)?,
                to_uv,
            },
            "mtlx" => {
                let file = obj.opt_string("filename")?.ok_or_else(|| obj.error("mtlx texture needs a 'filename'"))?;
                let output = obj
                    .opt_string("output")?
                    .ok_or_else(|| obj.error("mtlx texture needs an 'output' (nodegraph/output, e.g. NG_wood/out)"))?;
                if obj.has("to_uv") {
                    return Err(
                        obj.error_at("to_uv", "mtlx textures place uv inside the graph (place2d), not with to_uv")
                    );
                }
                let (g, doc) = self.document(obj, &file)?;
                let out = doc.graph().output_id(&output).ok_or_else(|| {
                    if let Some((_, reason)) = doc.skipped().iter().find(|(n, _)| *n == output) {
                        return obj
                            .error_at("output", format!("output '{output}' of {file} cannot be evaluated: {reason}"));
                    }
                    let names: Vec<&str> = doc.graph().outputs().iter().map(|o| o.name.as_str()).collect();
                    obj.error_at(
                        "output",
                        format!("'{output}' is not an output of {file} (outputs: {})", names.join(", ")),
                    )
                })?;
                self.graph_texture(obj, g, out, false)?
            }
            other => {
                return Err(obj.error(format!("unknown texture '{other}' (supported: bitmap, checkerboard, mtlx)")))
            }
        };
        obj.check_unused()?;
        Ok(tex)
    }

    /// A colour or float parameter that may also be a nested texture.
    fn texture_param(&mut self, obj: &Object, name: &str, default: Vec3) -> Result<Texture> {
        if let Some(child) = obj.child_named(name) {
            if child.tag != "texture" {
                return Err(child.error(format!(
                    "parameter '{name}' must be a colour, a float or a <texture>, found <{}>",
                    child.tag
                )));
            }
            return self.texture(&child);
        }
        Ok(Texture::Constant(check_rgb(obj, name, obj.rgb(name, default)?)?))
    }

    fn ior(&mut self, obj: &Object, name: &str, default: f32) -> Result<f32> {
        let v = match obj.opt_float(name) {
            Ok(Some(v)) => v,
            Ok(None) => default,
            Err(_) => {
                let s = obj.string(name, "")?;
                crate::bsdf::dielectric_ior_preset(&s).ok_or_else(|| {
                    obj.error(format!(
                        "unknown material '{s}' for '{name}' (give a number or a name such as bk7, water, air)"
                    ))
                })?
            }
        };
        check_finite_positive(obj, name, v, false)
    }

    /// Roughness parameters shared by `roughconductor` and `roughdielectric`.
    fn microfacet(&mut self, obj: &Object) -> Result<(MicrofacetKind, Texture, Texture)> {
        let kind = match obj.string("distribution", "beckmann")?.as_str() {
            "beckmann" => MicrofacetKind::Beckmann,
            "ggx" => MicrofacetKind::Ggx,
            other => {
                return Err(obj.error_at("distribution", format!("distribution must be beckmann or ggx, got '{other}'")))
            }
        };
        let _ = obj.bool("sample_visible", true)?;
        let (au, av) = if obj.has("alpha_u") || obj.has("alpha_v") {
            if obj.has("alpha") {
                return Err(obj.error("give either alpha or alpha_u/alpha_v, not both"));
            }
            (self.roughness_param(obj, "alpha_u")?, self.roughness_param(obj, "alpha_v")?)
        } else {
            let a = self.roughness_param(obj, "alpha")?;
            (a.clone(), a)
        };
        Ok((kind, au, av))
    }

    /// A roughness: a positive finite float (default 0.1) or a float texture.
    fn roughness_param(&mut self, obj: &Object, name: &str) -> Result<Texture> {
        if obj.child_named(name).is_some() {
            return self.texture_param(obj, name, Vec3::splat(0.1));
        }
        let a = obj.float(name, 0.1)?;
        if !(a.is_finite() && a > 0.0) {
            return Err(obj.error_at(name, format!("roughness {name} must be a finite positive number, got {a}")));
        }
        Ok(Texture::Constant(Vec3::splat(a)))
    }

    fn conductor_ior(&mut self, obj: &Object) -> Result<(Vec3, Vec3)> {
        let has_explicit = obj.has("eta") || obj.has("k");
        let (eta, k) = if has_explicit {
            if obj.has("material") {
                return Err(obj.error("give either material or eta/k, not both"));
            }
            (obj.rgb("eta", Vec3::ZERO)?, obj.rgb("k", Vec3::ONE)?)
        } else {
            let m = obj.string("material", "none")?;
            conductor_preset(&m).ok_or_else(|| {
                obj.error_at("material", format!("unknown conductor material '{m}' (supported: none, Au, Ag, Cu, Al)"))
            })?
        };
        let ext = check_finite_positive(obj, "ext_eta", obj.float("ext_eta", 1.0)?, false)?;
        Ok((check_rgb(obj, "eta", eta)? / ext, check_rgb(obj, "k", k)? / ext))
    }

    fn dielectric_eta(&mut self, obj: &Object) -> Result<f32> {
        let int_ior = self.ior(obj, "int_ior", crate::bsdf::DEFAULT_INT_IOR)?;
        let ext_ior = self.ior(obj, "ext_ior", crate::bsdf::DEFAULT_EXT_IOR)?;
        if (int_ior - ext_ior).abs() < 1e-6 {
            return Err(obj.error("int_ior and ext_ior must differ (an index-matched interface is invisible)"));
        }
        Ok(int_ior / ext_ior)
    }

    fn bsdf(&mut self, obj: &Object) -> Result<BsdfDesc> {
        let desc = match obj.plugin.as_str() {
            "diffuse" => BsdfDesc::Diffuse { reflectance: self.texture_param(obj, "reflectance", Vec3::splat(0.5))? },
            "conductor" => {
                let (eta, k) = self.conductor_ior(obj)?;
                BsdfDesc::Conductor { eta, k, specular_reflectance: self.texture_param(obj, "specular_reflectance", Vec3::ONE)? }
            }
            "roughconductor" => {
                let (eta, k) = self.conductor_ior(obj)?;
                let (distribution, alpha_u, alpha_v) = self.microfacet(obj)?;
                BsdfDesc::RoughConductor {
                    eta,
                    k,
                    specular_reflectance: self.texture_param(obj, "specular_reflectance", Vec3::ONE)?,
                    distribution,
                    alpha_u,
                    alpha_v,
                }
            }
            "dielectric" => BsdfDesc::Dielectric {
                eta: self.dielectric_eta(obj)?,
                specular_reflectance: self.texture_param(obj, "specular_reflectance", Vec3::ONE)?,
                specular_transmittance: self.texture_param(obj, "specular_transmittance", Vec3::ONE)?,
            },
            "roughdielectric" => {
                let eta = self.dielectric_eta(obj)?;
                let (distribution, alpha_u, alpha_v) = self.microfacet(obj)?;
                BsdfDesc::RoughDielectric {
                    eta,
                    specular_reflectance: self.texture_param(obj, "specular_reflectance", Vec3::ONE)?,
                    specular_transmittance: self.texture_param(obj, "specular_transmittance", Vec3::ONE)?,
                    distribution,
                    alpha_u,
                    alpha_v,
                }
            }
            "twosided" => {
                let inner = obj.children("bsdf");
                match inner.as_slice() {
                    [b] => {
                        if b.plugin == "twosided" {
                            return Err(b.error("twosided cannot nest another twosided"));
                        }
                        BsdfDesc::TwoSided(Box::new(self.bsdf(b)?))
                    }
                    [] => return Err(obj.error("twosided needs one nested <bsdf>")),
                    _ => return Err(obj.error("twosided with a different BSDF on each side is not supported; give one nested <bsdf>")),
                }
            }
            "mask" => {
                // Mitsuba's default opacity is 0.5; a texture may drive it (`<texture name="opacity">`).
                let opacity = self.texture_param(obj, "opacity", Vec3::splat(0.5))?;
                if let Texture::Constant(o) = &opacity {
                    if o.min_element() < 0.0 || o.max_element() > 1.0 {
                        return Err(obj.error(format!(
                            "mask opacity must lie in [0, 1] (0 = clear, 1 = opaque), got ({}, {}, {})",
                            o.x, o.y, o.z
                        )));
                    }
                }
                let inner = match obj.children("bsdf").as_slice() {
                    [b] => self.bsdf(b)?,
                    [] => return Err(obj.error("mask needs one nested <bsdf>")),
                    [_, b, ..] => return Err(b.error("mask takes one nested <bsdf>")),
                };
                let opaque = matches!(&opacity, Texture::Constant(_))
                    && opacity.eval_float(&crate::texture::ShadeContext::uv(Vec2::ZERO)) >= 1.0;
                if opaque {
                    inner
                } else {
                    BsdfDesc::Mask { opacity, scalar: true, bsdf: Box::new(inner) }
                }
            }
            "mtlx" => self.mtlx_material(obj)?,
            other => {
                return Err(obj.error(format!(
                    "unknown bsdf '{other}' (supported: diffuse, conductor, roughconductor, dielectric, roughdielectric, twosided, mask, mtlx)"
                )))
            }
        };
        obj.check_unused()?;
        Ok(desc)
    }

    fn material(&mut self, obj: &Rc<Object>) -> Result<u32> {
        let key = Rc::as_ptr(obj);
        if let Some(&i) = self.material_ids.get(&key) {
            return Ok(i);
        }
        self.pending_outputs.clear();
        self.pending_normal = None;
        let desc = self.bsdf(obj)?;
        let mut material = self.finish_material(desc);
        material.name = obj.id.clone().unwrap_or_else(|| format!("{} at {}", obj.plugin, obj.loc));
        let i = self.materials.len() as u32;
        self.materials.push(material);
        self.material_ids.insert(key, i);
        Ok(i)
    }

    /// Builds one `<shape>` with its BSDF and area light; its parameters are listed in the
    /// module docs' "Shapes" section.
    fn shape(&mut self, obj: &Object) -> Result<()> {
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

    fn default_material(&mut self) -> u32 {
        let i = self.materials.len() as u32;
        self.materials.push(Material::plain(BsdfDesc::default()));
        i
    }

    /// Groups the graph outputs the material's textures asked for into one plan per graph.
    fn finish_material(&mut self, bsdf: BsdfDesc) -> Material {
        let slot_count = self.pending_outputs.len() as u32;
        let mut graphs: Vec<MaterialGraph> = Vec::new();
        let mut order: Vec<u32> = Vec::new();
        for &(g, _) in &self.pending_outputs {
            if !order.contains(&g) {
                order.push(g);
            }
        }
        for g in order {
            let (outputs, slots): (Vec<graph::OutputId>, Vec<u32>) = self
                .pending_outputs
                .iter()
                .enumerate()
                .filter(|(_, (pg, _))| *pg == g)
                .map(|(slot, (_, out))| (*out, slot as u32))
                .unzip();
            let order = self.graphs[g as usize].graph().eval_order(&outputs);
            graphs.push(MaterialGraph { graph: g, order, slots, stream: 0 });
        }
        self.pending_outputs.clear();
        let normal_slot = self.pending_normal.take();
        let mut m =
            Material { name: String::new(), bsdf, graphs, slot_count, constant_outputs: Vec::new(), normal_slot };
        m.compute_constant_outputs(&self.graphs);
        m
    }

    /// `<bsdf type="mtlx">`: a MaterialX `standard_surface`, `open_pbr_surface` or `gltf_pbr`
    /// material (the document maps the latter two onto `standard_surface`'s inputs; see
    /// [`graph::Document::material`]), its inputs constants or graph outputs, inside a
    /// [`BsdfDesc::Mask`] when its opacity is not 1.
    fn mtlx_material(&mut self, obj: &Object) -> Result<BsdfDesc> {
        let file = obj.opt_string("filename")?.ok_or_else(|| obj.error("mtlx bsdf needs a 'filename'"))?;
        let name = obj.opt_string("material")?.ok_or_else(|| obj.error("mtlx bsdf needs a 'material' name"))?;
        let (g, doc) = self.document(obj, &file)?;
        let binding = doc.material(&name).ok_or_else(|| {
            obj.error_at(
                "material",
                format!("no material '{name}' in {file} (materials: {})", doc.material_names().join(", ")),
            )
        })?;
        if !binding.unavailable.is_empty() {
            return Err(obj.error_at(
                "material",
                format!("material '{name}' of {file} cannot be evaluated: {}", binding.unavailable.join("; ")),
            ));
        }
        for w in &binding.warnings {
            eprintln!("warning: {}: {w}", obj.loc);
        }
        let input = |this: &mut Self, input: &str, default: Vec3| -> Result<Texture> {
            match binding.get(input) {
                Some(graph::MaterialSource::Output(out)) => this.graph_texture(obj, g, *out, false),
                Some(graph::MaterialSource::Constant(v)) => {
                    let c = v.channels();
                    let rgb = if c.len() >= 3 { Vec3::new(c[0], c[1], c[2]) } else { Vec3::splat(c[0]) };
                    if !rgb.is_finite() || rgb.min_element() < 0.0 {
                        return Err(obj.error(format!(
                            "{file}: material '{name}' input {input} must be finite and non-negative, got {rgb}"
                        )));
                    }
                    Ok(Texture::Constant(rgb))
                }
                _ => Ok(Texture::Constant(default)),
            }
        };
        let desc = BsdfDesc::StandardSurface {
            base: input(self, "base", Vec3::splat(0.8))?,
            base_color: input(self, "base_color", Vec3::ONE)?,
            metalness: input(self, "metalness", Vec3::ZERO)?,
            specular: input(self, "specular", Vec3::ONE)?,
            specular_color: input(self, "specular_color", Vec3::ONE)?,
            specular_roughness: input(self, "specular_roughness", Vec3::splat(0.2))?,
            specular_ior: input(self, "specular_IOR", Vec3::splat(1.5))?,
            transmission: input(self, "transmission", Vec3::ZERO)?,
            transmission_color: input(self, "transmission_color", Vec3::ONE)?,
        };
        // Opacity below 1 (constant or from a graph): the BSDF inside a mask, which the
        // integrator renders as partial pass-through. An opaque material keeps the bare BSDF.
        let opaque = match binding.get("opacity") {
            Some(graph::MaterialSource::Constant(v)) => v.channels().iter().all(|&x| x >= 1.0),
            Some(graph::MaterialSource::Output(_)) => false,
            _ => true,
        };
        let desc = if opaque {
            desc
        } else {
            BsdfDesc::Mask { opacity: input(self, "opacity", Vec3::ONE)?, scalar: false, bsdf: Box::new(desc) }
        };
        if let Some(graph::MaterialSource::Output(out)) = binding.get("normal") {
            let g_out = *out;
            match self.graph_texture(obj, g, g_out, false)? {
                Texture::GraphOutput { slot, scalar: false } => self.pending_normal = Some(slot),
                _ => return Err(obj.error(format!("material '{name}': its normal input must be a vector3 output"))),
            }
        }
        Ok(desc)
    }

    /// Loads (once) the MaterialX document `file` named by `obj`; returns its graph index.
    fn document(&mut self, obj: &Object, file: &str) -> Result<(u32, Arc<graph::Document>)> {
        let path = self.resolve(file);
        if let Some(d) = self.documents.get(&path) {
            return Ok(d.clone());
        }
        let doc = if let Some(text) = self.embedded.get(file) {
            graph::Document::parse(text, Path::new(file), &self.mtlx)
        } else if !path.is_file() {
            return Err(obj.error_at("filename", format!("MaterialX document '{}' not found", path.display())));
        } else {
            graph::Document::load_with(&path, &self.mtlx)
        }
        .map_err(|e| obj.error_at("filename", format!("in MaterialX document: {e}")))?;
        for w in doc.warnings() {
            eprintln!("warning: {}: {w}", path.display());
        }
        // Nodes that cannot be evaluated fail only what needs them: here a warning names each,
        // and the outputs left out; a texture or material that needs one is an error.
        for u in doc.unsupported() {
            eprintln!("warning: {}: {u}: what depends on it is left out", path.display());
        }
        if !self.embedded.contains_key(file) {
            self.files.extend(doc.files().iter().cloned());
            let g = doc.graph();
            for id in g.node_ids() {
                for p in g.node_params(id) {
                    if let graph::nodes::Param::File { path, .. } = p {
                        self.files.push(path.clone());
                    }
                }
            }
        }
        let doc = Arc::new(doc);
        let index = self.graphs.len() as u32;
        self.graphs.push(SceneGraph { name: path.display().to_string(), document: doc.clone() });
        self.documents.insert(path, (index, doc.clone()));
        Ok((index, doc))
    }

    /// A texture reading graph output `output` of graph `g`: allocates (or reuses) its slot.
    fn graph_texture(&mut self, obj: &Object, g: u32, output: graph::OutputId, want_scalar: bool) -> Result<Texture> {
        let ty = self.graphs[g as usize].graph().output(output).ty;
        let scalar = match ty {
            graph::ValueType::Float => true,
            graph::ValueType::Color3
            | graph::ValueType::Vector3
            | graph::ValueType::Color4
            | graph::ValueType::Vector4 => false,
            other => {
                return Err(obj.error(format!(
                    "graph output of type {other} cannot drive a BSDF parameter (expected float or color3)"
                )))
            }
        };
        // A colour output in a float slot reads as its luminance (Mitsuba's eval_1).
        let _ = want_scalar;
        let slot = match self.pending_outputs.iter().position(|&(pg, po)| pg == g && po == output) {
            Some(i) => i,
            None => {
                self.pending_outputs.push((g, output));
                self.pending_outputs.len() - 1
            }
        };
        Ok(Texture::GraphOutput { slot: slot as u32, scalar })
    }

    /// Builds one top-level `<emitter>`; the parameters of each type are listed in
    /// [`crate::emitter`]. An `area` emitter is read by [`Builder::shape`] instead.
    fn emitter(&mut self, obj: &Object) -> Result<Emitter> {
        let e = match obj.plugin.as_str() {
            "point" => {
                let mut position = obj.point("position", Vec3::ZERO)?;
                if let Some(m) = obj.transform("to_world")? {
                    position = m.transform_point3(position);
                }
                Emitter::Point { position, intensity: check_rgb(obj, "intensity", obj.rgb("intensity", Vec3::ONE)?)? }
            }
            "constant" => Emitter::Constant { radiance: check_rgb(obj, "radiance", obj.rgb("radiance", Vec3::ONE)?)? },
            "envmap" => {
                let file = obj.opt_string("filename")?.ok_or_else(|| obj.error("envmap needs a 'filename'"))?;
                let scale = check_finite_positive(obj, "scale", obj.float("scale", 1.0)?, true)?;
                let to_world = obj.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
                let lin = Mat3::from_mat4(to_world);
                let rot = Mat3::from_cols(lin.x_axis.normalize(), lin.y_axis.normalize(), lin.z_axis.normalize());
                let bitmap = self.bitmap(obj, &file, false)?;
                let env =
                    EnvMap::new(bitmap, rot, scale).ok_or_else(|| obj.error("envmap image is black everywhere"))?;
                Emitter::Env(Box::new(env))
            }
            "directional" => {
                let mut direction = obj.vector("direction", Vec3::Z)?;
                if let Some(m) = obj.transform("to_world")? {
                    direction = m.transform_vector3(if obj.has("direction") { direction } else { Vec3::Z });
                }
                let direction = direction.normalize_or_zero();
                if direction == Vec3::ZERO || !direction.is_finite() {
                    return Err(obj.error("directional emitter needs a non-zero direction"));
                }
                Emitter::Directional {
                    direction,
                    irradiance: check_rgb(obj, "irradiance", obj.rgb("irradiance", Vec3::ONE)?)?,
                }
            }
            "area" => return Err(obj.error("an area emitter must be nested in a <shape>")),
            other => {
                return Err(obj.error(format!(
                    "unknown emitter '{other}' (supported: area, point, constant, envmap, directional)"
                )))
            }
        };
        obj.check_unused()?;
        Ok(e)
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
    Ok(ShapeGeometry::Mesh { mesh, area })
}
