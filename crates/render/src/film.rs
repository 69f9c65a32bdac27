//! The rendered image and how it is written: EXR (linear float32 RGB) or PNG (sRGB, 8-bit),
//! chosen by extension, always through a temporary file renamed into place so that an
//! interrupted write never leaves a truncated image under the final name.

use crate::error::{Error, Result};
use crate::math::Spectrum;
use crate::texture::linear_to_srgb;
use std::path::{Path, PathBuf};

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
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        if ext != "exr" && ext != "png" {
            return Err(Error::in_file(path, format!("unsupported output format '.{ext}' (expected .exr or .png)")));
        }
        let tmp = temp_path(path);
        let result = match ext.as_str() {
            "exr" => self.write_exr(&tmp),
            _ => self.write_png(&tmp),
        };
        if let Err(e) = result {
            let _ = std::fs::remove_file(&tmp);
            return Err(e);
        }
        std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            Error::in_file(path, format!("cannot move the finished image into place: {e}"))
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

fn temp_path(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
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
