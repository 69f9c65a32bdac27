//! Colour-mapped PNG heat maps with a labelled colour bar, for AOVs a person should read at a
//! glance (footprint LODs per bounce).

use render::film::Image;
use std::path::Path;

/// A perceptually ordered dark-blue → green → yellow ramp (viridis-like), `t` in [0, 1].
pub fn colormap(t: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 6] = [
        [0.267, 0.005, 0.329],
        [0.230, 0.322, 0.546],
        [0.128, 0.567, 0.551],
        [0.369, 0.789, 0.383],
        [0.741, 0.873, 0.150],
        [0.993, 0.906, 0.144],
    ];
    let t = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f32;
    let i = (t as usize).min(STOPS.len() - 2);
    let f = t - i as f32;
    let c: [f32; 3] = std::array::from_fn(|k| STOPS[i][k] * (1.0 - f) + STOPS[i + 1][k] * f);
    c.map(|v| (v * 255.0).round() as u8)
}

/// 3×5 glyphs for the characters labels need.
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '-' => [0, 0, 7, 0, 0],
        '.' => [0, 0, 0, 0, 2],
        'b' => [4, 4, 7, 5, 7],
        _ => [0; 5],
    }
}

struct Canvas {
    w: usize,
    h: usize,
    px: Vec<u8>,
}

impl Canvas {
    fn set(&mut self, x: usize, y: usize, c: [u8; 3]) {
        if x < self.w && y < self.h {
            let i = (y * self.w + x) * 3;
            self.px[i..i + 3].copy_from_slice(&c);
        }
    }

    /// Draws `text` with glyphs scaled by `s`, top-left at (x, y).
    fn text(&mut self, x: usize, y: usize, text: &str, s: usize, c: [u8; 3]) {
        for (k, ch) in text.chars().enumerate() {
            let g = glyph(ch);
            for (row, bits) in g.iter().enumerate() {
                for col in 0..3 {
                    if bits & (4 >> col) != 0 {
                        for dy in 0..s {
                            for dx in 0..s {
                                self.set(x + (k * 4 + col) * s + dx, y + row * s + dy, c);
                            }
                        }
                    }
                }
            }
        }
    }
}

/// Writes the channels of `aov` side by side as heat maps over a shared range, each panel
/// labelled `b1`, `b2`, ..., with a colour bar labelled with the range below. Values equal to
/// `missing` are drawn grey.
pub fn write_heatmap(aov: &Image, missing: f32, path: &Path) -> anyhow::Result<()> {
    let channels = 3;
    let (w, h) = (aov.width as usize, aov.height as usize);
    let valid = aov.pixels.iter().flat_map(|p| [p.x, p.y, p.z]).filter(|v| *v != missing && v.is_finite());
    let (lo, hi) = valid.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    let (lo, hi) = if lo.is_finite() { (lo.floor(), hi.ceil().max(lo.floor() + 1.0)) } else { (0.0, 1.0) };
    let scale = if w < 96 { 1 } else { 2 };
    let gap = 6;
    let label_h = 7 * scale + 4;
    let bar_h = 12;
    let cw = channels * w + (channels + 1) * gap;
    let ch = label_h + h + gap + bar_h + 4 + label_h + gap;
    let mut canvas = Canvas { w: cw, h: ch, px: vec![24; cw * ch * 3] };
    let white = [235, 235, 235];
    for k in 0..channels {
        let x0 = gap + k * (w + gap);
        canvas.text(x0, 2, &format!("b{}", k + 1), scale, white);
        for y in 0..h {
            for x in 0..w {
                let v = aov.pixels[y * w + x][k];
                let c = if v == missing || !v.is_finite() { [96, 96, 96] } else { colormap((v - lo) / (hi - lo)) };
                canvas.set(x0 + x, label_h + y, c);
            }
        }
    }
    let bar_y = label_h + h + gap;
    let bar_w = cw - 2 * gap;
    for x in 0..bar_w {
        let c = colormap(x as f32 / (bar_w - 1).max(1) as f32);
        for y in 0..bar_h {
            canvas.set(gap + x, bar_y + y, c);
        }
    }
    // Integer tick labels along the bar.
    let steps = (hi - lo) as usize;
    let every = steps.div_ceil(8).max(1);
    for i in (0..=steps).step_by(every) {
        let x = gap + (i as f32 / steps.max(1) as f32 * (bar_w - 1) as f32) as usize;
        for y in 0..4 {
            canvas.set(x, bar_y + bar_h + y, white);
        }
        let label = format!("{}", lo as i32 + i as i32);
        let tw = label.len() * 4 * scale;
        canvas.text(x.saturating_sub(tw / 2).min(cw - tw), bar_y + bar_h + 5, &label, scale, white);
    }
    render::film::write_through_temp(path, |tmp| {
        image::save_buffer_with_format(
            tmp,
            &canvas.px,
            cw as u32,
            ch as u32,
            image::ColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(|e| render::error::Error::in_file(path, format!("cannot write PNG: {e}")))
    })?;
    Ok(())
}
