//! Unified noise.

use super::cell::{cellnoise2d, cellnoise3d};
use super::fractal::fractal_sum;
use super::lattice::{Dim, HashSel, Sel};
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

/// The axis about which `unifiednoise3d` rotates its Perlin, cell and fractal lattices (by
/// [`unified_spin`] degrees).
pub(super) const UNIFIED_AXIS: [f64; 3] = [0.1, 1.0, 0.0];

/// What `unifiednoise2d` and `unifiednoise3d` do differently: the coordinate's rotation, the
/// nodes behind each type, and the fractal (2D: a slice `z = spin` of 3D fractal noise at the
/// unrotated coordinate, its z scaled with each octave's frequency; 3D: fractal noise at the
/// rotated coordinate).
pub(super) trait UnifiedNoise<const D: usize> {
    /// The Worley statistics the node holds for its jitter.
    type Stats;
    /// The coordinate's value type.
    const COORDINATE: ValueType;
    /// Whether type 3's fractal reads the rotated coordinate (3D) or the unrotated one, with
    /// the spin as its slice's z (2D).
    const FRACTAL_ROTATED: bool;
    /// `p` rotated by `spin` degrees (never called for 0).
    fn rotate(p: &Filtered, spin: f32, ctx: &Ctx) -> Filtered;
    /// The Perlin noise node (`amplitude`, `pivot`, coordinate).
    fn perlin(ins: &[Filtered], ctx: &mut Ctx) -> Filtered;
    /// The cell noise node (coordinate).
    fn cell(ins: &[Filtered], ctx: &mut Ctx) -> Filtered;
    /// The Worley noise node (coordinate, `jitter`, `style`).
    fn worley(stats: &Self::Stats, ins: &[Filtered], ctx: &mut Ctx) -> Filtered;
    /// Type 3's fractal of `octaves` at coordinate `p` (rotated or not, [`Self::FRACTAL_ROTATED`]),
    /// in uv.
    fn fractal(p: &Filtered, spin: f32, octaves: i32, lac: f64, dim: f64, ctx: &mut Ctx) -> Moments;
}

impl UnifiedNoise<2> for Dim<2> {
    type Stats = PatternStats;
    const COORDINATE: ValueType = ValueType::Vector2;
    const FRACTAL_ROTATED: bool = false;
    #[inline(always)]
    fn rotate(p: &Filtered, spin: f32, ctx: &Ctx) -> Filtered {
        let mut pr = *p;
        (pr.ch[0], pr.ch[1]) = crate::nodes::geometry::rotate(p.ch[0], p.ch[1], spin, ctx);
        pr
    }
    #[inline(always)]
    fn perlin(ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
        noise2d(ValueType::Float, ins, ctx)
    }
    #[inline(always)]
    fn cell(ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
        cellnoise2d(ValueType::Float, ins, ctx)
    }
    #[inline(always)]
    fn worley(stats: &PatternStats, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
        worley2d(stats, ValueType::Float, ins, ctx)
    }
    #[inline(always)]
    fn fractal(p: &Filtered, spin: f32, octaves: i32, lac: f64, dim: f64, ctx: &mut Ctx) -> Moments {
        let (p0, s0, j) = coordinate(p);
        let sels = |f: f64| [HashSel::Slice((spin as f64 * f) as f32); 4];
        let sum = fractal_sum(p0.to_array(), s0.to_array(), octaves, lac, dim, sels, &[[0.0; 2]; 4], 1, ctx);
        to_uv(&moments2(&sum[0], crate::moments::sat), &j)
    }
}

impl UnifiedNoise<3> for Dim<3> {
    type Stats = WorleyStats;
    const COORDINATE: ValueType = ValueType::Vector3;
    const FRACTAL_ROTATED: bool = true;
    #[inline(always)]
    fn rotate(p: &Filtered, spin: f32, ctx: &Ctx) -> Filtered {
        let mut q = *p;
        let m = crate::nodes::geometry::rotate3d_matrix(UNIFIED_AXIS, spin as f64);
        for (k, row) in m.iter().enumerate() {
            let acc = affine(p.ch[0], row[0] as f32, 0.0);
            let acc = add_scaled(acc, p.ch[1], row[1] as f32, ctx.fp);
            q.ch[k] = add_scaled(acc, p.ch[2], row[2] as f32, ctx.fp);
        }
        q
    }
    #[inline(always)]
    fn perlin(ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
        noise3d(ValueType::Float, ins, ctx)
    }
    #[inline(always)]
    fn cell(ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
        cellnoise3d(ValueType::Float, ins, ctx)
    }
    #[inline(always)]
    fn worley(stats: &WorleyStats, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
        worley3d(stats, ValueType::Float, ins, ctx)
    }
    #[inline(always)]
    fn fractal(q: &Filtered, _: f32, octaves: i32, lac: f64, dim: f64, ctx: &mut Ctx) -> Moments {
        let (p0, s0, j) = coordinate3(q);
        let sels = |_| [Sel::Full; 4];
        let sum = fractal_sum(p0.to_array(), s0.to_array(), octaves, lac, dim, sels, &[[0.0; 3]; 4], 1, ctx);
        to_uv3(&sum[0], &j)
    }
}

/// `unifiednoise2d` / `unifiednoise3d` (float): `p = coordinate · freq + offset` (exact: affine
/// in the inputs), rotated by [`unified_spin`] for the Perlin, cell and (3D) fractal types; the
/// type's noise remapped from [0, 1] to [outmin, outmax], clamped to that range if asked.
pub(super) fn unified<const D: usize>(
    stats: &<Dim<D> as UnifiedNoise<D>>::Stats,
    ty: ValueType,
    ins: &[Filtered],
    ctx: &mut Ctx,
) -> Filtered
where
    Dim<D>: UnifiedNoise<D>,
{
    let (t, freq, off, jitter) = (&ins[0], &ins[1], &ins[2], ins[3].ch[0].mean);
    let (outmin, outmax) = (ins[4].ch[0], ins[5].ch[0]);
    let clamp = ins[6].ch[0].mean > 0.5;
    let octaves = octave_count(ins[7].ch[0].mean);
    let (lac, dim) = (ins[8].ch[0].mean as f64, ins[9].ch[0].mean as f64);
    let kind = ins[10].ch[0].mean.round() as i32;
    let mut p = Filtered::zero(Dim::<D>::COORDINATE);
    for k in 0..D {
        p.ch[k] = add_scaled(mul(t.ch[k], freq.ch[k], ctx.fp), off.ch[k], 1.0, ctx.fp);
    }
    let spin = unified_spin(jitter);
    let rotated = |ctx: &Ctx| if spin != 0.0 { Dim::<D>::rotate(&p, spin, ctx) } else { p };
    let raw = match kind {
        0 => {
            let (half, q) = (Filtered::constant(Value::float(0.5)), rotated(ctx));
            Dim::<D>::perlin(&[half, half, q], ctx).ch[0]
        }
        1 => {
            let q = rotated(ctx);
            Dim::<D>::cell(&[q], ctx).ch[0]
        }
        2 => Dim::<D>::worley(stats, &[p, ins[3], ins[11]], ctx).ch[0],
        3 => {
            let q = if Dim::<D>::FRACTAL_ROTATED { rotated(ctx) } else { p };
            Dim::<D>::fractal(&q, spin, octaves, lac, dim, ctx)
        }
        _ => Moments::default(),
    };
    // range(raw, 0, 1 → outmin, outmax), clamped to [outmin, outmax]: the clamp acts on raw.
    let w = if clamp { crate::nodes::pattern::clamp01(raw) } else { raw };
    let mut out = Filtered::zero(ty);
    out.ch[0] = mix(outmin, outmax, w, ctx.fp);
    out
}
