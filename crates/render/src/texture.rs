//! Textures of the Mitsuba subset: constants, `checkerboard` and `bitmap`.

use crate::error::{Error, Result};
use crate::math::{luminance, Spectrum};
use glam::{Affine2, Vec2, Vec3};
use std::path::Path;
use std::sync::Arc;

/// The most pixels an image file may hold (2^28, as many as a film may have): checked against
/// the header before any pixel is decoded.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// How a bitmap treats uv outside [0, 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WrapMode {
    /// Tile the image (Mitsuba's default).
    Repeat,
    /// Tile with every other copy mirrored.
    Mirror,
    /// Clamp to the edge texels.
    Clamp,
}

/// A linear-RGB image held in memory, row 0 at the top of the file.
#[derive(Clone, Debug)]
pub struct Bitmap {
    /// Width in texels.
    pub width: usize,
    /// Height in texels.
    pub height: usize,
    /// Row-major linear RGB texels.
    pub texels: Vec<Spectrum>,
}

/// Converts one sRGB-encoded value in [0, 1] to linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Converts one linear value to sRGB encoding (not clamped).
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

impl Bitmap {
    /// Loads a PNG (8 or 16 bit; sRGB-decoded unless `raw`) or an EXR (linear) image.
    pub fn load(path: &Path, raw: bool) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        if !path.exists() {
            return Err(Error::in_file(path, "image file not found"));
        }
        let bitmap = match ext.as_str() {
            "exr" => Self::load_exr(path)?,
            "png" | "jpg" | "jpeg" => Self::load_ldr(path, raw)?,
            _ => {
                return Err(Error::in_file(path, format!("unsupported image format '.{ext}' (expected .png or .exr)")))
            }
        };
        if bitmap.width == 0 || bitmap.height == 0 {
            return Err(Error::in_file(path, "image has zero size"));
        }
        if bitmap.texels.iter().any(|t| !t.is_finite()) {
            return Err(Error::in_file(path, "image contains NaN or infinite values"));
        }
        Ok(bitmap)
    }

    fn load_ldr(path: &Path, raw: bool) -> Result<Self> {
        let img = image::ImageReader::open(path)
            .map_err(|e| Error::in_file(path, format!("cannot open image: {e}")))?
            .with_guessed_format()
            .map_err(|e| Error::in_file(path, format!("cannot read image: {e}")))?
            .decode()
            .map_err(|e| Error::in_file(path, format!("cannot decode image: {e}")))?;
        let rgb = img.to_rgb32f();
        let (width, height) = (rgb.width() as usize, rgb.height() as usize);
        let decode = |c: f32| if raw { c } else { srgb_to_linear(c) };
        let texels = rgb.pixels().map(|p| Vec3::new(decode(p[0]), decode(p[1]), decode(p[2]))).collect();
        Ok(Bitmap { width, height, texels })
    }

    fn load_exr(path: &Path) -> Result<Self> {
        use exr::prelude::*;
        // The header first: a few bytes may claim any size, and decoding allocates it.
        let meta = exr::meta::MetaData::read_from_file(path, false)
            .map_err(|e| crate::error::Error::in_file(path, format!("cannot read EXR: {e}")))?;
        for h in &meta.headers {
            let (w, h) = (h.layer_size.width() as u64, h.layer_size.height() as u64);
            if w.saturating_mul(h) > MAX_IMAGE_PIXELS {
                return Err(crate::error::Error::in_file(
                    path,
                    format!("EXR image of {w}×{h} pixels exceeds the limit of {MAX_IMAGE_PIXELS} pixels"),
                ));
            }
        }
        let image = read_first_rgba_layer_from_file(
            path,
            |res, _| {
                let (w, h) = (res.width(), res.height());
                (w, h, vec![Vec3::ZERO; w * h])
            },
            |(w, _, px): &mut (usize, usize, Vec<Vec3>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                px[pos.y() * *w + pos.x()] = Vec3::new(r, g, b);
            },
        )
        .map_err(|e| crate::error::Error::in_file(path, format!("cannot read EXR: {e}")))?;
        let (width, height, texels) = image.layer_data.channel_data.pixels;
        Ok(Bitmap { width, height, texels })
    }

    #[inline]
    fn texel(&self, x: i64, y: i64, wrap: WrapMode) -> Spectrum {
        let fix = |i: i64, n: usize| -> usize {
            let n = n as i64;
            match wrap {
                WrapMode::Repeat => i.rem_euclid(n) as usize,
                WrapMode::Clamp => i.clamp(0, n - 1) as usize,
                WrapMode::Mirror => {
                    let m = i.rem_euclid(2 * n);
                    (if m >= n { 2 * n - 1 - m } else { m }) as usize
                }
            }
        };
        self.texels[fix(y, self.height) * self.width + fix(x, self.width)]
    }

    /// Bilinear lookup; uv (0, 0) is the top-left corner of the file, texel centres at (i + ½)/w.
    pub fn bilinear(&self, uv: Vec2, wrap: WrapMode) -> Spectrum {
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        if !(x.is_finite() && y.is_finite()) {
            return Spectrum::ZERO;
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let a = self.texel(x0, y0, wrap).lerp(self.texel(x0 + 1, y0, wrap), fx);
        let b = self.texel(x0, y0 + 1, wrap).lerp(self.texel(x0 + 1, y0 + 1, wrap), fx);
        a.lerp(b, fy)
    }
}

/// What textures may read at a shading point: its uv and, for procedural graphs, the values of
/// the material's graph outputs already evaluated for the point's footprint.
#[derive(Clone, Copy, Debug)]
pub struct ShadeContext<'a> {
    /// Texture coordinates.
    pub uv: Vec2,
    /// The material's graph outputs at this point (filtered to its footprint), by slot.
    pub outputs: &'a [graph::Filtered],
}

impl ShadeContext<'static> {
    /// A context with only uv (materials without graphs).
    pub fn uv(uv: Vec2) -> Self {
        ShadeContext { uv, outputs: &[] }
    }
}

/// A texture bound to a BSDF parameter.
#[derive(Clone, Debug)]
pub enum Texture {
    /// The same value everywhere.
    Constant(Spectrum),
    /// Mitsuba's `checkerboard`: `color0` where the cells' parities agree.
    Checkerboard {
        /// Colour of cells whose parities agree.
        color0: Spectrum,
        /// Colour of the other cells.
        color1: Spectrum,
        /// Transform applied to uv before the pattern.
        to_uv: Affine2,
    },
    /// Mitsuba's `bitmap`, bilinear, no mip-mapping.
    Bitmap {
        /// The image.
        image: Arc<Bitmap>,
        /// Transform applied to uv before the lookup.
        to_uv: Affine2,
        /// Behaviour outside [0, 1).
        wrap: WrapMode,
    },
    /// An output of a procedural graph, evaluated per shading point before the BSDF (see
    /// [`ShadeContext::outputs`]). Negative or NaN values read as 0.
    GraphOutput {
        /// Index into the material's evaluated outputs.
        slot: u32,
        /// A scalar output (float): broadcast to RGB.
        scalar: bool,
    },
}

impl Texture {
    /// The value at the shading point.
    #[inline]
    pub fn eval(&self, ctx: &ShadeContext) -> Spectrum {
        let uv = ctx.uv;
        match self {
            Texture::Constant(c) => *c,
            Texture::Checkerboard { color0, color1, to_uv } => {
                let p = to_uv.transform_point2(uv);
                let fx = p.x - p.x.floor();
                let fy = p.y - p.y.floor();
                if (fx > 0.5) == (fy > 0.5) {
                    *color0
                } else {
                    *color1
                }
            }
            Texture::Bitmap { image, to_uv, wrap } => image.bilinear(to_uv.transform_point2(uv), *wrap),
            Texture::GraphOutput { slot, scalar } => {
                let f = &ctx.outputs[*slot as usize];
                let v = if *scalar {
                    Spectrum::splat(f.ch[0].mean)
                } else {
                    Spectrum::new(f.ch[0].mean, f.ch[1].mean, f.ch[2].mean)
                };
                // `max` maps NaN to 0 as well.
                v.max(Spectrum::ZERO)
            }
        }
    }

    /// A scalar value (the luminance of a colour texture), as Mitsuba's `eval_1`.
    #[inline]
    pub fn eval_float(&self, ctx: &ShadeContext) -> f32 {
        match self {
            Texture::Constant(c) if c.x == c.y && c.y == c.z => c.x,
            Texture::GraphOutput { slot, scalar: true } => ctx.outputs[*slot as usize].ch[0].mean.max(0.0),
            _ => luminance(self.eval(ctx)),
        }
    }

    /// The largest value the texture can take (for bounds and validation).
    pub fn max_value(&self) -> f32 {
        match self {
            Texture::Constant(c) => c.max_element(),
            Texture::Checkerboard { color0, color1, .. } => color0.max_element().max(color1.max_element()),
            Texture::Bitmap { image, .. } => image.texels.iter().fold(0.0f32, |m, t| m.max(t.max_element())),
            Texture::GraphOutput { .. } => f32::INFINITY,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checkerboard_matches_mitsuba_convention() {
        let t = Texture::Checkerboard { color0: Vec3::splat(0.4), color1: Vec3::splat(0.2), to_uv: Affine2::IDENTITY };
        assert_eq!(t.eval(&ShadeContext::uv(Vec2::new(0.25, 0.25))).x, 0.4);
        assert_eq!(t.eval(&ShadeContext::uv(Vec2::new(0.75, 0.25))).x, 0.2);
        assert_eq!(t.eval(&ShadeContext::uv(Vec2::new(0.75, 0.75))).x, 0.4);
        assert_eq!(t.eval(&ShadeContext::uv(Vec2::new(-0.25, 0.25))).x, 0.2);
    }

    #[test]
    fn bilinear_hits_texel_centres_and_wraps() {
        let b = Bitmap { width: 2, height: 1, texels: vec![Vec3::ZERO, Vec3::ONE] };
        assert_eq!(b.bilinear(Vec2::new(0.25, 0.5), WrapMode::Repeat), Vec3::ZERO);
        assert_eq!(b.bilinear(Vec2::new(0.75, 0.5), WrapMode::Repeat), Vec3::ONE);
        assert!((b.bilinear(Vec2::new(0.5, 0.5), WrapMode::Repeat).x - 0.5).abs() < 1e-6);
        // Halfway between the last and (wrapped) first texel.
        assert!((b.bilinear(Vec2::new(1.0, 0.5), WrapMode::Repeat).x - 0.5).abs() < 1e-6);
        assert_eq!(b.bilinear(Vec2::new(1.0, 0.5), WrapMode::Clamp), Vec3::ONE);
    }

    #[test]
    fn srgb_round_trips() {
        for c in [0.0, 0.001, 0.2, 0.5, 1.0] {
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5);
        }
    }
}
