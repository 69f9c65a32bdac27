//! Image error for benchmarks: relative MSE on linear radiance and LDR-ꟻLIP (Andersson et al.,
//! "FLIP: A Difference Evaluator for Alternating Images", HPG 2020) on the sRGB images a person
//! would look at.
//!
//! ꟻLIP is computed by NVIDIA's own C++ implementation through the `nv-flip` crate (gfx-rs's
//! bindings, which compile the bundled sources with the system C++ compiler), so the numbers are
//! those of the published tool. Both images are converted to 8-bit sRGB exactly as `tessera
//! render` writes PNGs (clamped to [0, 1], sRGB-encoded, rounded), then compared at
//! [`PIXELS_PER_DEGREE`].

use anyhow::{bail, Result};
use render::film::Image;
use render::texture::linear_to_srgb;

/// Observer distance, screen size and resolution as pixels per degree of visual angle: ꟻLIP's
/// default (a 0.7 m wide 4K monitor seen from 0.7 m).
pub const PIXELS_PER_DEGREE: f32 = nv_flip::DEFAULT_PIXELS_PER_DEGREE;

/// An 8-bit sRGB image, row-major RGB.
#[derive(Clone, Debug, PartialEq)]
pub struct Srgb8 {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major RGB bytes.
    pub data: Vec<u8>,
}

impl Srgb8 {
    /// The image as `tessera render` would write it to a PNG.
    pub fn from_linear(img: &Image) -> Srgb8 {
        let data = img
            .pixels
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .map(|c| (linear_to_srgb(c.clamp(0.0, 1.0)) * 255.0 + 0.5).clamp(0.0, 255.0) as u8)
            .collect();
        Srgb8 { width: img.width, height: img.height, data }
    }

    /// Encodes the image as a PNG in memory.
    pub fn to_png(&self) -> Result<Vec<u8>> {
        use image::ImageEncoder;
        let mut buf = Vec::new();
        image::codecs::png::PngEncoder::new(&mut buf)
            .write_image(&self.data, self.width, self.height, image::ExtendedColorType::Rgb8)
            .map_err(|e| anyhow::anyhow!("cannot encode PNG: {e}"))?;
        Ok(buf)
    }
}

/// The per-pixel ꟻLIP error of `test` against `reference` and its mean.
#[derive(Debug)]
pub struct FlipResult {
    /// Mean of the error map, in [0, 1]: the single number ꟻLIP's authors recommend.
    pub mean: f64,
    /// The error map coloured with ꟻLIP's magma map (black = no visible difference).
    pub map: Srgb8,
}

/// LDR-ꟻLIP of `test` against `reference` (both sRGB).
pub fn flip(reference: &Srgb8, test: &Srgb8) -> Result<FlipResult> {
    check_sizes(reference.width, reference.height, test.width, test.height)?;
    if reference.width == 0 || reference.height == 0 {
        bail!("cannot compare empty images");
    }
    let r = nv_flip::FlipImageRgb8::with_data(reference.width, reference.height, &reference.data);
    let t = nv_flip::FlipImageRgb8::with_data(test.width, test.height, &test.data);
    let errors = nv_flip::flip(r, t, PIXELS_PER_DEGREE);
    let values = errors.to_vec();
    let mean = values.iter().map(|&v| v as f64).sum::<f64>() / values.len() as f64;
    let colored = errors.apply_color_lut(&nv_flip::magma_lut());
    let map = Srgb8 { width: colored.width(), height: colored.height(), data: colored.to_vec() };
    Ok(FlipResult { mean, map })
}

/// Relative MSE of `test` against `reference` on linear radiance (see
/// [`render::film::relative_mse`]), with a size check instead of a panic.
pub fn relative_mse(reference: &Image, test: &Image) -> Result<f64> {
    check_sizes(reference.width, reference.height, test.width, test.height)?;
    Ok(render::film::relative_mse(test, reference))
}

fn check_sizes(rw: u32, rh: u32, tw: u32, th: u32) -> Result<()> {
    if (rw, rh) != (tw, th) {
        bail!("image is {tw}x{th} but the reference is {rw}x{rh}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use render::math::Spectrum;

    /// A test card: a smooth gradient, a hard-edged square and a fine stripe pattern.
    fn card(w: u32, h: u32) -> Image {
        let mut img = Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
                let square = (0.3..0.6).contains(&u) && (0.3..0.6).contains(&v);
                let stripe = if (x / 2) % 2 == 0 { 0.1 } else { 0.0 };
                let base = Spectrum::new(0.2 + 0.5 * u, 0.3 * v + stripe, 0.4);
                img.pixels[(y * w + x) as usize] = if square { Spectrum::new(0.9, 0.1, 0.05) } else { base };
            }
        }
        img
    }

    /// Deterministic noise in [-1, 1] per pixel and channel.
    fn noise(i: usize) -> f32 {
        let mut z = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03;
        z = (z ^ (z >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z ^= z >> 29;
        (z >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    }

    fn noisy(img: &Image, amplitude: f32) -> Image {
        let mut out = img.clone();
        for (i, p) in out.pixels.iter_mut().enumerate() {
            let n = Spectrum::new(noise(3 * i), noise(3 * i + 1), noise(3 * i + 2));
            *p = (*p + n * amplitude).max(Spectrum::ZERO);
        }
        out
    }

    #[test]
    fn identical_images_have_zero_error() {
        let a = Srgb8::from_linear(&card(48, 40));
        let f = flip(&a, &a).unwrap();
        assert_eq!(f.mean, 0.0);
        assert_eq!((f.map.width, f.map.height), (48, 40));
        assert_eq!(relative_mse(&card(48, 40), &card(48, 40)).unwrap(), 0.0);
    }

    #[test]
    fn flip_is_symmetric_and_bounded() {
        let a = card(40, 40);
        let (sa, sb) = (Srgb8::from_linear(&a), Srgb8::from_linear(&noisy(&a, 0.2)));
        let ab = flip(&sa, &sb).unwrap().mean;
        let ba = flip(&sb, &sa).unwrap().mean;
        assert!(ab > 0.0 && ab < 1.0, "{ab}");
        assert!((ab - ba).abs() <= 1e-6 * ab, "{ab} vs {ba}");
    }

    #[test]
    fn flip_and_mse_grow_with_noise_amplitude() {
        let a = card(40, 40);
        let sa = Srgb8::from_linear(&a);
        let mut last = (0.0, 0.0);
        for amp in [0.01, 0.03, 0.1, 0.3] {
            let b = noisy(&a, amp);
            let f = flip(&sa, &Srgb8::from_linear(&b)).unwrap().mean;
            let m = relative_mse(&a, &b).unwrap();
            assert!(f > last.0 && m > last.1, "amplitude {amp}: flip {f} mse {m} after {last:?}");
            last = (f, m);
        }
    }

    #[test]
    fn size_mismatch_is_an_error_not_a_panic() {
        let a = Srgb8::from_linear(&card(8, 8));
        let b = Srgb8::from_linear(&card(8, 9));
        assert!(flip(&a, &b).unwrap_err().to_string().contains("8x9"));
        assert!(relative_mse(&card(8, 8), &card(9, 8)).is_err());
    }

    #[test]
    fn png_encoding_round_trips() {
        let a = Srgb8::from_linear(&card(7, 5));
        let png = a.to_png().unwrap();
        let back = image::load_from_memory(&png).unwrap().into_rgb8();
        assert_eq!(back.into_raw(), a.data);
    }
}
