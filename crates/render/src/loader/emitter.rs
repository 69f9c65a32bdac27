//! Top-level emitters (their parameters are listed in [`crate::emitter`]).

use super::{check_finite_positive, check_rgb, Builder};
use crate::emitter::{Emitter, EnvMap};
use crate::error::Result;
use crate::xml::Object;
use glam::{Mat3, Mat4, Vec3};

impl Builder {
    /// Builds one top-level `<emitter>`; the parameters of each type are listed in
    /// [`crate::emitter`]. An `area` emitter is read by [`Builder::shape`] instead.
    pub(super) fn emitter(&mut self, obj: &Object) -> Result<Emitter> {
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
