//! Shared helpers for the graph crate's tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// `shared/` beside the workspace root.
pub fn shared() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared")
}

/// An EXR image: width, height, channels (by name), row-major, row 0 = top.
pub struct Exr {
    pub width: usize,
    pub height: usize,
    pub channels: Vec<(String, Vec<f32>)>,
}

impl Exr {
    pub fn channel(&self, name: &str) -> Option<&[f32]> {
        self.channels.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_slice())
    }
}

pub fn read_exr(path: &Path) -> Exr {
    use exr::prelude::*;
    let img = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let size = img.layer_data.size;
    let mut channels = Vec::new();
    for ch in img.layer_data.channel_data.list.iter() {
        let v: Vec<f32> = ch.sample_data.values_as_f32().collect();
        channels.push((ch.name.to_string(), v));
    }
    Exr { width: size.0, height: size.1, channels }
}

/// A deterministic xorshift generator for test sampling.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// Brute-force Gaussian average of output `out` over `uv + l z`, z ~ N(0, I): `samples` points of
/// the R2 sequence shifted by `shift`, through Box–Muller. Per channel: (mean, mean square) of
/// the unfiltered values.
pub fn supersample(
    g: &graph::Graph,
    out: graph::OutputId,
    uv: glam::Vec2,
    l: glam::Mat2,
    shift: (f64, f64),
    samples: usize,
    scratch: &mut graph::EvalScratch,
) -> ([f64; 4], [f64; 4]) {
    let n = g.output(out).ty.channels();
    let (mut acc, mut acc2) = ([0.0f64; 4], [0.0f64; 4]);
    for s in 0..samples {
        let u1 = (shift.0 + 0.754_877_666_246_692_7 * (s as f64 + 0.5)).fract();
        let u2 = (shift.1 + 0.569_840_290_998_053_3 * (s as f64 + 0.5)).fract();
        let r = (-2.0 * u1.max(1e-12).ln()).sqrt();
        let z = glam::Vec2::new(
            (r * (2.0 * std::f64::consts::PI * u2).cos()) as f32,
            (r * (2.0 * std::f64::consts::PI * u2).sin()) as f32,
        );
        let v = g.eval_output(out, &graph::Footprint::point(uv + l * z), scratch);
        for k in 0..n {
            acc[k] += v.ch[k].mean as f64;
            acc2[k] += (v.ch[k].mean as f64).powi(2);
        }
    }
    (acc.map(|a| a / samples as f64), acc2.map(|a| a / samples as f64))
}
