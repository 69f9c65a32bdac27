//! Fractal (fBm) octave sums.

use super::lattice::{perlin, Dim, HashSel, Lattice, Sel};
use super::perlin::{perlin3_octave, perlin_octave, M3, PERLIN3_VARIANCE};
use crate::nodes::Ctx;
use crate::value::Moments;
use glam::{DVec2, DVec3, Vec2, Vec3};

/// The most octaves a fractal sums: far more than any document asks for (a lacunarity of 2
/// leaves the f32 range after 128), and a bound on the work a node can cost.
pub const MAX_OCTAVES: u32 = 64;

/// A fractal's `octaves` input as a count: rounded, at least 0, at most [`MAX_OCTAVES`].
#[inline]
pub(crate) fn octave_count(x: f32) -> i32 {
    x.round().clamp(0.0, MAX_OCTAVES as f32) as i32
}

/// Whether a fractal octave of amplitude `a` and frequency `f` is summed. Octaves stop once the
/// amplitude leaves [1e-30, 1e30] (below, nothing an f32 sum can hold; above, beyond where a
/// value saturates) or the frequency leaves the f32 range (where every coordinate is a lattice
/// point and the noise is 0): the fractals' total rule, which also bounds their work.
#[inline]
pub(crate) fn octave_counts(a: f64, f: f64) -> bool {
    (1e-30..=1e30).contains(&a.abs()) && f.abs() <= f32::MAX as f64
}

/// `Σ (a·dimʲ)²` over the `remaining` octaves after one of amplitude `a`: the variance weight
/// of the octaves a fractal drops (each is fully filtered to its mean), stopping once the
/// amplitudes fall below 1e-4.
pub(crate) fn remaining_power(a: f64, dim: f64, remaining: i32) -> f64 {
    let mut rest = 0.0;
    let mut ai = a * dim;
    for _ in 0..remaining.clamp(0, 64) {
        if !(1e-4..=1e30).contains(&ai.abs()) {
            break;
        }
        rest += ai * ai;
        ai *= dim;
    }
    rest
}

/// Sums `octaves` filtered Perlin octaves `diminishⁱ perlin((p + offset) · lacunarityⁱ)` (in
/// noise space); `sels(f)` gives the lattices of the octave at frequency `f`.
#[allow(clippy::too_many_arguments)]
pub(super) fn fractal_sum(
    p0: DVec2,
    s0: DVec2,
    octaves: i32,
    lac: f64,
    dim: f64,
    sels: impl Fn(f64) -> [HashSel; 4],
    offs: &[DVec2; 4],
    n: usize,
    ctx: &mut Ctx,
) -> [Moments; 4] {
    let mut acc = [(0.0f64, DVec2::ZERO, 0.0f64); 4];
    let (mut a, mut f) = (1.0f64, 1.0f64);
    let mut oct = [Moments::default(); 4];
    for i in 0..octaves {
        // MaterialX offsets the coordinate before the octave loop: (t + offset) · lacunarityⁱ.
        let offs_i: [DVec2; 4] = offs.map(|o| o * f);
        let sel = sels(f);
        let alive = perlin_octave(p0 * f, s0 * f.abs(), &sel[..n], &offs_i[..n], &mut oct, ctx);
        for k in 0..n {
            let o = &oct[k];
            acc[k].0 += a * o.mean as f64;
            acc[k].1 += DVec2::new(o.grad.x as f64, o.grad.y as f64) * (a * f);
            acc[k].2 += a * a * o.var as f64;
        }
        if !alive {
            // Every further octave is finer still: each contributes its mean (0) and its full
            // variance, without being evaluated.
            let rest = remaining_power(a, dim, octaves - i - 1);
            for a in acc.iter_mut().take(n) {
                a.2 += rest * sel[0].variance();
            }
            break;
        }
        a *= dim;
        f *= lac;
        if !octave_counts(a, f) {
            break;
        }
    }
    let mut out = [Moments::default(); 4];
    for k in 0..n {
        let (m, g, v) = acc[k];
        out[k] = Moments {
            mean: crate::moments::sat(m),
            grad: Vec2::new(crate::moments::sat(g.x), crate::moments::sat(g.y)),
            var: crate::moments::sat(v),
        };
    }
    out
}

/// Unfiltered fractal noise (for tests and the point path).
pub fn fractal_point(p: Vec2, octaves: i32, lacunarity: f32, diminish: f32) -> f32 {
    fractal(p.to_array(), HashSel::Full, octaves, lacunarity, diminish)
}

/// Unfiltered float 3D fractal noise (MaterialX `mx_fractal_noise_float(vec3)`).
pub fn fractal3_point(p: Vec3, octaves: i32, lacunarity: f32, diminish: f32) -> f32 {
    fractal(p.to_array(), Sel::Full, octaves, lacunarity, diminish)
}

/// Unfiltered fractal noise on lattice `sel`: `Σ diminishⁱ perlin(p · lacunarityⁱ)` (f64 sum,
/// f32 octaves) under the fractals' total rule ([`octave_counts`]; the octave stops where the
/// coordinate leaves the f32 range).
#[inline]
fn fractal<const D: usize>(
    p: [f32; D],
    sel: <Dim<D> as Lattice<D>>::Sel,
    octaves: i32,
    lacunarity: f32,
    diminish: f32,
) -> f32
where
    Dim<D>: Lattice<D>,
{
    let (mut r, mut a, mut q) = (0.0f64, 1.0f64, p);
    for _ in 0..octaves.min(MAX_OCTAVES as i32) {
        if !(octave_counts(a, 1.0) && q.iter().all(|x| x.is_finite())) {
            break;
        }
        r += a * perlin(q, sel) as f64;
        a *= diminish as f64;
        q = q.map(|x| x * lacunarity);
    }
    r as f32
}

/// Sums `octaves` filtered 3D Perlin octaves `diminishⁱ perlin3((p + offset) · lacunarityⁱ)`
/// in noise space.
#[allow(clippy::too_many_arguments)]
pub(super) fn fractal_sum3(
    p0: DVec3,
    s0: DVec3,
    octaves: i32,
    lac: f64,
    dim: f64,
    sels: &[Sel],
    offs: &[DVec3],
    ctx: &mut Ctx,
) -> [M3; 4] {
    let n = sels.len();
    let mut acc = [M3::default(); 4];
    let (mut a, mut f) = (1.0f64, 1.0f64);
    let mut oct = [M3::default(); 4];
    let mut offs_i = [DVec3::ZERO; 4];
    for i in 0..octaves {
        for (o, base) in offs_i.iter_mut().zip(offs) {
            *o = *base * f;
        }
        let alive = perlin3_octave(p0 * f, s0 * f.abs(), sels, &offs_i[..n], &mut oct, ctx);
        for k in 0..n {
            acc[k].mean += a * oct[k].mean;
            acc[k].grad += oct[k].grad * (a * f);
            acc[k].var += a * a * oct[k].var;
        }
        if !alive {
            // Every further octave is finer still: its mean (0) and its full variance.
            let rest = remaining_power(a, dim, octaves - i - 1);
            for m in acc.iter_mut().take(n) {
                m.var += rest * PERLIN3_VARIANCE;
            }
            break;
        }
        a *= dim;
        f *= lac;
        if !octave_counts(a, f) {
            break;
        }
    }
    acc
}
