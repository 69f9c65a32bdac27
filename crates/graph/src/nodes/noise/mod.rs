//! Noise nodes in 2D and 3D, and the node glue that reads their inputs. The algorithms live in
//! one file each: [`lattice`] (unfiltered Perlin lattices), [`filter`] (the corner kernel's 1D
//! Gaussian expectations), [`perlin`] (filtered Perlin octaves), [`fractal`] (octave sums),
//! [`cell`], [`worley`] and [`unified`].
//!
//! ## 2D noise: `noise2d`, `fractal2d`, `cellnoise2d`, `worleynoise2d`, `unifiednoise2d`
//!
//! | node | inputs (default) | unfiltered (MaterialX 1.39) | filtered evaluation |
//! |---|---|---|---|
//! | `noise2d` | `amplitude` (1), `pivot` (0), `texcoord` (UV0) | `perlin(t) · amplitude + pivot` | exact Gaussian convolution of Perlin's corner kernels for per-axis σ ≤ 0.75 lattice units (every corner whose kernel support meets ±3.5σ, at most 8 per axis); beyond, the value at σ clamped to 0.75 (its corners summed over ±2.5σ) times a per-axis Gaussian damping `exp(−κ(σ² − 0.75²))` least-squares fitted to the exact convolution up to 2.25 (κ 0.34); octave dropped (exactly its mean, 0) once damped below 1e-3; variance within the footprint blends the linearisation and the plane average (`1 −` the mean's fitted variance share) by that share |
//! | `fractal2d` | `amplitude` (1), `octaves` (3), `lacunarity` (2), `diminish` (0.5), `texcoord` (UV0) | `Σ diminishⁱ perlin(t · lacunarityⁱ) · amplitude` | each octave as `noise2d` (exact up to per-axis σ = 0.75 of its own lattice); octaves beyond the footprint's band limit (damped below 1e-3) are never evaluated |
//! | `cellnoise2d` | `texcoord` (UV0) | hash of `floor(t)` in [0, 1] | exact: cell values weighted by the footprint's mass over each cell (σ ≤ 0.5 cells); beyond, the residual around the mean 0.5 shrinks like white noise (`√(σ₀/σ)` per axis) |
//! | `worleynoise2d` | `texcoord` (UV0), `jitter` (1), `style` (0) | distance to the nearest 1–3 jittered feature points (style 0) or the nearest point's cell value (style 1) | 3×3 (σ < 0.2 cells) or 5×5 Gauss–Hermite over the footprint up to σ = 1 cell, blended into the pattern's global mean by σ = 2, then the mean alone |
//! | `unifiednoise2d` (float) | `texcoord` (UV0), `freq` (1,1), `offset` (0,0), `jitter` (1), `outmin` (0), `outmax` (1), `clampoutput` (true), `octaves` (3), `lacunarity` (2), `diminish` (0.5), `type` (0), `style` (0) | `p = t·freq + offset`; raw by `type`: 0 `0.5 + 0.5·perlin(rot(p))`, 1 `cellnoise(rot(p))`, 2 `worley(p, jitter, style)`, 3 `fractal3d(p.x, p.y, z)`, else 0; rotation by and slice `z = (jitter − 1)·90000` (degrees); out `outmin + raw·(outmax − outmin)`, raw clamped to [0, 1] if `clampoutput` | `p` and the rotation exactly (affine); each type as its node above; `fractal3d`'s slice `z = const` of 3D Perlin noise folds both z layers into per-corner in-plane gradients plus a constant, filtered by the same separable corner integrals (scale 0.9820; its own damping rate 0.25 and variance share); the clamp by clamped-ramp moments, the remap exactly |
//!
//! Perlin noise is `0.6616 Σ_c (g_c · (p − c)) W(pₓ − cₓ) W(p_y − c_y)` over lattice corners
//! `c` with `W(d) = 1 − fade(|d|)`: each corner's kernel is separable, so for a footprint with
//! per-axis spreads `σₓ, σ_y` (the marginals: correlation is ignored) its Gaussian average is a
//! sum of products of 1D expectations of piecewise polynomials, integrated exactly by
//! [`axis_terms_exact`] and read by the filters from the table of [`crate::nodes::kernel_table`].
//! Vector outputs use MaterialX's per-channel hash bytes; `vector4`'s fourth channel is float
//! noise at `t + (19, 73)` (`fractal2d`: `t + (19, 193)`), `fractal2d` `vector2` is two float
//! fractals at `t` and `t + (19, 193)`.
//!
//! ## 3D noise: `noise3d`, `fractal3d`, `cellnoise3d`, `worleynoise3d`, `unifiednoise3d`
//!
//! | node | inputs (default) | unfiltered (MaterialX 1.39) | filtered evaluation |
//! |---|---|---|---|
//! | `noise3d` | `amplitude` (1), `pivot` (0), `position` (Pobject) | `perlin3(p) · amplitude + pivot` | exact Gaussian convolution of the separable 3D corner kernels for per-axis σ ≤ 0.25 lattice units, Gaussian damping of the rest beyond, octave dropped (exactly its mean, 0) once damped below 1e-3 |
//! | `fractal3d` | `amplitude` (1), `octaves` (3), `lacunarity` (2), `diminish` (0.5), `position` (Pobject) | `Σ diminishⁱ perlin3(p · lacunarityⁱ) · amplitude` | each octave as `noise3d`; octaves beyond the footprint's band limit are never evaluated (their variance is added) |
//! | `cellnoise3d` | `position` (Pobject) | hash of `floor(p)` in [0, 1] (float; vector3: three hashes) | exact: cell values weighted by the footprint's mass over each cell (σ ≤ 0.5 cells per axis); beyond, the residual around the mean 0.5 shrinks like white noise (`√(σ₀/σ)` per axis) |
//! | `worleynoise3d` | `position` (Pobject), `jitter` (1), `style` (0) | distances to the nearest 1–3 jittered feature points of the 27 cells around `p` (style 0), or the nearest point's cell value (style 1) | Gauss–Hermite over the axes that spread (3 nodes per axis below 0.2 cells, 5 beyond while at most two axes spread), blended into the pattern's global mean between σ = 1 and 2 cells, then the mean alone |
//! | `unifiednoise3d` (float) | `position` (Pobject), `freq` (1,1,1), `offset` (0,0,0), `jitter` (1), `outmin` (0), `outmax` (1), `clampoutput` (true), `octaves` (3), `lacunarity` (2), `diminish` (0.5), `type` (0), `style` (0) | `p = position·freq + offset`, `q = rotate3d(p, (jitter − 1)·90000°, axis (0.1, 1, 0))`; raw by `type`: 0 `0.5 + 0.5·perlin3(q)`, 1 `cellnoise3d(q)`, 2 `worley3d(p, jitter, style)`, 3 `fractal3d(q)`, else 0; out `outmin + raw·(outmax − outmin)`, raw clamped to [0, 1] if `clampoutput` | `p` and `q` exactly (affine); each type as its node; the clamp by clamped-ramp moments, the remap exactly |
//!
//! Vector outputs use MaterialX's per-channel hash bytes (`mx_perlin_noise_vec3(vec3)`):
//! `noise3d` vector2/3 are its first two/three channels, vector4 adds float noise at
//! `p + (19, 73, 29)`; `fractal3d` vector2 is float fractal noise at `p` and `p + (19, 193, 17)`,
//! vector3 the byte channels, vector4 the byte channels and float noise at `p + (19, 193, 17)`.
//!
//! The footprint of the `position` input is read per channel, as the 2D noises read theirs:
//! channel `i`'s standard deviation is its spread along lattice axis `i`, and its uv gradient
//! maps the noise's 3D gradient back to uv. For a surface position (`position` node, the
//! default) the channels' variances are the diagonal of `J Σ Jᵀ`; correlations between axes
//! are ignored (an axis-aligned Gaussian with the right marginals), so a footprint on a plane
//! oblique to the lattice is blurred somewhat more than it needs to be, never less. A flat
//! footprint (a plane z = const) has zero spread along z and is exact in the plane.

mod cell;
mod filter;
mod fractal;
mod lattice;
mod perlin;
#[cfg(test)]
mod tests;
mod unified;
mod worley;

use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::{GeomProp, Source};
use crate::moments::mul;
use crate::value::{Filtered, Moments, ValueType};
use cell::{cellnoise2d, cellnoise3d};
use fractal::{fractal_sum, octave_count};
use glam::{DVec2, DVec3, Vec2};
use lattice::{HashSel, Sel};
use perlin::{perlin_octave, NoiseMoments};
use unified::unified;
use worley::{worley2d, worley3_stats, worley3d, worley_stats, WorleyStats};

#[cfg(test)]
pub(crate) use filter::axis_terms_exact;
#[cfg(test)]
pub(crate) use filter::kernel_expectations;
pub(crate) use filter::AxisTerms;
pub use fractal::{fractal3_point, fractal_point};
pub use lattice::{perlin3, perlin_float};
pub use worley::{worley3_point, worley_point};

pub(crate) const CATEGORIES: &[&str] = &["noise2d", "fractal2d", "cellnoise2d", "worleynoise2d", "unifiednoise2d"];

/// Global statistics of a pattern (mean and variance of each output channel over the plane).
#[derive(Clone, Copy, Debug, Default)]
pub struct PatternStats {
    /// Per-channel mean.
    pub mean: [f32; 3],
    /// Per-channel variance.
    pub var: [f32; 3],
}

/// Noise operations.
#[derive(Debug)]
pub enum NoiseOp {
    /// `noise2d`
    Noise2d,
    /// `fractal2d`
    Fractal2d,
    /// `cellnoise2d`
    Cellnoise2d,
    /// `worleynoise2d`, with its statistics for its (uniform) jitter.
    Worley2d(PatternStats),
    /// `unifiednoise2d`, with the Worley statistics for its (uniform) jitter.
    Unified2d(PatternStats),
}

pub(crate) const CATEGORIES_3D: &[&str] = &["noise3d", "fractal3d", "cellnoise3d", "worleynoise3d", "unifiednoise3d"];

/// 3D noise operations.
#[derive(Debug)]
pub enum Noise3dOp {
    /// `noise3d`
    Noise3d,
    /// `fractal3d`
    Fractal3d,
    /// `cellnoise3d`
    Cellnoise3d,
    /// `worleynoise3d`, with its statistics for its (uniform) jitter.
    Worley3d(Box<WorleyStats>),
    /// `unifiednoise3d`, with the Worley statistics for its (uniform) jitter.
    Unified3d(Box<WorleyStats>),
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let (inputs, types): (&'static [_], fn(ValueType) -> bool) = match category {
        "noise2d" => (
            &[inp!("amplitude", OutOrFloat, One), inp!("pivot", Float, Zero), inp!("texcoord", V2, Uv)],
            types::float_or_vector,
        ),
        "fractal2d" => (
            &[
                inp!("amplitude", OutOrFloat, One),
                inp!("octaves", Int, Splat(3.0)),
                inp!("lacunarity", OutOrFloat, Splat(2.0)),
                inp!("diminish", OutOrFloat, Half),
                inp!("texcoord", V2, Uv),
            ],
            types::float_or_vector,
        ),
        "cellnoise2d" => (&[inp!("texcoord", V2, Uv)], |t| matches!(t, ValueType::Float | ValueType::Vector3)),
        "worleynoise2d" => (&[inp!("texcoord", V2, Uv), inp!("jitter", Float, One), inp!("style", Int, Zero)], |t| {
            matches!(t, ValueType::Float | ValueType::Vector2 | ValueType::Vector3)
        }),
        "unifiednoise2d" => (
            &[
                inp!("texcoord", V2, Uv),
                inp!("freq", V2, Pair(1.0, 1.0)),
                inp!("offset", V2, Zero),
                inp!("jitter", Float, One),
                inp!("outmin", Float, Zero),
                inp!("outmax", Float, One),
                inp!("clampoutput", Bool, One),
                inp!("octaves", Int, Splat(3.0)),
                inp!("lacunarity", Float, Splat(2.0)),
                inp!("diminish", Float, Half),
                inp!("type", Int, Zero),
                inp!("style", Int, Zero),
            ],
            types::float,
        ),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types, build })
}

fn build(category: &str, ty: ValueType, _: &[ValueType], srcs: &[Source], _: &[Param]) -> Result<Op, String> {
    Ok(Op::Noise(match category {
        "noise2d" => NoiseOp::Noise2d,
        "fractal2d" => NoiseOp::Fractal2d,
        "cellnoise2d" => NoiseOp::Cellnoise2d,
        "unifiednoise2d" => {
            let jitter = match &srcs[3] {
                Source::Constant(v) => v.v[0],
                _ => 1.0,
            };
            NoiseOp::Unified2d(worley_stats(jitter, 1))
        }
        _ => {
            let jitter = match &srcs[1] {
                Source::Constant(v) => v.v[0],
                _ => 1.0,
            };
            NoiseOp::Worley2d(worley_stats(jitter, ty.channels()))
        }
    }))
}

const POSITION: Def = Def::Geom(GeomProp::Position);

pub(crate) fn definition3d(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let (inputs, types): (&'static [_], fn(ValueType) -> bool) = match category {
        "noise3d" => (
            &[inp!("amplitude", OutOrFloat, One), inp!("pivot", Float, Zero), inp!("position", V3, POSITION)],
            types::float_or_vector,
        ),
        "fractal3d" => (
            &[
                inp!("amplitude", OutOrFloat, One),
                inp!("octaves", Int, Splat(3.0)),
                inp!("lacunarity", Float, Splat(2.0)),
                inp!("diminish", Float, Half),
                inp!("position", V3, POSITION),
            ],
            types::float_or_vector,
        ),
        "cellnoise3d" => (&[inp!("position", V3, POSITION)], |t| matches!(t, ValueType::Float | ValueType::Vector3)),
        "worleynoise3d" => {
            (&[inp!("position", V3, POSITION), inp!("jitter", Float, One), inp!("style", Int, Zero)], |t| {
                matches!(t, ValueType::Float | ValueType::Vector2 | ValueType::Vector3)
            })
        }
        "unifiednoise3d" => (
            &[
                inp!("position", V3, POSITION),
                inp!("freq", V3, Triple(1.0, 1.0, 1.0)),
                inp!("offset", V3, Zero),
                inp!("jitter", Float, One),
                inp!("outmin", Float, Zero),
                inp!("outmax", Float, One),
                inp!("clampoutput", Bool, One),
                inp!("octaves", Int, Splat(3.0)),
                inp!("lacunarity", Float, Splat(2.0)),
                inp!("diminish", Float, Half),
                inp!("type", Int, Zero),
                inp!("style", Int, Zero),
            ],
            types::float,
        ),
        _ => return None,
    };
    let category = CATEGORIES_3D.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types, build: build3d })
}

fn build3d(category: &str, ty: ValueType, _: &[ValueType], srcs: &[Source], _: &[Param]) -> Result<Op, String> {
    let jitter = |s: &Source| match s {
        Source::Constant(v) => v.v[0],
        _ => 1.0,
    };
    Ok(Op::Noise3d(match category {
        "noise3d" => Noise3dOp::Noise3d,
        "fractal3d" => Noise3dOp::Fractal3d,
        "cellnoise3d" => Noise3dOp::Cellnoise3d,
        "unifiednoise3d" => Noise3dOp::Unified3d(Box::new(worley3_stats(jitter(&srcs[3]), 1))),
        _ => Noise3dOp::Worley3d(Box::new(worley3_stats(jitter(&srcs[1]), ty.channels()))),
    }))
}

/// Hash selections and coordinate offsets per output channel.
fn channel_layout(ty: ValueType, fractal: bool) -> ([HashSel; 4], [[f64; 2]; 4], usize) {
    let off = if fractal { [19.0, 193.0] } else { [19.0, 73.0] };
    let z = [0.0; 2];
    let b = |k| HashSel::Byte(k);
    match ty.channels() {
        1 => ([HashSel::Full; 4], [z; 4], 1),
        2 if fractal => ([HashSel::Full, HashSel::Full, HashSel::Full, HashSel::Full], [z, off, z, z], 2),
        2 => ([b(0), b(1), b(2), b(2)], [z; 4], 2),
        3 => ([b(0), b(1), b(2), b(2)], [z; 4], 3),
        _ => ([b(0), b(1), b(2), HashSel::Full], [z, z, z, off], 4),
    }
}

/// The input coordinate: mean, per-axis spread, and the Jacobian rows (d coordinate / d uv).
fn coordinate(t: &Filtered) -> (DVec2, DVec2, [Vec2; 2]) {
    let p = DVec2::new(t.ch[0].mean as f64, t.ch[1].mean as f64);
    let s = DVec2::new(t.ch[0].sigma() as f64, t.ch[1].sigma() as f64);
    (p, s, [t.ch[0].grad, t.ch[1].grad])
}

/// A 2D channel's noise-space moments as f32 moments, each field through `to_f32` (`as` for an
/// octave's, [`crate::moments::sat`] for a fractal's sums).
#[inline]
fn moments2(m: &NoiseMoments<2>, to_f32: impl Fn(f64) -> f32) -> Moments {
    Moments { mean: to_f32(m.mean), grad: Vec2::new(to_f32(m.grad[0]), to_f32(m.grad[1])), var: to_f32(m.var) }
}

/// Maps a noise-space gradient to a uv gradient.
#[inline]
fn to_uv(m: &Moments, j: &[Vec2; 2]) -> Moments {
    use crate::moments::{add_grad, scale_grad};
    let grad = add_grad(scale_grad(j[0], m.grad.x as f64), scale_grad(j[1], m.grad.y as f64));
    Moments { mean: m.mean, grad, var: m.var }
}

fn noise2d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (amp, pivot, t) = (&ins[0], ins[1].ch[0], &ins[2]);
    let (p, s, j) = coordinate(t);
    let (sels, offs, n) = channel_layout(ty, false);
    let mut oct = [NoiseMoments::default(); 4];
    perlin_octave(p.to_array(), s.to_array(), &sels[..n], &offs[..n], &mut oct, ctx);
    let mut out = Filtered::zero(ty);
    for k in 0..n {
        let v = mul(to_uv(&moments2(&oct[k], |x| x as f32), &j), amp.at(k), ctx.fp);
        out.ch[k] = Moments { mean: v.mean + pivot.mean, grad: v.grad + pivot.grad, var: v.var + pivot.var };
    }
    out
}

fn fractal2d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let amp = &ins[0];
    let octaves = octave_count(ins[1].ch[0].mean);
    let lac = ins[2].ch[0].mean as f64;
    let dim = ins[3].ch[0].mean as f64;
    let (p0, s0, j) = coordinate(&ins[4]);
    let (sels, offs, n) = channel_layout(ty, true);
    let sum = fractal_sum(p0.to_array(), s0.to_array(), octaves, lac, dim, |_| sels, &offs, n, ctx);
    let mut out = Filtered::zero(ty);
    for k in 0..n {
        out.ch[k] = mul(to_uv(&moments2(&sum[k], crate::moments::sat), &j), amp.at(k), ctx.fp);
    }
    out
}

/// Lattices and coordinate offsets per output channel.
fn channel_layout3(ty: ValueType, fractal: bool) -> ([Sel; 4], [[f64; 3]; 4], usize) {
    let off = if fractal { [19.0, 193.0, 17.0] } else { [19.0, 73.0, 29.0] };
    let z = [0.0; 3];
    let b = Sel::Byte;
    match ty.channels() {
        1 => ([Sel::Full; 4], [z; 4], 1),
        2 if fractal => ([Sel::Full; 4], [z, off, z, z], 2),
        2 => ([b(0), b(1), b(2), b(2)], [z; 4], 2),
        3 => ([b(0), b(1), b(2), b(2)], [z; 4], 3),
        _ => ([b(0), b(1), b(2), Sel::Full], [z, z, z, off], 4),
    }
}

/// The input coordinate: mean, per-axis spread, and the channels' uv gradients.
fn coordinate3(t: &Filtered) -> (DVec3, DVec3, [Vec2; 3]) {
    let p = DVec3::new(t.ch[0].mean as f64, t.ch[1].mean as f64, t.ch[2].mean as f64);
    let s = DVec3::new(t.ch[0].sigma() as f64, t.ch[1].sigma() as f64, t.ch[2].sigma() as f64);
    (p, s, [t.ch[0].grad, t.ch[1].grad, t.ch[2].grad])
}

/// Maps noise-space moments to uv moments (the gradient through the coordinate's Jacobian).
#[inline]
fn to_uv3(m: &NoiseMoments<3>, j: &[Vec2; 3]) -> Moments {
    use crate::moments::{add_grad, sat, scale_grad};
    let g = add_grad(add_grad(scale_grad(j[0], m.grad[0]), scale_grad(j[1], m.grad[1])), scale_grad(j[2], m.grad[2]));
    Moments { mean: sat(m.mean), grad: g, var: sat(m.var) }
}

fn noise3d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (amp, pivot) = (&ins[0], ins[1].ch[0]);
    let (p, s, j) = coordinate3(&ins[2]);
    let (sels, offs, n) = channel_layout3(ty, false);
    let mut oct = [NoiseMoments::default(); 4];
    perlin_octave(p.to_array(), s.to_array(), &sels[..n], &offs[..n], &mut oct, ctx);
    let mut out = Filtered::zero(ty);
    for k in 0..n {
        let v = mul(to_uv3(&oct[k], &j), amp.at(k), ctx.fp);
        out.ch[k] = Moments { mean: v.mean + pivot.mean, grad: v.grad + pivot.grad, var: v.var + pivot.var };
    }
    out
}

fn fractal3d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let amp = &ins[0];
    let octaves = octave_count(ins[1].ch[0].mean);
    let (lac, dim) = (ins[2].ch[0].mean as f64, ins[3].ch[0].mean as f64);
    let (p, s, j) = coordinate3(&ins[4]);
    let (sels, offs, n) = channel_layout3(ty, true);
    let sum = fractal_sum(p.to_array(), s.to_array(), octaves, lac, dim, |_| sels, &offs, n, ctx);
    let mut out = Filtered::zero(ty);
    for k in 0..n {
        out.ch[k] = mul(to_uv3(&sum[k], &j), amp.at(k), ctx.fp);
    }
    out
}

pub(crate) fn eval(op: &NoiseOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    match op {
        NoiseOp::Noise2d => noise2d(ty, ins, ctx),
        NoiseOp::Fractal2d => fractal2d(ty, ins, ctx),
        NoiseOp::Cellnoise2d => cellnoise2d(ty, ins, ctx),
        NoiseOp::Worley2d(st) => worley2d(st, ty, ins, ctx),
        NoiseOp::Unified2d(st) => unified::<2>(st, ty, ins, ctx),
    }
}

pub(crate) fn eval3d(op: &Noise3dOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    match op {
        Noise3dOp::Noise3d => noise3d(ty, ins, ctx),
        Noise3dOp::Fractal3d => fractal3d(ty, ins, ctx),
        Noise3dOp::Cellnoise3d => cellnoise3d(ty, ins, ctx),
        Noise3dOp::Worley3d(st) => worley3d(st, ty, ins, ctx),
        Noise3dOp::Unified3d(st) => unified::<3>(st, ty, ins, ctx),
    }
}
