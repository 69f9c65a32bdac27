//! Textures (`bitmap`, `checkerboard`, `mtlx`), the image files they and `envmap` read, and
//! the MaterialX documents whose graph outputs `mtlx` textures and materials read.

use super::{check_rgb, to_uv_affine, Builder};
use crate::error::Result;
use crate::material::SceneGraph;
use crate::texture::{Bitmap, Texture, WrapMode};
use crate::xml::Object;
use glam::{Affine2, Vec3};
use std::path::Path;
use std::sync::Arc;

impl Builder {
    pub(super) fn bitmap(&mut self, obj: &Object, file: &str, raw: bool) -> Result<Arc<Bitmap>> {
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
    pub(super) fn texture(&mut self, obj: &Object) -> Result<Texture> {
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
    pub(super) fn texture_param(&mut self, obj: &Object, name: &str, default: Vec3) -> Result<Texture> {
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

    /// Loads (once) the MaterialX document `file` named by `obj`; returns its graph index.
    pub(super) fn document(&mut self, obj: &Object, file: &str) -> Result<(u32, Arc<graph::Document>)> {
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
    pub(super) fn graph_texture(
        &mut self,
        obj: &Object,
        g: u32,
        output: graph::OutputId,
        want_scalar: bool,
    ) -> Result<Texture> {
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
}
