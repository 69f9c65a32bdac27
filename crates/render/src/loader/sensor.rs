//! The `<sensor>` with its `<film>`, `<rfilter>` and `<sampler>`, and the `<integrator>`.

use super::{check_finite_positive, mat4_to_affine, Builder, MAX_PIXELS};
use crate::camera::{Camera, FovAxis, Rfilter};
use crate::error::Result;
use crate::scene::PathSettings;
use crate::xml::Object;
use glam::Mat4;

impl Builder {
    pub(super) fn integrator(&mut self, obj: &Object) -> Result<PathSettings> {
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

    pub(super) fn sensor(&mut self, obj: &Object) -> Result<(Camera, Rfilter, u32, u64)> {
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
}
