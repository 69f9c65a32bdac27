//! Fractal (fBm) octave sums.

use super::lattice::{perlin, Dim, HashSel, Lattice, Sel};
use super::perlin::{perlin_octave, NoiseMoments, PerlinOctave};
use crate::nodes::Ctx;
use glam::{Vec2, Vec3};

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

/// Sums `octaves` filtered Perlin octaves `diminishⁱ perlin((p + offset) · lacunarityⁱ)` in
/// noise space for `n` channels (`offs` per channel); `sels(f)` gives the channels' lattices
/// at frequency `f` (a 2D slice of 3D noise moves its z with the frequency). Once an octave
/// is filtered out, the finer ones add their variance without being evaluated.
#[allow(clippy::too_many_arguments)]
pub(super) fn fractal_sum<const D: usize>(
    p0: [f64; D],
    s0: [f64; D],
    octaves: i32,
    lac: f64,
    dim: f64,
    sels: impl Fn(f64) -> [<Dim<D> as Lattice<D>>::Sel; 4],
    offs: &[[f64; D]; 4],
    n: usize,
    ctx: &mut Ctx,
) -> [NoiseMoments<D>; 4]
where
    Dim<D>: PerlinOctave<D>,
{
    let mut acc = [NoiseMoments::<D>::default(); 4];
    let (mut a, mut f) = (1.0f64, 1.0f64);
    let mut oct = [NoiseMoments::default(); 4];
    let mut offs_i = [[0.0; D]; 4];
    for i in 0..octaves {
        // MaterialX offsets the coordinate before the octave loop: (t + offset) · lacunarityⁱ.
        // Scaled in place, a copy at a time: `array::map` is not inlined here, and coordinates
        // stored one scalar at a time stall the octave's wider loads of them (store forwarding;
        // either cost the 3D fractal 15–20 % at points).
        let (mut p, mut s) = (p0, s0);
        for a in 0..D {
            p[a] *= f;
            s[a] *= f.abs();
        }
        for (oi, o) in offs_i.iter_mut().zip(offs).take(n) {
            *oi = *o;
            for x in oi.iter_mut() {
                *x *= f;
            }
        }
        let sel = sels(f);
        let alive = perlin_octave::<D>(p, s, &sel[..n], &offs_i[..n], &mut oct, ctx);
        for (acc, o) in acc.iter_mut().zip(&oct).take(n) {
            let o = Dim::<D>::round(*o);
            acc.mean += a * o.mean;
            for (g, og) in acc.grad.iter_mut().zip(o.grad) {
                *g += og * (a * f);
            }
            acc.var += a * a * o.var;
        }
        if !alive {
            // Every further octave is finer still: each contributes its mean (0) and its full
            // variance, without being evaluated.
            let rest = remaining_power(a, dim, octaves - i - 1);
            for a in acc.iter_mut().take(n) {
                a.var += rest * Dim::<D>::variance(sel[0]);
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
