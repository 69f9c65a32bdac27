//! BSDFs (their parameters are listed in each model's file under [`crate::bsdf`]) and the
//! materials built from them, MaterialX materials included.

use super::{check_finite_positive, check_rgb, Builder};
use crate::bsdf::{conductor_preset, BsdfDesc, MicrofacetKind};
use crate::error::Result;
use crate::material::{Material, MaterialGraph};
use crate::texture::Texture;
use crate::xml::Object;
use glam::{Vec2, Vec3};
use std::rc::Rc;

impl Builder {
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

    pub(super) fn material(&mut self, obj: &Rc<Object>) -> Result<u32> {
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

    pub(super) fn default_material(&mut self) -> u32 {
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
}
