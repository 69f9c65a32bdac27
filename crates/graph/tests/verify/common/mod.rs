//! Shared helpers for the graph crate's tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// A folder for one test's files, removed with them when the test is done (so that test runs
/// leave nothing behind in the temporary directory).
pub struct TestDir(PathBuf);

impl TestDir {
    /// A fresh folder named after the test (and the process, so parallel runs keep apart).
    pub fn new(name: &str) -> TestDir {
        let d = std::env::temp_dir().join(format!("graph-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        TestDir(d)
    }
}

impl std::ops::Deref for TestDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

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

/// One footprint size of an error sweep: mean absolute error, per channel and centre, of the
/// filtered value and of point sampling (the unfiltered value at the centre) against the
/// brute-force Gaussian average; the true spread of the values over the footprint (their
/// standard deviation under the Gaussian) and the σ the node reports.
#[derive(Clone, Copy, Debug)]
pub struct SweepRow {
    pub sigma: f32,
    pub filtered: f64,
    pub point: f64,
    pub spread: f64,
    pub node_sigma: f64,
}

impl SweepRow {
    /// Filtered error as a fraction of point sampling's.
    pub fn ratio(&self) -> f64 {
        self.filtered / self.point.max(1e-12)
    }
}

/// The footprint sizes every sweep spans, in uv units.
pub const SWEEP_SIGMAS: [f32; 10] = [1e-6, 1e-4, 1e-3, 1e-2, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0];

/// Filtered evaluation of `out` against brute-force supersampling: for each σ, `centres` random
/// anisotropic footprints `R diag(σ², (aσ)²) Rᵀ` (aspect a ∈ [0.25, 1], random angle) around
/// centres drawn by `centre`, each against `samples` unfiltered values (`supersample`).
pub fn sweep(
    g: &graph::Graph,
    out: graph::OutputId,
    sigmas: &[f32],
    seed: u64,
    centres: usize,
    samples: usize,
    centre: impl Fn(&mut Rng) -> glam::Vec2,
) -> Vec<SweepRow> {
    use glam::{Mat2, Vec2};
    let mut rng = Rng(seed);
    let mut scratch = graph::EvalScratch::new(g);
    let n = g.output(out).ty.channels();
    let mut rows = Vec::new();
    for &sigma in sigmas {
        let (mut ef, mut ep, mut spread, mut sd) = (0.0, 0.0, 0.0, 0.0);
        for _ in 0..centres {
            let uv = centre(&mut rng);
            let a = 0.25 + 0.75 * rng.uniform() as f32;
            let r = Mat2::from_angle(rng.uniform() as f32 * std::f32::consts::PI);
            let l = r * Mat2::from_diagonal(Vec2::new(sigma, a * sigma));
            let f = g.eval_output(out, &graph::Footprint::new(uv, l * l.transpose()), &mut scratch);
            let p = g.eval_output(out, &graph::Footprint::point(uv), &mut scratch);
            let shift = (rng.uniform(), rng.uniform());
            let (acc, acc2) = supersample(g, out, uv, l, shift, samples, &mut scratch);
            for k in 0..n {
                let b = acc[k];
                ef += (f.ch[k].mean as f64 - b).abs();
                ep += (p.ch[k].mean as f64 - b).abs();
                spread += (acc2[k] - b * b).max(0.0).sqrt();
                sd += f.ch[k].sigma() as f64;
            }
        }
        let d = (centres * n) as f64;
        rows.push(SweepRow { sigma, filtered: ef / d, point: ep / d, spread: spread / d, node_sigma: sd / d });
    }
    rows
}

/// Centres uniform in [-2, 2]²: a few periods of most patterns.
pub fn centre_in_square(rng: &mut Rng) -> glam::Vec2 {
    glam::Vec2::new(rng.uniform() as f32 * 4.0 - 2.0, rng.uniform() as f32 * 4.0 - 2.0)
}

/// The header of a sweep table, for stdout.
pub fn sweep_header() -> String {
    format!(
        "{:<24} {:>8} {:>11} {:>11} {:>8} {:>9} {:>9}",
        "graph", "sigma", "filt err", "point err", "ratio", "spread", "σ(node)"
    )
}

/// A sweep row, for stdout.
pub fn sweep_line(name: &str, r: &SweepRow) -> String {
    format!(
        "{:<24} {:>8.0e} {:>11.2e} {:>11.2e} {:>8.3} {:>9.2e} {:>9.2e}",
        name,
        r.sigma,
        r.filtered,
        r.point,
        r.ratio(),
        r.spread,
        r.node_sigma
    )
}

/// Sweeps as one Markdown table: a row per graph, a column per σ, each cell the filtered error,
/// the point error and their ratio.
pub fn sweep_markdown(sweeps: &[(String, Vec<SweepRow>)]) -> String {
    let Some((_, first)) = sweeps.first() else { return String::new() };
    let mut s = String::from("| graph |");
    for r in first {
        s += &format!(" σ {:.0e} |", r.sigma);
    }
    s += "\n|---|";
    s += &"---:|".repeat(first.len());
    s += "\n";
    for (name, rows) in sweeps {
        s += &format!("| {name} |");
        for r in rows {
            if r.point < 1e-9 && r.filtered < 1e-9 {
                s += " 0 |";
            } else {
                s += &format!(" {:.1e} / {:.1e} ({:.2}) |", r.filtered, r.point, r.ratio());
            }
        }
        s += "\n";
    }
    s
}

/// Writes `text` to `docs/<name>` at the workspace root.
pub fn write_doc(name: &str, text: &str) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs").join(name);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(&path, text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}
