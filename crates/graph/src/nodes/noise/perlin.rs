//! Filtered Perlin noise: Gaussian averages of the corner sum.

use super::filter::{axis_terms, axis_terms_exact, AxisTerms};
use super::lattice::{
    perlin3_point, perlin_gradient, perlin_point, within_lattice_precision, Dim, HashSel, Lattice, Sel,
    LATTICE_PRECISION_LIMIT,
};
use crate::nodes::Ctx;
use glam::{DVec2, DVec3};

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
/// Shorter tails for more strongly damped octaves: `(a, t)` sums over ±`t`·σₑ once the damping is
/// below `a`. The corners a tail leaves out move the value at σₑ by at most 3.9e-3 (tail 2),
/// 1.2e-2 (1.5), 3.8e-2 (1) and 9.8e-2 (0.5) (measured on 4000 footprints, see the tests); times
/// a damping below `a`, each moves the octave by under 1.1e-3, what [`PERLIN_DAMPED_TAIL`] moves
/// an undamped one. The sums visit about 22, 16, 11 and 7 corners instead of 29 (damped octaves
/// are the most common filtered ones at pixel footprints, a third to a half of them).
pub const PERLIN_DAMPED_TAILS: [(f64, f64); 4] = [(0.28, 2.0), (0.09, 1.5), (0.028, 1.0), (0.011, 0.5)];
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
/// As one exponential of two logarithms: every filtered octave computes it, and the two
/// powers it was written with cost as much as the rest of a small footprint's octave.
#[inline]
pub(super) fn share_model([a, c, b, d]: [f64; 4], s: DVec2) -> f64 {
    let (x, y) = (s.x * s.x, s.y * s.y);
    (-c * ((1.0 + a * x) * (1.0 + a * y)).ln() - d * (b * x * y).ln_1p()).exp()
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
#[cfg(test)]
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
    let mut corners = [Dim::<D>::corners(sels[0]); 4];
    for (c, sel) in corners.iter_mut().zip(sels) {
        *c = Dim::<D>::corners(*sel);
    }
    // Float noise (one lattice) gets its own copy of the loops, without the loop over channels.
    if sels.len() == 1 {
        corner_products::<D, N>(&axes, &n, &corners[..1], out);
    } else {
        corner_products::<D, N>(&axes, &n, &corners[..sels.len()], out);
    }
    work.lattice += n.iter().product::<usize>() as u64;
    for (o, sel) in out.iter_mut().zip(sels) {
        let k = Dim::<D>::scale(*sel);
        for v in o.iter_mut().take(D + 1) {
            *v *= k;
        }
    }
}

/// [`corner_sum`]'s loops over the corners: the outer cells by odometer, the products over their
/// axes once per cell, and the x loop adding each corner's hashed gradients times the axes'
/// expectations into `out` (per lattice in `sels`).
#[inline(always)]
fn corner_products<const D: usize, const N: usize>(
    axes: &[[(i32, AxisTerms); N]; D],
    n: &[usize; D],
    sels: &[<Dim<D> as Lattice<D>>::Corners],
    out: &mut [[f64; 4]; 4],
) where
    Dim<D>: Lattice<D>,
{
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

/// Footprint half-width, in σ, over which the 3D corner sum visits corners.
pub const PERLIN3_TAIL: f64 = 4.0;

/// Filtered 3D Perlin noise for up to 4 lattices at once: per channel (value, gradient).
/// `s` are the per-axis spreads, each in [1e-4, [`PERLIN3_SIGMA_EXACT`]].
#[cfg(test)]
pub(super) fn perlin3_exact(
    p: DVec3,
    s: DVec3,
    sels: &[Sel],
    out: &mut [(f64, DVec3); 4],
    work: &mut crate::eval::Work,
) {
    let mut r = [[0.0; 4]; 4];
    corner_sum::<3, MAX_AXIS, true>(p.to_array(), s.to_array(), PERLIN3_TAIL, sels, &mut r, work);
    for (o, r) in out.iter_mut().zip(r) {
        *o = (r[0], DVec3::new(r[1], r[2], r[3]));
    }
}

/// Filtered moments of one channel in noise space: mean, gradient with respect to the
/// `D`-dimensional coordinate, variance.
#[derive(Clone, Copy, Debug)]
pub(super) struct NoiseMoments<const D: usize> {
    pub(super) mean: f64,
    pub(super) grad: [f64; D],
    pub(super) var: f64,
}

impl<const D: usize> Default for NoiseMoments<D> {
    fn default() -> Self {
        NoiseMoments { mean: 0.0, grad: [0.0; D], var: 0.0 }
    }
}

/// What a filtered Perlin octave ([`perlin_octave`]) does differently in 2D and 3D: its
/// constants, its point path's gradient, its model of the variance within the footprint and
/// the rounding of its moments. Each hook keeps its dimension's behaviour exactly, NaN rules
/// included (2D compares with `f64::max`, 3D with glam's `max_element`, which differ on NaN).
pub(super) trait PerlinOctave<const D: usize>: Lattice<D> {
    /// Per-axis spread up to which the corner sum is evaluated exactly (lattice units).
    const SIGMA_EXACT: f64;
    /// What the variance model prepares once per octave (it depends on the spreads only).
    type VarianceModel: Copy;
    /// Whether f32 resolves the lattice cell of noise-space coordinate `q` (where it does not,
    /// every f32 coordinate is a lattice point and the noise is 0).
    fn resolves(q: [f64; D]) -> bool;
    /// The largest per-axis spread.
    fn max_spread(s: [f64; D]) -> f64;
    /// Unfiltered noise at `q` on lattice `sel`.
    fn point_value(q: [f64; D], sel: Self::Sel) -> f32;
    /// The gradient of unfiltered noise at `q` on lattice `sel`.
    fn point_gradient(q: [f64; D], sel: Self::Sel, work: &mut crate::eval::Work) -> [f64; D];
    /// Gaussian damping rate per axis beyond [`Self::SIGMA_EXACT`].
    fn kappa(sel: Self::Sel) -> f64;
    /// Variance of the lattice's noise over space (the variance of a fully filtered octave).
    fn variance(sel: Self::Sel) -> f64;
    /// Footprint half-width, in σ, over which corners are summed for an octave whose value is
    /// the one at σₑ times the damping `att` (1: not damped).
    fn tail(att: f64) -> f64;
    /// The spreads at which corners are summed: `s` clamped to `[1e-4, σₑ]` (an axis without
    /// spread gets a negligible one, since the exact corner integrals divide by σ).
    fn exact_spreads(s: [f64; D]) -> [f64; D];
    /// The linearisation's variance within the footprint for gradient `g`.
    fn linear_variance(g: [f64; D], s: [f64; D]) -> f64;
    /// The variance model at spreads `s` for lattice `sel`.
    fn variance_model(sel: Self::Sel, s: [f64; D]) -> Self::VarianceModel;
    /// Variance within the footprint from the linearisation's `v_lin` and the model.
    fn footprint_variance(model: Self::VarianceModel, v_lin: f64) -> f64;
    /// An octave's moments as a fractal sums them (2D: each through f32, as the 2D octave
    /// always handed them on; 3D: as they are).
    fn round(m: NoiseMoments<D>) -> NoiseMoments<D>;
}

impl PerlinOctave<2> for Dim<2> {
    const SIGMA_EXACT: f64 = PERLIN_SIGMA_EXACT;
    /// The share of the lattice's variance that the filtered mean keeps, and the plane
    /// average of the variance within the footprint.
    type VarianceModel = (f64, f64);
    #[inline(always)]
    fn resolves(q: [f64; 2]) -> bool {
        within_lattice_precision(DVec2::from_array(q))
    }
    #[inline(always)]
    fn max_spread(s: [f64; 2]) -> f64 {
        s[0].max(s[1])
    }
    #[inline(always)]
    fn point_value(q: [f64; 2], sel: HashSel) -> f32 {
        perlin_point(DVec2::from_array(q).as_vec2(), sel)
    }
    #[inline(always)]
    fn point_gradient(q: [f64; 2], sel: HashSel, _: &mut crate::eval::Work) -> [f64; 2] {
        perlin_gradient(DVec2::from_array(q), sel).to_array()
    }
    #[inline(always)]
    fn kappa(sel: HashSel) -> f64 {
        sel.kappa()
    }
    #[inline(always)]
    fn variance(sel: HashSel) -> f64 {
        sel.variance()
    }
    /// A damped octave's corners are summed over a shorter tail, the shorter the stronger the
    /// damping, whose error is far below the damping fit's ([`PERLIN_DAMPED_TAILS`]).
    #[inline(always)]
    fn tail(att: f64) -> f64 {
        if att >= 1.0 {
            return PERLIN_TAIL;
        }
        let mut tail = PERLIN_DAMPED_TAIL;
        for (below, t) in PERLIN_DAMPED_TAILS {
            if att < below {
                tail = t;
            }
        }
        tail
    }
    #[inline(always)]
    fn exact_spreads(s: [f64; 2]) -> [f64; 2] {
        DVec2::from_array(s).min(DVec2::splat(PERLIN_SIGMA_EXACT)).max(DVec2::splat(1e-4)).to_array()
    }
    #[inline(always)]
    fn linear_variance(g: [f64; 2], s: [f64; 2]) -> f64 {
        g[0] * g[0] * s[0] * s[0] + g[1] * g[1] * s[1] * s[1]
    }
    #[inline(always)]
    fn variance_model(sel: HashSel, s: [f64; 2]) -> (f64, f64) {
        let share = sel.mean_share(DVec2::from_array(s));
        (share, sel.variance() * (1.0 - share))
    }
    /// Locally, the linearisation through the filtered gradient; on average over the plane
    /// (law of total variance), what the filtered mean does not keep of the lattice's variance.
    /// Blended by that share: the linearisation while the mean keeps most of the variance
    /// (small footprints), the plane average as it keeps little.
    #[inline(always)]
    fn footprint_variance((share, v_glob): (f64, f64), v_lin: f64) -> f64 {
        share * v_lin + (1.0 - share) * v_glob
    }
    #[inline(always)]
    fn round(m: NoiseMoments<2>) -> NoiseMoments<2> {
        let r = |x: f64| x as f32 as f64;
        NoiseMoments { mean: r(m.mean), grad: [r(m.grad[0]), r(m.grad[1])], var: r(m.var) }
    }
}

impl PerlinOctave<3> for Dim<3> {
    const SIGMA_EXACT: f64 = PERLIN3_SIGMA_EXACT;
    /// The variance within the footprint that the damped-out detail leaves.
    type VarianceModel = f64;
    #[inline(always)]
    fn resolves(q: [f64; 3]) -> bool {
        DVec3::from_array(q).abs().max_element() < LATTICE_PRECISION_LIMIT
    }
    #[inline(always)]
    fn max_spread(s: [f64; 3]) -> f64 {
        DVec3::from_array(s).max_element()
    }
    #[inline(always)]
    fn point_value(q: [f64; 3], sel: Sel) -> f32 {
        perlin3_point(DVec3::from_array(q).as_vec3(), sel)
    }
    /// From the corner sum at a negligible spread.
    #[inline(always)]
    fn point_gradient(q: [f64; 3], sel: Sel, work: &mut crate::eval::Work) -> [f64; 3] {
        let mut r = [[0.0; 4]; 4];
        exact_sum::<3>(q, [1e-4; 3], 1.0, std::slice::from_ref(&sel), &mut r, work);
        [r[0][1], r[0][2], r[0][3]]
    }
    #[inline(always)]
    fn kappa(_: Sel) -> f64 {
        PERLIN3_KAPPA
    }
    #[inline(always)]
    fn variance(_: Sel) -> f64 {
        PERLIN3_VARIANCE
    }
    #[inline(always)]
    fn tail(_: f64) -> f64 {
        PERLIN3_TAIL
    }
    #[inline(always)]
    fn exact_spreads(s: [f64; 3]) -> [f64; 3] {
        DVec3::from_array(s).clamp(DVec3::splat(1e-4), DVec3::splat(PERLIN3_SIGMA_EXACT)).to_array()
    }
    #[inline(always)]
    fn linear_variance(g: [f64; 3], s: [f64; 3]) -> f64 {
        (DVec3::from_array(g) * DVec3::from_array(s)).length_squared()
    }
    #[inline(always)]
    fn variance_model(_: Sel, s: [f64; 3]) -> f64 {
        PERLIN3_VARIANCE * (1.0 - (-PERLIN3_KAPPA * DVec3::from_array(s).length_squared()).exp())
    }
    /// The larger of the linearisation and the damped-out detail's variance.
    #[inline(always)]
    fn footprint_variance(v_glob: f64, v_lin: f64) -> f64 {
        v_lin.max(v_glob)
    }
    #[inline(always)]
    fn round(m: NoiseMoments<3>) -> NoiseMoments<3> {
        m
    }
}

/// [`corner_sum`] from the table with room for [`MAX_AXIS`] coordinates per axis, over the
/// dimension's tail for an octave damped by `att` (1: not damped): the filtered octaves' exact sum. One
/// out-of-line copy per dimension, called from the octave's paths (inlined into them, the
/// octave's code grows threefold and the 3D octaves slow by 5–10 %), with the tail chosen inside
/// so that 3D's constant one folds into the loop bounds as it did before.
#[inline(never)]
fn exact_sum<const D: usize>(
    p: [f64; D],
    s: [f64; D],
    att: f64,
    sels: &[<Dim<D> as Lattice<D>>::Sel],
    out: &mut [[f64; 4]; 4],
    work: &mut crate::eval::Work,
) where
    Dim<D>: PerlinOctave<D>,
{
    let mut r = [[0.0; 4]; 4];
    corner_sum::<D, MAX_AXIS, true>(p, s, Dim::<D>::tail(att), sels, &mut r, work);
    *out = r;
}

/// One filtered Perlin octave for several channels (`sels` and `offsets` per channel) at
/// noise-space coordinate `p` with per-axis spreads `s`. Returns `false` (means 0, the global
/// variance) when the footprint filters the octave out completely.
///
/// Beyond a point-sized footprint, the octave is the exact Gaussian average of the corner sum
/// at spreads clamped to σₑ, times a fitted Gaussian damping `exp(−κ (σ² − σₑ²))` per axis
/// beyond σₑ; the variance within the footprint follows the dimension's model
/// ([`PerlinOctave`]).
///
/// Inlined into its callers (noise nodes and fractal sums): out of line, the 2D float noise node
/// measured 3–4 % slower than its own copy of the octave had been.
#[inline]
pub(super) fn perlin_octave<const D: usize>(
    p: [f64; D],
    s: [f64; D],
    sels: &[<Dim<D> as Lattice<D>>::Sel],
    offsets: &[[f64; D]],
    out: &mut [NoiseMoments<D>; 4],
    ctx: &mut Ctx,
) -> bool
where
    Dim<D>: PerlinOctave<D>,
{
    let at = |o: &[f64; D]| {
        let mut q = p;
        for (q, o) in q.iter_mut().zip(o) {
            *q += o;
        }
        q
    };
    ctx.work.octaves += 1;
    if offsets.iter().any(|o| !Dim::<D>::resolves(at(o))) {
        // Where f32 coordinates are all whole numbers, every point is a lattice point and the
        // noise is 0 (the point evaluation's own result, and the total rule for any footprint).
        for o in out.iter_mut() {
            *o = NoiseMoments::default();
        }
        return true;
    }
    if Dim::<D>::max_spread(s) < PERLIN_SIGMA_POINT {
        for (k, sel) in sels.iter().enumerate() {
            let q = at(&offsets[k]);
            let mut m = NoiseMoments { mean: Dim::<D>::point_value(q, *sel) as f64, ..NoiseMoments::default() };
            if !ctx.point {
                m.grad = Dim::<D>::point_gradient(q, *sel, ctx.work);
                m.var = Dim::<D>::linear_variance(m.grad, s);
            }
            out[k] = m;
        }
        ctx.work.lattice += 1 << D;
        return true;
    }
    let (kappa, sigma_e) = (Dim::<D>::kappa(sels[0]), Dim::<D>::SIGMA_EXACT);
    let damp =
        |s: f64| if s > sigma_e { crate::gaussian::exp_damping(-kappa * (s * s - sigma_e * sigma_e)) } else { 1.0 };
    let att = s[1..].iter().fold(damp(s[0]), |acc, &x| acc * damp(x));
    if att < OCTAVE_CUTOFF {
        let cut = NoiseMoments { var: Dim::<D>::variance(sels[0]), ..NoiseMoments::default() };
        for o in out.iter_mut() {
            *o = cut;
        }
        return false;
    }
    let se = Dim::<D>::exact_spreads(s);
    let mut r = [[0.0; 4]; 4];
    // Channels with equal offsets share one corner sum.
    if offsets.iter().all(|o| *o == offsets[0]) {
        exact_sum::<D>(at(&offsets[0]), se, att, sels, &mut r, ctx.work);
    } else {
        for (k, sel) in sels.iter().enumerate() {
            let mut one = [[0.0; 4]; 4];
            exact_sum::<D>(at(&offsets[k]), se, att, std::slice::from_ref(sel), &mut one, ctx.work);
            r[k] = one[0];
        }
    }
    let model = Dim::<D>::variance_model(sels[0], s);
    for k in 0..sels.len() {
        let mut grad = [0.0; D];
        for (a, g) in grad.iter_mut().enumerate() {
            *g = r[k][1 + a] * att;
        }
        let var = Dim::<D>::footprint_variance(model, Dim::<D>::linear_variance(grad, s));
        out[k] = NoiseMoments { mean: r[k][0] * att, grad, var };
    }
    true
}
