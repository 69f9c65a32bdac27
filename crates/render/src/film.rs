//! The rendered image and how it is written: EXR (linear float32 RGB) or PNG (sRGB, 8-bit),
//! chosen by extension, always through [`crate::output`] (a temporary file moved into place, so
//! that an interrupted write never leaves a truncated image under the final name).

use crate::error::{Error, Result};
use crate::math::Spectrum;
pub use crate::output::{check_file_name, check_output, write_through_temp, MAX_FILE_NAME_BYTES};
use crate::texture::linear_to_srgb;
use std::path::Path;

/// A linear RGB image, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major pixels.
    pub pixels: Vec<Spectrum>,
}

impl Image {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Self {
        Image { width, height, pixels: vec![Spectrum::ZERO; width as usize * height as usize] }
    }

    /// Pixel at (x, y).
    pub fn get(&self, x: u32, y: u32) -> Spectrum {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Writes the image; the format follows the extension (`.exr` or `.png`).
    pub fn save(&self, path: &Path) -> Result<()> {
        let format = check_image_output(path)?;
        write_through_temp(path, |tmp| match format {
            ImageFormat::Exr => self.write_exr(tmp),
            ImageFormat::Png => self.write_png(tmp),
        })
    }

    fn write_exr(&self, tmp: &Path) -> Result<()> {
        use exr::prelude::*;
        let w = self.width as usize;
        let channels = SpecificChannels::rgb(|pos: Vec2<usize>| {
            let p = self.pixels[pos.y() * w + pos.x()];
            (p.x, p.y, p.z)
        });
        // Increasing line order: blocks compressed in parallel are still written in order, so a
        // file's bytes do not depend on thread timing.
        let encoding = Encoding { line_order: LineOrder::Increasing, ..Encoding::default() };
        let image =
            exr::image::Image::from_encoded_channels((self.width as usize, self.height as usize), encoding, channels);
        image.write().to_file(tmp).map_err(|e| crate::error::Error::in_file(tmp, format!("cannot write EXR: {e}")))
    }

    fn write_png(&self, tmp: &Path) -> Result<()> {
        let mut buf = Vec::with_capacity(self.pixels.len() * 3);
        for p in &self.pixels {
            for c in [p.x, p.y, p.z] {
                let v = linear_to_srgb(c.clamp(0.0, 1.0));
                buf.push((v * 255.0 + 0.5).clamp(0.0, 255.0) as u8);
            }
        }
        image::save_buffer_with_format(
            tmp,
            &buf,
            self.width,
            self.height,
            image::ColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(|e| Error::in_file(tmp, format!("cannot write PNG: {e}")))
    }

    /// Reads an EXR written by [`Image::save`] or by another renderer (first RGB(A) layer).
    pub fn load_exr(path: &Path) -> Result<Image> {
        let b = crate::texture::Bitmap::load(path, true)?;
        Ok(Image { width: b.width as u32, height: b.height as u32, pixels: b.texels })
    }
}

/// Bits of a [`PixelSum`] below the unit: samples are summed in multiples of 2⁻⁵⁶ (1.4e-17).
pub const SUM_FRACTION_BITS: i32 = 56;

/// The largest magnitude a sample's channel adds to a [`PixelSum`]: 2⁴⁶ (7.0e13). Larger finite
/// values are clamped to it and counted (`RenderCounts::clamped_samples`), so that 2²⁴ samples
/// (the most `--spp` takes) still sum without overflow.
pub const SAMPLE_LIMIT: f32 = (1u64 << 46) as f32;

/// A pixel's samples summed exactly, in fixed point ([`SUM_FRACTION_BITS`] below the unit, one
/// `i128` per channel).
///
/// Integer addition is associative where floating-point addition is not: sums of any split of a
/// pixel's samples (sample passes rendered apart, `tessera merge`) add up to the very sum a
/// single render makes, so the merged pixel is the single render's bit for bit. Each sample is
/// rounded once, towards zero, to a multiple of 2⁻⁵⁶: far below what an f32 pixel resolves for
/// radiance above 1e-9.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PixelSum(pub [i128; 3]);

/// 2⁶³: scaled samples below it in magnitude convert to integers through i64.
const I64_RANGE: f64 = 9_223_372_036_854_775_808.0;

impl PixelSum {
    const SCALE: f64 = (1u64 << SUM_FRACTION_BITS) as f64;

    /// Adds a finite sample; returns whether a channel was beyond [`SAMPLE_LIMIT`] and clamped.
    #[inline]
    pub fn add(&mut self, l: Spectrum) -> bool {
        let mut clamped = false;
        for (acc, v) in self.0.iter_mut().zip(l.to_array()) {
            let c = v.clamp(-SAMPLE_LIMIT, SAMPLE_LIMIT);
            clamped |= c != v;
            // Exact: a power-of-two scale of an f32 fits an f64, and the product (below 2¹⁰²)
            // converts to an integer by dropping its fraction. Through i64 when it fits (a
            // hardware conversion; f64 to i128 is a library call, 1.3 % of a render), which
            // drops the fraction the same way.
            let scaled = f64::from(c) * Self::SCALE;
            *acc += if scaled.abs() < I64_RANGE { scaled as i64 as i128 } else { scaled as i128 };
        }
        clamped
    }

    /// Adds another sum (of other samples of the same pixel).
    #[inline]
    pub fn merge(&mut self, o: &PixelSum) {
        for (a, b) in self.0.iter_mut().zip(o.0) {
            *a += b;
        }
    }

    /// The mean over `n` samples, rounded to f32 (through f64, the same way wherever the sum
    /// was made).
    #[inline]
    pub fn mean(&self, n: u32) -> Spectrum {
        let n = f64::from(n.max(1));
        let c = |a: i128| ((a as f64 / Self::SCALE) / n) as f32;
        Spectrum::new(c(self.0[0]), c(self.0[1]), c(self.0[2]))
    }
}

/// An image file's format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// OpenEXR, linear float.
    Exr,
    /// PNG, sRGB 8-bit.
    Png,
}

/// Checks an image output before any work is done for it (renders, merges and bakes call this
/// first): its format from the extension, `.exr` or `.png`, and that it can be written
/// ([`check_output`]: a legal file name in a folder that takes new files).
pub fn check_image_output(path: &Path) -> Result<ImageFormat> {
    check_output(path)?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "exr" => Ok(ImageFormat::Exr),
        "png" => Ok(ImageFormat::Png),
        _ => Err(Error::in_file(path, format!("unsupported output format '.{ext}' (expected .exr or .png)"))),
    }
}

/// Relative mean squared error of `a` against `reference`: mean over pixels and channels of
/// (a − r)² / (r² + ε), with ε = 1e-2 so that dark pixels do not dominate.
pub fn relative_mse(a: &Image, reference: &Image) -> f64 {
    assert_eq!((a.width, a.height), (reference.width, reference.height));
    let mut sum = 0.0f64;
    for (p, r) in a.pixels.iter().zip(&reference.pixels) {
        for (x, y) in [(p.x, r.x), (p.y, r.y), (p.z, r.z)] {
            let d = (x - y) as f64;
            sum += d * d / ((y as f64) * (y as f64) + 1e-2);
        }
    }
    sum / (a.pixels.len() as f64 * 3.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples of every magnitude a render meets, from a fixed linear congruential stream.
    fn samples(n: usize, seed: u64) -> Vec<Spectrum> {
        let mut state = seed;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n)
            .map(|_| {
                let mut c = || {
                    let v = (next() * 40.0 - 20.0).exp2() as f32; // 1e-6 to 1e6
                    if next() < 0.1 {
                        -v
                    } else {
                        v
                    }
                };
                Spectrum::new(c(), c(), c())
            })
            .collect()
    }

    /// Any split of a pixel's samples sums to the same bits, and the mean is the f64 mean of the
    /// samples (summed independently, in order) to f32 precision.
    #[test]
    fn the_i64_fast_path_converts_as_i128_does() {
        let scale = (1u64 << SUM_FRACTION_BITS) as f64;
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for k in 0..200_000u32 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            // Magnitudes around the i64 boundary (2⁷ before scaling) and far from it.
            let e = (state % 40) as i32 - 20 + if k % 2 == 0 { 7 } else { 0 };
            let v = f32::from_bits((state >> 40) as u32 | 0x3f80_0000)
                * 2f32.powi(e)
                * if state & 1 == 0 { 1.0 } else { -1.0 };
            let mut s = PixelSum::default();
            s.add(Spectrum::new(v, 0.0, 0.0));
            let c = v.clamp(-SAMPLE_LIMIT, SAMPLE_LIMIT);
            assert_eq!(s.0[0], (f64::from(c) * scale) as i128, "{v:e}");
        }
        for v in [127.99999f32, 128.0, -128.0, 128.00002, SAMPLE_LIMIT, -SAMPLE_LIMIT] {
            let mut s = PixelSum::default();
            s.add(Spectrum::new(v, 0.0, 0.0));
            assert_eq!(s.0[0], (f64::from(v) * scale) as i128, "{v:e}");
        }
    }

    #[test]
    fn pixel_sums_are_exact_whatever_the_split() {
        for seed in 0..20u64 {
            let s = samples(1 + (seed as usize * 37) % 300, seed);
            let mut whole = PixelSum::default();
            for l in &s {
                assert!(!whole.add(*l));
            }
            for cuts in [vec![1], vec![s.len() / 3, s.len() / 2], (1..s.len()).step_by(7).collect()] {
                let mut bounds = vec![0];
                bounds.extend(cuts.into_iter().filter(|&c| c < s.len()));
                bounds.push(s.len());
                let mut parts: Vec<PixelSum> = bounds
                    .windows(2)
                    .map(|w| {
                        let mut p = PixelSum::default();
                        s[w[0]..w[1]].iter().for_each(|l| {
                            p.add(*l);
                        });
                        p
                    })
                    .collect();
                parts.reverse();
                let mut merged = PixelSum::default();
                parts.iter().for_each(|p| merged.merge(p));
                assert_eq!(merged, whole, "seed {seed}, split at {bounds:?}");
            }
            let n = s.len() as u32;
            let mean = whole.mean(n);
            for c in 0..3 {
                let exact: f64 = s.iter().map(|l| f64::from(l[c])).sum::<f64>() / f64::from(n);
                let scale: f64 = s.iter().map(|l| f64::from(l[c]).abs()).sum::<f64>() / f64::from(n);
                assert!(((f64::from(mean[c]) - exact) / scale).abs() < 1e-6, "seed {seed}: {} vs {exact}", mean[c]);
            }
        }
    }

    #[test]
    fn samples_beyond_the_limit_are_clamped_and_said() {
        let mut p = PixelSum::default();
        assert!(p.add(Spectrum::new(1e30, -1e20, 1.0)));
        assert!(!p.add(Spectrum::splat(SAMPLE_LIMIT)));
        let m = p.mean(2);
        assert_eq!((m.x, m.y), (SAMPLE_LIMIT, 0.0));
        // 2^24 samples at the limit (the most --spp takes) do not overflow.
        let mut big = PixelSum::default();
        big.add(Spectrum::splat(SAMPLE_LIMIT));
        let one = big;
        for _ in 0..24 {
            let copy = big;
            big.merge(&copy);
        }
        assert_eq!(big.mean(1 << 24), one.mean(1));
    }

    #[test]
    fn exr_round_trips_and_png_writes() {
        let dir = std::env::temp_dir().join(format!("tessera-film-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut img = Image::new(3, 2);
        img.pixels[4] = Spectrum::new(0.25, 2.5, 1e-3);
        let p = dir.join("a.exr");
        img.save(&p).unwrap();
        assert_eq!(Image::load_exr(&p).unwrap(), img);
        img.save(&dir.join("a.png")).unwrap();
        assert!(img.save(&dir.join("a.tiff")).is_err());
        // No temporary files are left behind.
        let leftovers: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
            .collect();
        assert!(leftovers.is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
