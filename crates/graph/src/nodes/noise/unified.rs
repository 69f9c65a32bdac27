//! Unified noise.

use super::cell::{cellnoise2d, cellnoise3d};
use super::fractal::fractal_sum;
use super::lattice::{HashSel, Sel};
use super::worley::{worley2d, worley3d, WorleyStats};
use super::{coordinate, coordinate3, moments2, noise2d, noise3d, octave_count, to_uv, to_uv3, PatternStats};
use crate::moments::{add_scaled, affine, mix, mul};
use crate::nodes::Ctx;
use crate::value::{Filtered, Moments, Value, ValueType};

/// The angle (degrees) by which `unifiednoise2d` rotates its Perlin and cell lattices, and the
/// z of its `fractal3d` slice, per unit of `jitter − 1`.
pub(super) const UNIFIED_JITTER_SCALE: f32 = 90000.0;

/// unifiednoise's rotation (degrees) for a `jitter`: `(jitter − 1) · 90000`, reduced modulo 360°
/// where that overflows f32 (the total rule: an infinite angle has no sine).
pub(crate) fn unified_spin(jitter: f32) -> f32 {
    let spin = (jitter - 1.0) * UNIFIED_JITTER_SCALE;
    if spin.is_finite() {
        spin
    } else {
        ((jitter as f64 - 1.0) * UNIFIED_JITTER_SCALE as f64).rem_euclid(360.0) as f32
    }
}

pub(super) fn unified2d(stats: &PatternStats, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (t, freq, off, jitter) = (&ins[0], &ins[1], &ins[2], ins[3].ch[0].mean);
    let (outmin, outmax) = (ins[4].ch[0], ins[5].ch[0]);
    let clamp = ins[6].ch[0].mean > 0.5;
    let octaves = octave_count(ins[7].ch[0].mean);
    let (lac, dim) = (ins[8].ch[0].mean as f64, ins[9].ch[0].mean as f64);
    let kind = ins[10].ch[0].mean.round() as i32;
    // p = texcoord · freq + offset (exact: affine in the inputs).
    let mut p = Filtered::zero(ValueType::Vector2);
    for k in 0..2 {
        p.ch[k] = add_scaled(mul(t.ch[k], freq.ch[k], ctx.fp), off.ch[k], 1.0, ctx.fp);
    }
    let spin = unified_spin(jitter);
    let raw = match kind {
        0 | 1 => {
            let mut pr = p;
            if spin != 0.0 {
                let (x, y) = crate::nodes::geometry::rotate(p.ch[0], p.ch[1], spin, ctx);
                pr.ch[0] = x;
                pr.ch[1] = y;
            }
            if kind == 0 {
                let half = Filtered::constant(crate::value::Value::float(0.5));
                noise2d(ValueType::Float, &[half, half, pr], ctx).ch[0]
            } else {
                cellnoise2d(ValueType::Float, &[pr], ctx).ch[0]
            }
        }
        2 => worley2d(stats, ValueType::Float, &[p, ins[3], ins[11]], ctx).ch[0],
        3 => {
            let (p0, s0, j) = coordinate(&p);
            let sels = |f: f64| [HashSel::Slice((spin as f64 * f) as f32); 4];
            let sum = fractal_sum(p0.to_array(), s0.to_array(), octaves, lac, dim, sels, &[[0.0; 2]; 4], 1, ctx);
            to_uv(&moments2(&sum[0], crate::moments::sat), &j)
        }
        _ => Moments::default(),
    };
    // range(raw, 0, 1 → outmin, outmax), clamped to [outmin, outmax]: the clamp acts on raw.
    let w = if clamp { crate::nodes::pattern::clamp01(raw) } else { raw };
    let mut out = Filtered::zero(ty);
    out.ch[0] = mix(outmin, outmax, w, ctx.fp);
    out
}

/// The angle (degrees) by which `unifiednoise3d` rotates its Perlin, cell and fractal lattices
/// per unit of `jitter − 1`, and the axis it rotates about.
pub(super) const UNIFIED_AXIS: [f64; 3] = [0.1, 1.0, 0.0];

pub(super) fn unified3d(stats: &WorleyStats, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (pos, freq, off, jitter) = (&ins[0], &ins[1], &ins[2], ins[3].ch[0].mean);
    let (outmin, outmax) = (ins[4].ch[0], ins[5].ch[0]);
    let clamp = ins[6].ch[0].mean > 0.5;
    let octaves = octave_count(ins[7].ch[0].mean);
    let (lac, dim) = (ins[8].ch[0].mean as f64, ins[9].ch[0].mean as f64);
    let kind = ins[10].ch[0].mean.round() as i32;
    // p = position · freq + offset (exact: affine in the inputs).
    let mut p = Filtered::zero(ValueType::Vector3);
    for k in 0..3 {
        p.ch[k] = add_scaled(mul(pos.ch[k], freq.ch[k], ctx.fp), off.ch[k], 1.0, ctx.fp);
    }
    let spin = unified_spin(jitter);
    let mut q = p;
    if spin != 0.0 {
        let m = crate::nodes::geometry::rotate3d_matrix(UNIFIED_AXIS, spin as f64);
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
            let (p0, s0, j) = coordinate3(&q);
            let sum = fractal_sum(
                p0.to_array(),
                s0.to_array(),
                octaves,
                lac,
                dim,
                |_| [Sel::Full; 4],
                &[[0.0; 3]; 4],
                1,
                ctx,
            );
            to_uv3(&sum[0], &j)
        }
        _ => Moments::default(),
    };
    let w = if clamp { crate::nodes::pattern::clamp01(raw) } else { raw };
    let mut out = Filtered::zero(ty);
    out.ch[0] = mix(outmin, outmax, w, ctx.fp);
    out
}
