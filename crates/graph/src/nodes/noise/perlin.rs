//! Filtered Perlin noise: Gaussian averages of the corner sum.

use super::filter::{axis_terms, axis_terms_exact, AxisTerms};
use super::lattice::{
    perlin3_point, perlin_gradient, perlin_point, within_lattice_precision, Dim, HashSel, Lattice, Sel,
    LATTICE_PRECISION_LIMIT,
};
use crate::nodes::Ctx;
use crate::value::Moments;
use glam::{DVec2, DVec3, Vec2};

/// Per-axis spread up to which the corner sum is evaluated exactly (lattice units). Up to here
/// every corner whose kernel support `[c − 1, c + 1]` meets `m ± PERLIN_TAIL·σ` is summed
/// (at most 8 × 8 corners). Measured against brute-force supersampling of the test graphs, a
/// limit of 1.0 gained little over 0.75 in accuracy for ~35% more lattice work.
pub const PERLIN_SIGMA_EXACT: f64 = 0.75;
/// Footprint half-width, in σ, over which corners are summed: the corners left out carry under
/// 5e-5 of filtered noise (1.5e-4 of the unfiltered noise's RMS; see the tests).
pub const PERLIN_TAIL: f64 = 3.5;
/// [`PERLIN_TAIL`] for damped octaves (per-axis spread beyond [`PERLIN_SIGMA_EXACT`]), whose value
/// is the one at σₑ times a fitted damping: the corners left out carry under 1.5e-3 of it (1.5 %
/// of its RMS; see the tests), well below the damping fit's own error, and the sum visits 6 × 6
/// corners instead of 8 × 8.
pub const PERLIN_DAMPED_TAIL: f64 = 2.5;
/// Most lattice coordinates per axis that the exact sum visits: `m ± (1 + PERLIN_TAIL·σ)`
/// spans `2 + 2·PERLIN_TAIL·σ`, which meets at most one more integer than its length.
pub(super) const MAX_AXIS: usize = (2.0 + 2.0 * PERLIN_TAIL * PERLIN_SIGMA_EXACT) as usize + 1;
/// Gaussian damping rate beyond [`PERLIN_SIGMA_EXACT`]: the filtered value at per-axis
/// spreads σ is the exact one at σ clamped to σₑ, times `exp(−κ (σ² − σₑ²))` per axis beyond
/// σₑ. κ is the least-squares fit of that prediction to the exact convolution between σₑ and
/// 3σₑ (see the tests): beyond σₑ the filtered noise decorrelates from its value at σₑ, and the
/// fit balances damping what still correlates against leaving in what no longer does.
pub const PERLIN_KAPPA: f64 = 0.34;
/// [`PERLIN_KAPPA`] for a `z = const` slice of 3D Perlin noise, whose in-plane average decays
/// more slowly (each corner also carries a constant).
pub const PERLIN3_SLICE_KAPPA: f64 = 0.25;
/// `[a, c, b, d]` of the share of the variance that the filtered mean keeps (fitted to the
/// exact convolution, see the tests; [`share_model`]).
pub(super) const PERLIN_SHARE: [f64; 4] = [14.8, 0.61, 42.0, 0.24];
/// [`PERLIN_SHARE`] for a `z = const` slice of 3D Perlin noise.
pub(super) const PERLIN3_SLICE_SHARE: [f64; 4] = [11.1, 0.545, 464.0, 0.015];
/// Damping below which an octave counts as fully filtered (value = its mean 0).
pub const OCTAVE_CUTOFF: f64 = 1e-3;
/// Per-axis spread (lattice units) below which an octave is evaluated at the footprint centre:
/// the Gaussian average differs from the centre value by `½ tr(H Σ)`, under 1e-4 here.
pub const PERLIN_SIGMA_POINT: f64 = 0.003;
/// Variance of MaterialX's 2D Perlin noise over the plane (measured).
pub const PERLIN_VARIANCE: f64 = 0.1055;

/// `((1 + a σₓ²)(1 + a σ_y²))^−c (1 + b σₓ² σ_y²)^−d` for `[a, c, b, d]`: averaging along one
/// axis alone leaves variance decaying like a power of σ, averaging along both decays faster.
#[inline]
pub(super) fn share_model([a, c, b, d]: [f64; 4], s: DVec2) -> f64 {
    let (x, y) = (s.x * s.x, s.y * s.y);
    ((1.0 + a * x) * (1.0 + a * y)).powf(-c) * (1.0 + b * x * y).powf(-d)
}

/// Filtered Perlin noise for up to 4 hash selections at once: per channel (value, ∂/∂x, ∂/∂y).
/// `s` are the per-axis spreads, each in [1e-4, [`PERLIN_SIGMA_EXACT`]].
#[cfg(test)]
pub(super) fn perlin_exact(
    p: DVec2,
    s: DVec2,
    sels: &[HashSel],
    out: &mut [(f64, f64, f64); 4],
    work: &mut crate::eval::Work,
) {
    perlin_exact_n::<MAX_AXIS, true>(p, s, PERLIN_TAIL, sels, out, work)
}

/// [`perlin_exact`] with room for `N` lattice coordinates per axis, i.e. for per-axis spreads up
/// to `(N − 3) / (2·PERLIN_TAIL)` (larger ones in the tests). The Gaussian average of corner
/// `c`'s kernel is `g·E[(p − c) W W] + k E[W W]`, a product of one 1D expectation per axis,
/// so each axis's expectations are computed once per lattice coordinate and the corner sum
/// combines them with the hashed gradients. `TABLE` reads the 1D expectations from the table,
/// otherwise they are integrated exactly.
pub(super) fn perlin_exact_n<const N: usize, const TABLE: bool>(
    p: DVec2,
    s: DVec2,
    tail: f64,
    sels: &[HashSel],
    out: &mut [(f64, f64, f64); 4],
    work: &mut crate::eval::Work,
) {
    let mut r = [[0.0; 4]; 4];
    corner_sum::<2, N, TABLE>(p.to_array(), s.to_array(), tail, sels, &mut r, work);
    for (o, r) in out.iter_mut().zip(r) {
        *o = (r[0], r[1], r[2]);
    }
}

/// The Gaussian average of the Perlin corner sum over `N(p, diag(s²))` and its derivatives with
/// respect to `p`, for up to 4 lattices at once: per channel `[value, ∂/∂p₀, …, ∂/∂p_{D−1}]`.
/// Every lattice coordinate whose kernel support `(c − 1, c + 1)` meets `p ± tail·s` is visited
/// along each axis (at most `N`). Corner `c`'s kernel is `Σᵢ gᵢ Πₐ Kᵢₐ` with `Kᵢₐ = dW` on the
/// coefficient's own axis and `W` on the others ([`Lattice::corner`]; a 2D slice's third
/// coefficient is a constant, `W` on both axes), so its average is a product of one 1D
/// expectation per axis ([`AxisTerms`]): each axis's are computed once per lattice coordinate,
/// the products over the outer axes (all but x) once per outer cell, and the x loop combines
/// them with the hashed gradients. `TABLE` reads the 1D expectations from the table, otherwise
/// they are integrated exactly.
#[inline(always)]
pub(super) fn corner_sum<const D: usize, const N: usize, const TABLE: bool>(
    p: [f64; D],
    s: [f64; D],
    tail: f64,
    sels: &[<Dim<D> as Lattice<D>>::Sel],
    out: &mut [[f64; 4]; 4],
    work: &mut crate::eval::Work,
) where
    Dim<D>: Lattice<D>,
{
    let mut axes = [[(0i32, AxisTerms::default()); N]; D];
    let mut n = [0usize; D];
    for a in 0..D {
        let (m, s) = (p[a], s[a]);
        // Every c whose support (c − 1, c + 1) meets [m − tail, m + tail].
        let lo = (m - 1.0 - tail * s).floor() as i32 + 1;
        let hi = (m + 1.0 + tail * s).ceil() as i32 - 1;
        debug_assert!(hi - lo < N as i32, "{} lattice coordinates at σ = {s}", hi - lo + 1);
        n[a] =
            if TABLE { axis_terms(m, s, lo, hi, &mut axes[a]) } else { axis_terms_exact(m, s, lo, hi, &mut axes[a]) };
    }
    *out = [[0.0; 4]; 4];
    // The outer cells in order, axis 1 fastest (an odometer over axes 1..D).
    let outer: usize = n[1..].iter().product();
    let mut at = [0usize; D];
    let mut c = [0i32; D];
    for _ in 0..outer {
        // f[r][i]: coefficient i's product over the outer axes, differentiated along axis r ≥ 1
        // (r = 0: the value).
        let mut f = [[1.0f64; 3]; D];
        for a in 1..D {
            let (ca, t) = axes[a][at[a]];
            c[a] = ca;
            for (r, fr) in f.iter_mut().enumerate() {
                for (i, fri) in fr.iter_mut().enumerate() {
                    *fri *= match (r == a, i == a) {
                        (false, false) => t.w,
                        (false, true) => t.dw,
                        (true, false) => t.w1,
                        (true, true) => t.dw1,
                    };
                }
            }
        }
        for &(cx, tx) in &axes[0][..n[0]] {
            c[0] = cx;
            let h = Dim::<D>::hash(c);
            let (x, x1) = ([tx.dw, tx.w, tx.w], [tx.dw1, tx.w1, tx.w1]);
            for (k, sel) in sels.iter().enumerate() {
                let g = Dim::<D>::corner(*sel, c, h);
                let o = &mut out[k];
                let f0 = &f[0];
                o[0] += g[0] * x[0] * f0[0] + g[1] * x[1] * f0[1] + g[2] * x[2] * f0[2];
                o[1] += g[0] * x1[0] * f0[0] + g[1] * x1[1] * f0[1] + g[2] * x1[2] * f0[2];
                for a in 1..D {
                    let fa = &f[a];
                    o[1 + a] += g[0] * x[0] * fa[0] + g[1] * x[1] * fa[1] + g[2] * x[2] * fa[2];
                }
            }
        }
        for a in 1..D {
            at[a] += 1;
            if at[a] < n[a] {
                break;
            }
            at[a] = 0;
        }
    }
    work.lattice += n.iter().product::<usize>() as u64;
    for (o, sel) in out.iter_mut().zip(sels) {
        let k = Dim::<D>::scale(*sel);
        for v in o.iter_mut().take(D + 1) {
            *v *= k;
        }
    }
}

/// One filtered Perlin octave for several channels. Returns `false` (and zeros) when the
/// footprint filters the octave out completely.
pub(super) fn perlin_octave(
    p: DVec2,
    s: DVec2,
    sels: &[HashSel],
    offsets: &[DVec2],
    out: &mut [Moments; 4],
    ctx: &mut Ctx,
) -> bool {
    ctx.work.octaves += 1;
    if offsets.iter().any(|o| !within_lattice_precision(p + *o)) {
        // Where f32 coordinates are all whole numbers, every point is a lattice point and the
        // noise is 0 (the point evaluation's own result, and the total rule for any footprint).
        for o in out.iter_mut() {
            *o = Moments::default();
        }
        return true;
    }
    if s.x.max(s.y) < PERLIN_SIGMA_POINT {
        for (k, sel) in sels.iter().enumerate() {
            let q = p + offsets[k];
            let mut m = Moments::constant(perlin_point(q.as_vec2(), *sel));
            if !ctx.point {
                let g = perlin_gradient(q, *sel);
                m.grad = g.as_vec2();
                m.var = (g.x * g.x * s.x * s.x + g.y * g.y * s.y * s.y) as f32;
            }
            out[k] = m;
        }
        ctx.work.lattice += 4;
        return true;
    }
    let kappa = sels[0].kappa();
    let damp = |s: f64| {
        if s > PERLIN_SIGMA_EXACT {
            (-kappa * (s * s - PERLIN_SIGMA_EXACT * PERLIN_SIGMA_EXACT)).exp()
        } else {
            1.0
        }
    };
    let att = damp(s.x) * damp(s.y);
    if att < OCTAVE_CUTOFF {
        for o in out.iter_mut() {
            *o = Moments { mean: 0.0, grad: Vec2::ZERO, var: sels[0].variance() as f32 };
        }
        return false;
    }
    // One axis may have no spread at all (a coordinate channel that is constant): give it a
    // negligible one, since the exact corner integrals divide by σ.
    let se = s.min(DVec2::splat(PERLIN_SIGMA_EXACT)).max(DVec2::splat(1e-4));
    let mut r = [(0.0, 0.0, 0.0); 4];
    // Channels with equal offsets share one corner sum.
    let same_offset = offsets.iter().all(|o| *o == offsets[0]);
    // A damped octave (beyond σₑ on some axis) is the value at σₑ times a fitted damping: its
    // corners are summed over the shorter tail, whose error is far below the fit's.
    let tail = if att < 1.0 { PERLIN_DAMPED_TAIL } else { PERLIN_TAIL };
    let exact = |q: DVec2, sels: &[HashSel], out: &mut [(f64, f64, f64); 4], work: &mut crate::eval::Work| {
        perlin_exact_n::<MAX_AXIS, true>(q, se, tail, sels, out, work)
    };
    if same_offset {
        exact(p + offsets[0], sels, &mut r, ctx.work);
    } else {
        for (k, sel) in sels.iter().enumerate() {
            let mut one = [(0.0, 0.0, 0.0); 4];
            exact(p + offsets[k], std::slice::from_ref(sel), &mut one, ctx.work);
            r[k] = one[0];
        }
    }
    // Variance within the footprint: locally, the linearisation through the filtered gradient;
    // on average over the plane (law of total variance), what the filtered mean does not keep
    // of the lattice's variance. Blended by that share: the linearisation while the mean keeps
    // most of the variance (small footprints), the plane average as it keeps little.
    let share = sels[0].mean_share(s);
    let v_glob = sels[0].variance() * (1.0 - share);
    for k in 0..sels.len() {
        let (v, dx, dy) = (r[k].0 * att, r[k].1 * att, r[k].2 * att);
        let v_lin = dx * dx * s.x * s.x + dy * dy * s.y * s.y;
        let var = share * v_lin + (1.0 - share) * v_glob;
        out[k] = Moments { mean: v as f32, grad: Vec2::new(dx as f32, dy as f32), var: var as f32 };
    }
    true
}

/// Variance of MaterialX's 3D float Perlin noise over space (measured; see the tests).
pub const PERLIN3_VARIANCE: f64 = 0.0695;

/// Per-axis spread up to which 3D Perlin noise is filtered exactly (lattice units): up to here
/// the corner sum visits at most 5 coordinates per axis.
pub const PERLIN3_SIGMA_EXACT: f64 = 0.25;

/// Gaussian damping rate of 3D Perlin noise beyond [`PERLIN3_SIGMA_EXACT`] per axis (fitted to
/// the decay of the exactly filtered noise's RMS between σ = 0.25 and 0.45 — 1.8 to 1.6; see
/// the tests).
pub const PERLIN3_KAPPA: f64 = 1.7;

/// Filtered 3D Perlin noise for up to 4 lattices at once: per channel (value, gradient).
/// `s` are the per-axis spreads, each in [1e-4, [`PERLIN3_SIGMA_EXACT`]].
pub(super) fn perlin3_exact(
    p: DVec3,
    s: DVec3,
    sels: &[Sel],
    out: &mut [(f64, DVec3); 4],
    work: &mut crate::eval::Work,
) {
    let mut r = [[0.0; 4]; 4];
    corner_sum::<3, MAX_AXIS, true>(p.to_array(), s.to_array(), 4.0, sels, &mut r, work);
    for (o, r) in out.iter_mut().zip(r) {
        *o = (r[0], DVec3::new(r[1], r[2], r[3]));
    }
}

/// Filtered moments of one channel in noise space: mean, gradient with respect to the 3D
/// coordinate, variance.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct M3 {
    pub(super) mean: f64,
    pub(super) grad: DVec3,
    pub(super) var: f64,
}

/// One filtered 3D Perlin octave for several channels. Returns `false` (means 0, the global
/// variance) when the footprint filters the octave out completely.
pub(super) fn perlin3_octave(
    p: DVec3,
    s: DVec3,
    sels: &[Sel],
    offsets: &[DVec3],
    out: &mut [M3; 4],
    ctx: &mut Ctx,
) -> bool {
    ctx.work.octaves += 1;
    let lim = LATTICE_PRECISION_LIMIT;
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
