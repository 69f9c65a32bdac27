//! Textures of the Mitsuba subset: constants, `checkerboard` and `bitmap`.

use crate::error::{Error, Result};
use crate::math::{luminance, Spectrum};
use glam::{Affine2, Vec2, Vec3};
use std::path::Path;
use std::sync::Arc;

/// The most pixels an image file may hold (2^28, as many as a film may have): checked against
/// the header before any pixel is decoded.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// The largest EXR block (a run of scan lines, or a tile) decoded without checking that the
/// file is large enough to hold it ([`MAX_EXR_EXPANSION`]).
const MAX_EXR_BLOCK_BYTES: u64 = 64 << 20;

/// More than any EXR compression expands data: deflate's limit is about 1032:1.
const MAX_EXR_EXPANSION: u64 = 2048;

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
        let file_bytes = std::fs::metadata(path).map_or(u64::MAX, |m| m.len());
        for header in &meta.headers {
            let (w, h) = (header.layer_size.width() as u64, header.layer_size.height() as u64);
            if w.saturating_mul(h) > MAX_IMAGE_PIXELS {
                return Err(crate::error::Error::in_file(
                    path,
                    format!("EXR image of {w}×{h} pixels exceeds the limit of {MAX_IMAGE_PIXELS} pixels"),
                ));
            }
            // The decoder sizes and fills a buffer for each block (a run of scan lines, or a
            // tile) from the header before it reads the block: a header of a few bytes may
            // claim blocks of gigabytes (a line 8 million pixels wide in 32-line PIZ blocks is
            // 2 GB). A block's data is in the file, compressed at most about 1032:1 (deflate's
            // limit; EXR's other methods compress less), so a block over 64 MiB needs a file of
            // at least 1/2048 of its size.
            let block_pixels = match header.blocks {
                exr::meta::BlockDescription::ScanLines => {
                    (header.compression.scan_lines_per_block() as u64).saturating_mul(w)
                }
                exr::meta::BlockDescription::Tiles(t) => {
                    (t.tile_size.width() as u64).saturating_mul(t.tile_size.height() as u64)
                }
            };
            let block_bytes = block_pixels.saturating_mul(header.channels.bytes_per_pixel as u64);
            if block_bytes > MAX_EXR_BLOCK_BYTES && block_bytes / MAX_EXR_EXPANSION > file_bytes {
                return Err(crate::error::Error::in_file(
                    path,
                    format!(
                        "EXR header claims blocks of {} MiB ({w}×{h} pixels), more than a file of {file_bytes} bytes can hold: the file is truncated or its header is corrupt",
                        block_bytes >> 20
                    ),
                ));
            }
        }
        // The pixels as plain float triples, whose zeroed allocation the system commits only
        // as the decoder writes them: a header under the limit may still claim 2^28 pixels
        // (3 GiB) that the file does not hold, and filling them with `Vec3::ZERO` up front took
        // that memory and seconds before the missing data was noticed.
        let image = read_first_rgba_layer_from_file(
            path,
            |res, _| {
                let (w, h) = (res.width(), res.height());
                (w, h, vec![[0.0f32; 3]; w * h])
            },
            |(w, _, px): &mut (usize, usize, Vec<[f32; 3]>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                px[pos.y() * *w + pos.x()] = [r, g, b];
            },
        )
        .map_err(|e| crate::error::Error::in_file(path, format!("cannot read EXR: {e}")))?;
        let (width, height, texels) = image.layer_data.channel_data.pixels;
        Ok(Bitmap { width, height, texels: texels.into_iter().map(Vec3::from).collect() })
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

    /// An EXR header: half-float channels B, G, R (type 1, linear 0, sampling 1 × 1),
    /// `compression` (4: PIZ), data and display windows (0, 0)..(w − 1, h − 1), then `tail`.
    fn exr_with_header(compression: u8, w: i32, h: i32, tail: &[u8]) -> Vec<u8> {
        let attr = |name: &str, ty: &str, value: &[u8]| {
            [name.as_bytes(), b"\0", ty.as_bytes(), b"\0", &(value.len() as i32).to_le_bytes(), value].concat()
        };
        let one = 1i32.to_le_bytes();
        let channels: Vec<u8> = ["B", "G", "R"]
            .iter()
            .flat_map(|c| [c.as_bytes(), b"\0", &one, &[0, 0, 0, 0], &one, &one].concat())
            .chain([0])
            .collect();
        let window: Vec<u8> = [0, 0, w - 1, h - 1].iter().flat_map(|v: &i32| v.to_le_bytes()).collect();
        [
            &[0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0][..],
            &attr("channels", "chlist", &channels),
            &attr("compression", "compression", &[compression]),
            &attr("dataWindow", "box2i", &window),
            &attr("displayWindow", "box2i", &window),
            &[0],
            tail,
        ]
        .concat()
    }

    /// Loads `file` (written as `name`) and returns the error and how much the process's peak
    /// resident memory grew meanwhile (0 where /proc/self/status is not there).
    fn exr_load_error(name: &str, file: &[u8]) -> (String, u64) {
        // A folder per file (every test names its own), removed once read.
        let dir = std::env::temp_dir().join(format!("tessera_texture_tests_{}_{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, file).unwrap();
        let before = peak_rss_bytes();
        let e = Bitmap::load(&path, false).expect_err("a bad EXR must be refused").to_string();
        let _ = std::fs::remove_dir_all(&dir);
        let grew = match (before, peak_rss_bytes()) {
            (Some(a), Some(b)) => b.saturating_sub(a),
            _ => 0,
        };
        (e, grew)
    }

    /// The process's peak resident memory in bytes (Linux), for tests that bound an allocation.
    fn peak_rss_bytes() -> Option<u64> {
        let status = std::fs::read_to_string("/proc/self/status").ok()?;
        let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
        Some(line.split_whitespace().nth(1)?.parse::<u64>().ok()? * 1024)
    }

    /// Found by fuzzing (fuzz/fuzz_targets/exr.rs): an EXR header of 2^28 pixels (at the limit)
    /// with no pixel data after it is an error, as it was, but it no longer fills 3 GiB of
    /// texels first (1.4 s and 3 GiB resident, for a file of 150 bytes).
    #[test]
    fn exr_header_without_data_is_an_error_without_a_huge_allocation() {
        let (e, grew) = exr_load_error("fuzz_no_data.exr", &exr_with_header(4, 16384, 16384, &[]));
        assert!(e.contains("fuzz_no_data.exr") && e.contains("cannot read EXR"), "{e}");
        assert!(grew < 1 << 30, "refusing it took {} MiB more memory", grew >> 20);
    }

    /// Found by fuzzing: a line 8 323 200 pixels wide, in PIZ blocks of 32 lines (1.6 GB for
    /// three half channels), whose one block claims 1.3 GB made the decoder fill a 1.3 GB buffer
    /// before it found the file short (214 bytes). Such blocks are now refused from the header.
    #[test]
    fn exr_blocks_larger_than_the_file_can_hold_are_refused() {
        let header_len = exr_with_header(4, 8_323_200, 1, &[]).len() as u64;
        // The offset table (one block, right after it), the block's y and claimed size, 8 bytes.
        let tail =
            [&(header_len + 8).to_le_bytes()[..], &0i32.to_le_bytes(), &0x5000_0000i32.to_le_bytes(), &[0; 8]].concat();
        let (e, grew) = exr_load_error("fuzz_huge_block.exr", &exr_with_header(4, 8_323_200, 1, &tail));
        assert!(e.contains("fuzz_huge_block.exr") && e.contains("more than a file of"), "{e}");
        assert!(grew < 1 << 30, "refusing it took {} MiB more memory", grew >> 20);
        // A block under 64 MiB is decoded (and found short) as before.
        let (e, _) = exr_load_error("short_block.exr", &exr_with_header(4, 4096, 1, &tail));
        assert!(e.contains("cannot read EXR"), "{e}");
    }

    #[test]
    fn srgb_round_trips() {
        for c in [0.0, 0.001, 0.2, 0.5, 1.0] {
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5);
        }
    }
}
