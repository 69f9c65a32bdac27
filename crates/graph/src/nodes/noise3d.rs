//! 3D noise: `noise3d`, `fractal3d`, `cellnoise3d`, `worleynoise3d`, `unifiednoise3d`.
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

use super::hash::{self, cell3_float, cell3_vec3, ifloor};
use super::noise::{
    axis_terms, fade, gradient3, gradient3_vector, AxisTerms, PatternStats, GRADIENT_SCALE_3D, MAX_AXIS, OCTAVE_CUTOFF,
    PERLIN_SIGMA_POINT,
};
use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::gaussian;
use crate::graph::{GeomProp, Source};
use crate::moments::{add_scaled, affine, mix, mul};
use crate::value::{Filtered, Moments, Value, ValueType};
use glam::{DVec3, Vec2, Vec3};

pub(crate) const CATEGORIES: &[&str] = &["noise3d", "fractal3d", "cellnoise3d", "worleynoise3d", "unifiednoise3d"];

/// Variance of MaterialX's 3D float Perlin noise over space (measured; see the tests).
pub const PERLIN3_VARIANCE: f64 = 0.0695;

/// Per-axis spread up to which 3D Perlin noise is filtered exactly (lattice units): up to here
/// the corner sum visits at most 5 coordinates per axis.
pub const PERLIN3_SIGMA_EXACT: f64 = 0.25;

/// Gaussian damping rate of 3D Perlin noise beyond [`PERLIN3_SIGMA_EXACT`] per axis (fitted to
/// the decay of the exactly filtered noise's RMS between σ = 0.25 and 0.45 — 1.8 to 1.6; see
/// the tests).
pub const PERLIN3_KAPPA: f64 = 1.7;

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

const POSITION: Def = Def::Geom(GeomProp::Position);

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
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
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types, build })
}

fn build(category: &str, ty: ValueType, _: &[ValueType], srcs: &[Source], _: &[Param]) -> Result<Op, String> {
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

// ---------------------------------------------------------------------------------------------
// Unfiltered MaterialX 3D noise (f32, as GLSL computes it).

/// Which lattice a 3D Perlin evaluation uses: the whole corner hash (float noise) or byte `k`
/// of it (channel `k` of vector noise).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Sel {
    Full,
    Byte(u32),
}

impl Sel {
    #[inline]
    fn pick(self, h: u32) -> u32 {
        match self {
            Sel::Full => h,
            Sel::Byte(k) => (h >> (8 * k)) & 0xff,
        }
    }
}

/// MaterialX `mx_perlin_noise_float(vec3)` (`Sel::Full`) or channel `k` of
/// `mx_perlin_noise_vec3(vec3)` (`Sel::Byte(k)`).
fn perlin3_point(p: Vec3, sel: Sel) -> f32 {
    let (x0, y0, z0) = (ifloor(p.x), ifloor(p.y), ifloor(p.z));
    // Fractions from f32's own floor (0 where every f32 is whole: see `perlin_point`).
    let (fx, fy, fz) = (p.x - p.x.floor(), p.y - p.y.floor(), p.z - p.z.floor());
    let (u, v, w) = (fade(fx), fade(fy), fade(fz));
    let g = |dx: i32, dy: i32, dz: i32| {
        let h = sel.pick(hash::hash3(x0.wrapping_add(dx), y0.wrapping_add(dy), z0.wrapping_add(dz)));
        gradient3(h, fx - dx as f32, fy - dy as f32, fz - dz as f32)
    };
    let (s1, t1, r1) = (1.0 - u, 1.0 - v, 1.0 - w);
    let r = r1 * (t1 * (g(0, 0, 0) * s1 + g(1, 0, 0) * u) + v * (g(0, 1, 0) * s1 + g(1, 1, 0) * u))
        + w * (t1 * (g(0, 0, 1) * s1 + g(1, 0, 1) * u) + v * (g(0, 1, 1) * s1 + g(1, 1, 1) * u));
    GRADIENT_SCALE_3D * r
}

/// Unfiltered float 3D Perlin noise (MaterialX `mx_perlin_noise_float(vec3)`).
pub fn perlin3(p: Vec3) -> f32 {
    perlin3_point(p, Sel::Full)
}

/// Unfiltered float 3D fractal noise (MaterialX `mx_fractal_noise_float(vec3)`).
pub fn fractal3_point(p: Vec3, octaves: i32, lacunarity: f32, diminish: f32) -> f32 {
    let (mut r, mut a, mut q) = (0.0f64, 1.0f64, p);
    for _ in 0..octaves.min(super::noise::MAX_OCTAVES as i32) {
        if !(super::noise::octave_counts(a, 1.0) && q.is_finite()) {
            break;
        }
        r += a * perlin3_point(q, Sel::Full) as f64;
        a *= diminish as f64;
        q *= lacunarity;
    }
    r as f32
}

/// Unfiltered MaterialX `mx_worley_noise_*(vec3)` (Euclidean metric): the `n` nearest
/// distances (style 0) or the nearest feature's cell value(s) (style 1).
pub fn worley3_point(p: Vec3, jitter: f32, style: i32, n: usize) -> [f32; 3] {
    let (x0, y0, z0) = (ifloor(p.x), ifloor(p.y), ifloor(p.z));
    let local = Vec3::new(p.x - x0 as f32, p.y - y0 as f32, p.z - z0 as f32);
    let mut d = [1e6f32; 3];
    let mut minpos = Vec3::ZERO;
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                let (cx, cy, cz) = (x0.wrapping_add(x), y0.wrapping_add(y), z0.wrapping_add(z));
                let off = Vec3::new(cell3_vec3(cx, cy, cz, 0), cell3_vec3(cx, cy, cz, 1), cell3_vec3(cx, cy, cz, 2));
                let off = (off - 0.5) * jitter + 0.5;
                let cell = Vec3::new(x as f32, y as f32, z as f32) + off - local;
                let dist = cell.dot(cell);
                if dist < d[0] {
                    d[2] = d[1];
                    d[1] = d[0];
                    d[0] = dist;
                    minpos = cell;
                } else if dist < d[1] {
                    d[2] = d[1];
                    d[1] = dist;
                } else if dist < d[2] {
                    d[2] = dist;
                }
            }
        }
    }
    if style == 1 {
        let q = minpos + p;
        let (ix, iy, iz) = (ifloor(q.x), ifloor(q.y), ifloor(q.z));
        if n == 1 {
            [cell3_float(ix, iy, iz), 0.0, 0.0]
        } else {
            [cell3_vec3(ix, iy, iz, 0), cell3_vec3(ix, iy, iz, 1), cell3_vec3(ix, iy, iz, 2)]
        }
    } else {
        [d[0].sqrt(), d[1].sqrt(), d[2].sqrt()]
    }
}

fn cell_value(c: [i32; 3], k: usize, vector: bool) -> f32 {
    if vector {
        cell3_vec3(c[0], c[1], c[2], k as i32)
    } else {
        cell3_float(c[0], c[1], c[2])
    }
}

// ---------------------------------------------------------------------------------------------
// Filtered 3D Perlin noise.

/// Filtered 3D Perlin noise for up to 4 lattices at once: per channel (value, gradient).
/// `s` are the per-axis spreads, each in [1e-4, [`PERLIN3_SIGMA_EXACT`]].
fn perlin3_exact(p: DVec3, s: DVec3, sels: &[Sel], out: &mut [(f64, DVec3); 4], work: &mut crate::eval::Work) {
    let mut axes = [[(0i32, AxisTerms::default()); MAX_AXIS]; 3];
    let mut n = [0usize; 3];
    for k in 0..3 {
        let (m, sk) = (p[k], s[k]);
        let lo = (m - 1.0 - 4.0 * sk).floor() as i32 + 1;
        let hi = (m + 1.0 + 4.0 * sk).ceil() as i32 - 1;
        n[k] = axis_terms(m, sk, lo, hi, &mut axes[k]);
    }
    for o in out.iter_mut() {
        *o = (0.0, DVec3::ZERO);
    }
    for &(cz, tz) in &axes[2][..n[2]] {
        for &(cy, ty) in &axes[1][..n[1]] {
            // Products of two axes' terms shared by the x loop.
            let (ww, dw_w, w_dw) = (ty.w * tz.w, ty.dw * tz.w, ty.w * tz.dw);
            let (w1w, dw1w, w1dw) = (ty.w1 * tz.w, ty.dw1 * tz.w, ty.w1 * tz.dw);
            let (ww1, dww1, wdw1) = (ty.w * tz.w1, ty.dw * tz.w1, ty.w * tz.dw1);
            for &(cx, tx) in &axes[0][..n[0]] {
                let h = hash::hash3(cx, cy, cz);
                for (k, sel) in sels.iter().enumerate() {
                    let g = gradient3_vector(sel.pick(h));
                    let o = &mut out[k];
                    o.0 += g[0] * tx.dw * ww + g[1] * tx.w * dw_w + g[2] * tx.w * w_dw;
                    o.1.x += g[0] * tx.dw1 * ww + g[1] * tx.w1 * dw_w + g[2] * tx.w1 * w_dw;
                    o.1.y += g[0] * tx.dw * w1w + g[1] * tx.w * dw1w + g[2] * tx.w * w1dw;
                    o.1.z += g[0] * tx.dw * ww1 + g[1] * tx.w * dww1 + g[2] * tx.w * wdw1;
                }
            }
        }
    }
    work.lattice += (n[0] * n[1] * n[2]) as u64;
    let k = GRADIENT_SCALE_3D as f64;
    for o in out.iter_mut().take(sels.len()) {
        *o = (o.0 * k, o.1 * k);
    }
}

/// Filtered moments of one channel in noise space: mean, gradient with respect to the 3D
/// coordinate, variance.
#[derive(Clone, Copy, Debug, Default)]
struct M3 {
    mean: f64,
    grad: DVec3,
    var: f64,
}

/// One filtered 3D Perlin octave for several channels. Returns `false` (means 0, the global
/// variance) when the footprint filters the octave out completely.
fn perlin3_octave(p: DVec3, s: DVec3, sels: &[Sel], offsets: &[DVec3], out: &mut [M3; 4], ctx: &mut Ctx) -> bool {
    ctx.work.octaves += 1;
    let lim = super::noise::LATTICE_PRECISION_LIMIT;
    if offsets.iter().any(|o| !((p + *o).abs().max_element() < lim)) {
        // Every f32 coordinate there is a lattice point, where the noise is 0.
        for o in out.iter_mut() {
            *o = M3::default();
        }
        return true;
    }
    let smax = s.max_element();
    if smax < PERLIN_SIGMA_POINT {
        for (k, sel) in sels.iter().enumerate() {
            let q = p + offsets[k];
            let mut m = M3 { mean: perlin3_point(q.as_vec3(), *sel) as f64, ..M3::default() };
            if !ctx.point {
                let mut r = [(0.0, DVec3::ZERO); 4];
                perlin3_exact(q, DVec3::splat(1e-4), std::slice::from_ref(sel), &mut r, ctx.work);
                m.grad = r[0].1;
                m.var = (m.grad * s).length_squared();
            }
            out[k] = m;
        }
        ctx.work.lattice += 8;
        return true;
    }
    let damp = |s: f64| {
        if s > PERLIN3_SIGMA_EXACT {
            (-PERLIN3_KAPPA * (s * s - PERLIN3_SIGMA_EXACT * PERLIN3_SIGMA_EXACT)).exp()
        } else {
            1.0
        }
    };
    let att = damp(s.x) * damp(s.y) * damp(s.z);
    if att < OCTAVE_CUTOFF {
        for o in out.iter_mut() {
            *o = M3 { mean: 0.0, grad: DVec3::ZERO, var: PERLIN3_VARIANCE };
        }
        return false;
    }
    // Axes without spread (a constant coordinate channel, a plane z = const) get a negligible
    // one: the exact corner integrals divide by σ.
    let se = s.clamp(DVec3::splat(1e-4), DVec3::splat(PERLIN3_SIGMA_EXACT));
    let mut r = [(0.0, DVec3::ZERO); 4];
    if offsets.iter().all(|o| *o == offsets[0]) {
        perlin3_exact(p + offsets[0], se, sels, &mut r, ctx.work);
    } else {
        for (k, sel) in sels.iter().enumerate() {
            let mut one = [(0.0, DVec3::ZERO); 4];
            perlin3_exact(p + offsets[k], se, std::slice::from_ref(sel), &mut one, ctx.work);
            r[k] = one[0];
        }
    }
    let v_glob = PERLIN3_VARIANCE * (1.0 - (-PERLIN3_KAPPA * s.length_squared()).exp());
    for k in 0..sels.len() {
        let (v, g) = (r[k].0 * att, r[k].1 * att);
        let v_lin = (g * s).length_squared();
        out[k] = M3 { mean: v, grad: g, var: v_lin.max(v_glob) };
    }
    true
}

/// Lattices and coordinate offsets per output channel.
fn channel_layout(ty: ValueType, fractal: bool) -> ([Sel; 4], [DVec3; 4], usize) {
    let off = if fractal { DVec3::new(19.0, 193.0, 17.0) } else { DVec3::new(19.0, 73.0, 29.0) };
    let z = DVec3::ZERO;
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
fn coordinate(t: &Filtered) -> (DVec3, DVec3, [Vec2; 3]) {
    let p = DVec3::new(t.ch[0].mean as f64, t.ch[1].mean as f64, t.ch[2].mean as f64);
    let s = DVec3::new(t.ch[0].sigma() as f64, t.ch[1].sigma() as f64, t.ch[2].sigma() as f64);
    (p, s, [t.ch[0].grad, t.ch[1].grad, t.ch[2].grad])
}

/// Maps noise-space moments to uv moments (the gradient through the coordinate's Jacobian).
#[inline]
fn to_uv(m: &M3, j: &[Vec2; 3]) -> Moments {
    use crate::moments::{add_grad, sat, scale_grad};
    let g = add_grad(add_grad(scale_grad(j[0], m.grad.x), scale_grad(j[1], m.grad.y)), scale_grad(j[2], m.grad.z));
    Moments { mean: sat(m.mean), grad: g, var: sat(m.var) }
}

fn noise3d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (amp, pivot) = (&ins[0], ins[1].ch[0]);
    let (p, s, j) = coordinate(&ins[2]);
    let (sels, offs, n) = channel_layout(ty, false);
    let mut oct = [M3::default(); 4];
    perlin3_octave(p, s, &sels[..n], &offs[..n], &mut oct, ctx);
    let mut out = Filtered::zero(ty);
    for k in 0..n {
        let v = mul(to_uv(&oct[k], &j), amp.at(k), ctx.fp);
        out.ch[k] = Moments { mean: v.mean + pivot.mean, grad: v.grad + pivot.grad, var: v.var + pivot.var };
    }
    out
}

/// Sums `octaves` filtered 3D Perlin octaves `diminishⁱ perlin3((p + offset) · lacunarityⁱ)`
/// in noise space.
#[allow(clippy::too_many_arguments)]
fn fractal_sum(
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
            let rest = super::noise::remaining_power(a, dim, octaves - i - 1);
            for m in acc.iter_mut().take(n) {
                m.var += rest * PERLIN3_VARIANCE;
            }
            break;
        }
        a *= dim;
        f *= lac;
        if !super::noise::octave_counts(a, f) {
            break;
        }
    }
    acc
}

fn fractal3d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let amp = &ins[0];
    let octaves = super::noise::octave_count(ins[1].ch[0].mean);
    let (lac, dim) = (ins[2].ch[0].mean as f64, ins[3].ch[0].mean as f64);
    let (p, s, j) = coordinate(&ins[4]);
    let (sels, offs, n) = channel_layout(ty, true);
    let sum = fractal_sum(p, s, octaves, lac, dim, &sels[..n], &offs[..n], ctx);
    let mut out = Filtered::zero(ty);
    for k in 0..n {
        out.ch[k] = mul(to_uv(&sum[k], &j), amp.at(k), ctx.fp);
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Cell noise.

/// Per-axis spread (cells) up to which cell noise is filtered exactly.
const CELL_SIGMA_EXACT: f64 = 0.5;

/// Cells an axis's footprint covers: (cell, mass, d mass / d mean); `None`-like single cell
/// with all the mass when the axis has no spread.
fn cell_axis(m: f64, s: f64, buf: &mut [(i32, f64, f64); 8]) -> usize {
    if s.is_nan() || s <= 1e-12 {
        buf[0] = (m.floor() as i32, 1.0, 0.0);
        return 1;
    }
    let lo = (m - 4.0 * s).floor() as i32;
    let hi = (m + 4.0 * s).floor() as i32;
    let mut n = 0;
    for c in lo..=hi.min(lo + 7) {
        let (a, b) = ((c as f64 - m) / s, (c as f64 + 1.0 - m) / s);
        buf[n] = (c, gaussian::mass(a, b), (gaussian::pdf(a) - gaussian::pdf(b)) / s);
        n += 1;
    }
    n
}

fn cellnoise3d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (p, s, j) = coordinate(&ins[0]);
    let vector = ty == ValueType::Vector3;
    let n = ty.channels();
    let mut out = Filtered::zero(ty);
    if s == DVec3::ZERO {
        let c = [ifloor(p.x as f32), ifloor(p.y as f32), ifloor(p.z as f32)];
        for k in 0..n {
            out.ch[k] = Moments::constant(cell_value(c, k, vector));
        }
        ctx.work.lattice += 1;
        return out;
    }
    let shrink_axis = |s: f64| (CELL_SIGMA_EXACT / s.max(CELL_SIGMA_EXACT)).sqrt();
    let shrink = shrink_axis(s.x) * shrink_axis(s.y) * shrink_axis(s.z);
    if shrink < 0.02 {
        for k in 0..n {
            out.ch[k] = Moments { mean: 0.5, grad: Vec2::ZERO, var: 1.0 / 12.0 };
        }
        return out;
    }
    let se = s.min(DVec3::splat(CELL_SIGMA_EXACT));
    let mut axes = [[(0i32, 0.0f64, 0.0f64); 8]; 3];
    let mut na = [0usize; 3];
    for k in 0..3 {
        na[k] = cell_axis(p[k], se[k], &mut axes[k]);
    }
    ctx.work.lattice += (na[0] * na[1] * na[2]) as u64;
    for k in 0..n {
        let (mut e, mut e2, mut d) = (0.0, 0.0, DVec3::ZERO);
        for &(cz, wz, dwz) in &axes[2][..na[2]] {
            for &(cy, wy, dwy) in &axes[1][..na[1]] {
                for &(cx, wx, dwx) in &axes[0][..na[0]] {
                    let h = cell_value([cx, cy, cz], k, vector) as f64;
                    let w = wx * wy * wz;
                    e += w * h;
                    e2 += w * h * h;
                    d += DVec3::new(dwx * wy * wz, wx * dwy * wz, wx * wy * dwz) * h;
                }
            }
        }
        let var = if shrink < 1.0 { 1.0 / 12.0 - ((e - 0.5) * shrink).powi(2) } else { e2 - e * e };
        let m = M3 { mean: 0.5 + (e - 0.5) * shrink, grad: d * shrink, var: var.max(0.0) };
        out.ch[k] = to_uv(&m, &j);
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Worley noise.

/// Planes of the statistics table: `PLANES` bins of a lattice coordinate's fraction.
const PLANES: usize = 16;

/// Statistics of 3D Worley noise for a jitter: over all of space, and over each plane
/// `coordinate = const` by the coordinate's fraction. The jittered grid is not stationary:
/// planes through cell faces lie farther from the feature points than mid-cell ones, so a
/// footprint that is wide within such a plane but thin across it (a flat surface aligned with
/// the lattice) averages to its plane's statistics, not to the volume's.
#[derive(Clone, Debug)]
pub struct WorleyStats {
    /// Over space.
    pub volume: PatternStats,
    /// Over the plane whose fixed coordinate has fraction `(i + ½)/PLANES`.
    pub planes: [PatternStats; PLANES],
}

/// Statistics of 3D Worley noise for a jitter (sampled on grids; the three axes are
/// statistically alike, so planes are sampled at fixed z).
fn worley3_stats(jitter: f32, n: usize) -> WorleyStats {
    let stats = |sums: ([f64; 3], [f64; 3]), count: f64| {
        let mut st = PatternStats::default();
        for k in 0..3 {
            st.mean[k] = (sums.0[k] / count) as f32;
            st.var[k] = (sums.1[k] / count - (sums.0[k] / count).powi(2)).max(0.0) as f32;
        }
        st
    };
    let add = |sums: &mut ([f64; 3], [f64; 3]), v: [f32; 3]| {
        for k in 0..3 {
            sums.0[k] += v[k] as f64;
            sums.1[k] += (v[k] as f64).powi(2);
        }
    };
    let res = 13;
    let f = |i: usize, o: f32| o + 5.0 * (i as f32 + 0.5) / res as f32;
    let mut vol = ([0.0; 3], [0.0; 3]);
    for i in 0..res {
        for j in 0..res {
            for l in 0..res {
                add(&mut vol, worley3_point(Vec3::new(f(i, 3.0), f(j, -7.0), f(l, 11.0)), jitter, 0, n));
            }
        }
    }
    let volume = stats(vol, (res * res * res) as f64);
    let planes = std::array::from_fn(|b| {
        let z = -4.0 + (b as f32 + 0.5) / PLANES as f32;
        let mut sums = ([0.0; 3], [0.0; 3]);
        let res2 = 24;
        let g = |i: usize, o: f32| o + 6.0 * (i as f32 + 0.5) / res2 as f32;
        for i in 0..res2 {
            for j in 0..res2 {
                add(&mut sums, worley3_point(Vec3::new(g(i, 3.0), g(j, -7.0), z), jitter, 0, n));
            }
        }
        stats(sums, (res2 * res2) as f64)
    });
    WorleyStats { volume, planes }
}

impl WorleyStats {
    /// Statistics of a footprint wide along every axis but `axis`, where it is `N(m, s²)`:
    /// the planes' statistics averaged over that axis (3-point Gauss–Hermite, interpolated
    /// between table planes); with no such thin axis, the volume's.
    fn wide(&self, thin: Option<(f64, f64)>) -> PatternStats {
        let Some((m, s)) = thin else { return self.volume };
        let mut st = PatternStats::default();
        for &(z, w) in &gaussian::HERMITE3 {
            let t = (m + s * z).rem_euclid(1.0) * PLANES as f64 - 0.5;
            let i0 = t.floor();
            let a = (t - i0) as f32;
            let (b0, b1) =
                ((i0 as i64).rem_euclid(PLANES as i64) as usize, ((i0 as i64) + 1).rem_euclid(PLANES as i64) as usize);
            for k in 0..3 {
                let (p0, p1) = (&self.planes[b0], &self.planes[b1]);
                st.mean[k] += w as f32 * (p0.mean[k] + (p1.mean[k] - p0.mean[k]) * a);
                st.var[k] += w as f32 * (p0.var[k] + (p1.var[k] - p0.var[k]) * a);
            }
        }
        st
    }
}

fn worley3d(stats: &WorleyStats, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (p, s, j) = coordinate(&ins[0]);
    let jitter = ins[1].ch[0].mean;
    let style = ins[2].ch[0].mean.round() as i32;
    let n = ty.channels();
    let mut out = Filtered::zero(ty);
    let smax = s.max_element();
    // The pattern's statistics over the footprint once it is wide: the volume's, or those of
    // the planes it lies in when exactly one axis stays thin (a lattice-aligned surface).
    let thin: Option<usize> = {
        let mut t = (0..3).filter(|&k| s[k] < 0.25);
        match (t.next(), t.next()) {
            (Some(k), None) => Some(k),
            _ => None,
        }
    };
    let (gmean, gvar) = if style == 1 {
        ([0.5; 3], [1.0 / 12.0; 3])
    } else {
        let st = stats.wide(thin.map(|k| (p[k], s[k])));
        (st.mean, st.var)
    };
    if smax == 0.0 {
        let v = worley3_point(p.as_vec3(), jitter, style, n);
        for k in 0..n {
            out.ch[k] = Moments::constant(v[k]);
        }
        ctx.work.lattice += 27;
        return out;
    }
    let w_global = (smax - 1.0).clamp(0.0, 1.0);
    if w_global >= 1.0 {
        for k in 0..n {
            out.ch[k] = Moments { mean: gmean[k], grad: Vec2::ZERO, var: gvar[k] };
        }
        return out;
    }
    // Gauss–Hermite nodes along the axes that spread; a single node (the mean) on the others.
    let spreading = (0..3).filter(|&k| s[k] > 0.0).count();
    let fine: &[(f64, f64)] = if smax < 0.2 || spreading > 2 { &gaussian::HERMITE3 } else { &gaussian::HERMITE5 };
    let single: &[(f64, f64)] = &[(0.0, 1.0)];
    let rule = |k: usize| if s[k] > 0.0 { fine } else { single };
    let (mut e, mut e2) = ([0.0f64; 3], [0.0f64; 3]);
    let mut ez = [DVec3::ZERO; 3];
    let mut nodes = 0u64;
    for &(zz, wz) in rule(2) {
        for &(zy, wy) in rule(1) {
            for &(zx, wx) in rule(0) {
                let z = DVec3::new(zx, zy, zz);
                let v = worley3_point((p + z * s).as_vec3(), jitter, style, n);
                let w = wx * wy * wz;
                for k in 0..n {
                    let vk = v[k] as f64;
                    e[k] += w * vk;
                    e2[k] += w * vk * vk;
                    ez[k] += z * (w * vk);
                }
                nodes += 1;
            }
        }
    }
    ctx.work.lattice += 27 * nodes;
    let wl = 1.0 - w_global;
    for k in 0..n {
        let var = (e2[k] - e[k] * e[k]).max(0.0);
        // Stein: dE/dm = E[z f] / σ per axis.
        let g = DVec3::new(
            if s.x > 0.0 { ez[k].x / s.x } else { 0.0 },
            if s.y > 0.0 { ez[k].y / s.y } else { 0.0 },
            if s.z > 0.0 { ez[k].z / s.z } else { 0.0 },
        );
        let m = M3 {
            mean: wl * e[k] + w_global * gmean[k] as f64,
            grad: g * wl,
            var: wl * var + w_global * gvar[k] as f64,
        };
        out.ch[k] = to_uv(&m, &j);
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Unified noise.

/// The angle (degrees) by which `unifiednoise3d` rotates its Perlin, cell and fractal lattices
/// per unit of `jitter − 1`, and the axis it rotates about.
const UNIFIED_AXIS: [f64; 3] = [0.1, 1.0, 0.0];

fn unified3d(stats: &WorleyStats, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (pos, freq, off, jitter) = (&ins[0], &ins[1], &ins[2], ins[3].ch[0].mean);
    let (outmin, outmax) = (ins[4].ch[0], ins[5].ch[0]);
    let clamp = ins[6].ch[0].mean > 0.5;
    let octaves = super::noise::octave_count(ins[7].ch[0].mean);
    let (lac, dim) = (ins[8].ch[0].mean as f64, ins[9].ch[0].mean as f64);
    let kind = ins[10].ch[0].mean.round() as i32;
    // p = position · freq + offset (exact: affine in the inputs).
    let mut p = Filtered::zero(ValueType::Vector3);
    for k in 0..3 {
        p.ch[k] = add_scaled(mul(pos.ch[k], freq.ch[k], ctx.fp), off.ch[k], 1.0, ctx.fp);
    }
    let spin = super::noise::unified_spin(jitter);
    let mut q = p;
    if spin != 0.0 {
        let m = super::geometry::rotate3d_matrix(UNIFIED_AXIS, spin as f64);
        for (k, row) in m.iter().enumerate() {
            let acc = affine(p.ch[0], row[0] as f32, 0.0);
            let acc = add_scaled(acc, p.ch[1], row[1] as f32, ctx.fp);
            q.ch[k] = add_scaled(acc, p.ch[2], row[2] as f32, ctx.fp);
        }
    }
    let raw = match kind {
        0 => {
            let half = Filtered::constant(Value::float(0.5));
            noise3d(ValueType::Float, &[half, half, q], ctx).ch[0]
        }
        1 => cellnoise3d(ValueType::Float, &[q], ctx).ch[0],
        2 => worley3d(stats, ValueType::Float, &[p, ins[3], ins[11]], ctx).ch[0],
        3 => {
            let (p0, s0, j) = coordinate(&q);
            let sum = fractal_sum(p0, s0, octaves, lac, dim, &[Sel::Full], &[DVec3::ZERO], ctx);
            to_uv(&sum[0], &j)
        }
        _ => Moments::default(),
    };
    let w = if clamp { super::pattern::clamp01(raw) } else { raw };
    let mut out = Filtered::zero(ty);
    out.ch[0] = mix(outmin, outmax, w, ctx.fp);
    out
}

pub(crate) fn eval(op: &Noise3dOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    match op {
        Noise3dOp::Noise3d => noise3d(ty, ins, ctx),
        Noise3dOp::Fractal3d => fractal3d(ty, ins, ctx),
        Noise3dOp::Cellnoise3d => cellnoise3d(ty, ins, ctx),
        Noise3dOp::Worley3d(st) => worley3d(st, ty, ins, ctx),
        Noise3dOp::Unified3d(st) => unified3d(st, ty, ins, ctx),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::Work;

    /// The closed-form gradient lattice reproduces MaterialX's GLSL-style point evaluation, for
    /// the float lattice and every byte lattice.
    #[test]
    fn exact_at_tiny_spread_is_the_point_value() {
        let mut work = Work::default();
        for i in 0..200 {
            let p = DVec3::new(-3.7 + i as f64 * 0.131, 2.2 - i as f64 * 0.077, 0.45 + i as f64 * 0.093);
            for sel in [Sel::Full, Sel::Byte(0), Sel::Byte(1), Sel::Byte(2)] {
                let mut r = [(0.0, DVec3::ZERO); 4];
                perlin3_exact(p, DVec3::splat(1e-4), &[sel], &mut r, &mut work);
                let v = perlin3_point(p.as_vec3(), sel) as f64;
                assert!((r[0].0 - v).abs() < 2e-4, "{p:?} {sel:?}: {} vs {v}", r[0].0);
                // The gradient against central differences of the point function.
                let h = 1e-3;
                for k in 0..3 {
                    let mut e = DVec3::ZERO;
                    e[k] = h;
                    let fd = (perlin3_point((p + e).as_vec3(), sel) - perlin3_point((p - e).as_vec3(), sel)) as f64
                        / (2.0 * h);
                    assert!(
                        (r[0].1[k] - fd).abs() < 2e-2 * (1.0 + fd.abs()),
                        "{p:?} {sel:?} axis {k}: {} vs {fd}",
                        r[0].1[k]
                    );
                }
            }
        }
    }

    /// Prints the global variance of 3D Perlin noise and the decay of the exactly filtered
    /// noise's RMS with an isotropic σ: `PERLIN3_VARIANCE` and the damping's κ come from here.
    #[test]
    fn perlin3_constants() {
        let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..60 {
            for j in 0..60 {
                for l in 0..60 {
                    let p = Vec3::new(0.013 + i as f32 * 0.317, 0.029 + j as f32 * 0.291, 0.041 + l as f32 * 0.273);
                    let v = perlin3(p) as f64;
                    s += v;
                    s2 += v * v;
                    n += 1.0;
                }
            }
        }
        let var = s2 / n - (s / n).powi(2);
        println!("perlin3 variance {var:.4}");
        assert!((var - PERLIN3_VARIANCE).abs() < 0.01, "variance {var}");
        let mut work = Work::default();
        let mut rms = Vec::new();
        for &sig in &[0.25, 0.35, 0.45] {
            let (mut acc, mut cnt) = (0.0, 0.0);
            for i in 0..20 {
                for j in 0..20 {
                    let p = DVec3::new(0.37 + i as f64 * 0.173, 0.11 + j as f64 * 0.191, 0.7 + (i + j) as f64 * 0.137);
                    let mut o = [(0.0, DVec3::ZERO); 4];
                    perlin3_exact(p, DVec3::splat(sig), &[Sel::Full], &mut o, &mut work);
                    acc += o[0].0 * o[0].0;
                    cnt += 1.0;
                }
            }
            rms.push((sig, (acc / cnt).sqrt()));
        }
        for &(sig, r) in &rms {
            let kappa = -(r / rms[0].1).ln() / (3.0 * (sig * sig - 0.0625));
            println!("sigma {sig}: rms {r:.5}, per-axis kappa {kappa:.2}");
        }
    }

    /// Vector cell noise hashes four integers (`hash4`, with its `bjmix` round): its channels
    /// differ from each other and from the float lattice's `hash3`, and lie in [0, 1].
    #[test]
    fn cell_vec3_channels_differ() {
        let a = cell3_vec3(3, -2, 7, 0);
        let b = cell3_vec3(3, -2, 7, 1);
        let c = cell3_float(3, -2, 7);
        assert!(a != b && a != c && (0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b));
    }
}
