//! Worley noise.

use super::lattice::{Dim, Lattice};
use super::perlin::NoiseMoments;
use super::{coordinate, coordinate3, moments2, to_uv, to_uv3, PatternStats};
use crate::gaussian;
use crate::nodes::hash::ifloor;
use crate::nodes::Ctx;
use crate::value::{Filtered, Moments, ValueType};
use glam::{DVec2, Vec2, Vec3};

/// Unfiltered MaterialX `mx_worley_noise_*(vec2)` (Euclidean metric): the `n` nearest
/// distances (style 0) or the nearest feature's cell value(s) (style 1).
pub fn worley_point(p: Vec2, jitter: f32, style: i32, n: usize) -> [f32; 3] {
    worley(p.to_array(), jitter, style, n)
}

/// Unfiltered MaterialX `mx_worley_noise_*(vec3)` (Euclidean metric): the `n` nearest
/// distances (style 0) or the nearest feature's cell value(s) (style 1).
pub fn worley3_point(p: Vec3, jitter: f32, style: i32, n: usize) -> [f32; 3] {
    worley(p.to_array(), jitter, style, n)
}

/// The 3^D cells around a cell, as offsets in −1..=1 per axis, visited in GLSL's nested order
/// (the last axis fastest). Nested loops per dimension: one loop decoding the offsets from an
/// index, or an odometer, measured 10–40 % slower than these.
trait Neighbourhood<const D: usize>: Lattice<D> {
    /// Calls `f` with each offset in order.
    fn neighbours(f: impl FnMut([i32; D]));
}

impl Neighbourhood<2> for Dim<2> {
    #[inline(always)]
    fn neighbours(mut f: impl FnMut([i32; 2])) {
        for x in -1..=1 {
            for y in -1..=1 {
                f([x, y]);
            }
        }
    }
}

impl Neighbourhood<3> for Dim<3> {
    #[inline(always)]
    fn neighbours(mut f: impl FnMut([i32; 3])) {
        for x in -1..=1 {
            for y in -1..=1 {
                for z in -1..=1 {
                    f([x, y, z]);
                }
            }
        }
    }
}

/// MaterialX Worley noise at `p` (f32, as GLSL computes it): the squared distances to the
/// jittered feature points of the 3^D cells around `p`'s, visited in GLSL's nested order (the
/// last axis fastest, which decides ties; [`Neighbourhood`]), the three nearest kept; then the distances, or the
/// cell noise of the nearest feature's cell.
#[inline(always)]
fn worley<const D: usize>(p: [f32; D], jitter: f32, style: i32, n: usize) -> [f32; 3]
where
    Dim<D>: Neighbourhood<D>,
{
    worley_with(p, style, n, |c| feature_offset::<D>(c, jitter))
}

/// Where cell `c`'s feature point lies within the cell (MaterialX's jittered offset).
#[inline(always)]
fn feature_offset<const D: usize>(c: [i32; D], jitter: f32) -> [f32; D]
where
    Dim<D>: Lattice<D>,
{
    std::array::from_fn(|a| (Dim::<D>::cell(c, a, true) - 0.5) * jitter + 0.5)
}

/// [`worley`] with the cells' feature offsets from `offset(c)`.
#[inline(always)]
fn worley_with<const D: usize>(
    p: [f32; D],
    style: i32,
    n: usize,
    mut offset: impl FnMut([i32; D]) -> [f32; D],
) -> [f32; 3]
where
    Dim<D>: Neighbourhood<D>,
{
    let mut d = [1e6f32; 3];
    let mut minpos = [0.0f32; D];
    each_feature(p, &mut offset, |dist, cell| {
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
    });
    worley_values(p, d, minpos, style, n)
}

/// What the search at `p` gives from its three nearest squared distances `d` and the offset
/// `nearest` to the nearest feature: the distances (style 0), or the cell noise of the nearest
/// feature's cell (style 1; `n` channels).
#[inline(always)]
fn worley_values<const D: usize>(p: [f32; D], d: [f32; 3], nearest: [f32; D], style: i32, n: usize) -> [f32; 3]
where
    Dim<D>: Lattice<D>,
{
    if style == 1 {
        let mut q = nearest;
        for (q, p) in q.iter_mut().zip(p) {
            *q += p;
        }
        let c = q.map(ifloor);
        if n == 1 {
            [Dim::<D>::cell(c, 0, false), 0.0, 0.0]
        } else {
            [Dim::<D>::cell(c, 0, true), Dim::<D>::cell(c, 1, true), Dim::<D>::cell(c, 2, true)]
        }
    } else {
        [d[0].sqrt(), d[1].sqrt(), d[2].sqrt()]
    }
}

/// Calls `f(squared distance, offset)` from `p` to the feature point of each of the 3^D cells
/// around `p`'s (`offset(c)` placing cell `c`'s feature within it), in the search's order and
/// f32 arithmetic.
#[inline(always)]
fn each_feature<const D: usize>(
    p: [f32; D],
    mut offset: impl FnMut([i32; D]) -> [f32; D],
    mut f: impl FnMut(f32, [f32; D]),
) where
    Dim<D>: Neighbourhood<D>,
{
    let c0 = p.map(ifloor);
    let mut local = p;
    for (l, c) in local.iter_mut().zip(c0) {
        *l -= c as f32;
    }
    Dim::<D>::neighbours(|o| {
        let mut c = c0;
        for (c, o) in c.iter_mut().zip(o) {
            *c = c.wrapping_add(o);
        }
        let off = offset(c);
        let mut cell = [0.0f32; D];
        for (a, x) in cell.iter_mut().enumerate() {
            *x = o[a] as f32 + off[a] - local[a];
        }
        f(cell[1..].iter().fold(cell[0] * cell[0], |acc, x| acc + x * x), cell);
    });
}

/// The four nearest squared distances of [`worley`]'s search at `p` (the same cells, order,
/// ties and f32 arithmetic, so its first three are the search's) and the offsets from `p` to
/// the three nearest feature points.
#[inline(always)]
fn worley_ranked<const D: usize>(p: [f32; D], jitter: f32) -> ([f32; 4], [[f32; D]; 3])
where
    Dim<D>: Neighbourhood<D>,
{
    let mut d = [1e6f32; 4];
    let mut at = [[0.0f32; D]; 3];
    let offset = |c| feature_offset::<D>(c, jitter);
    each_feature(p, offset, |dist, cell| {
        // Insertion into the sorted four, strict as the search's own comparisons.
        let mut k = 4;
        while k > 0 && dist < d[k - 1] {
            k -= 1;
        }
        if k < 4 {
            for j in (k + 1..4).rev() {
                d[j] = d[j - 1];
                if j < 3 {
                    at[j] = at[j - 1];
                }
            }
            d[k] = dist;
            if k < 3 {
                at[k] = cell;
            }
        }
    });
    (d, at)
}

/// Multiples of the footprint's spread (its per-axis spreads' length) within which nothing may
/// change for [`worley_settled`]: beyond, a Gaussian leaves under 1e-9 of its mass.
const WORLEY_SETTLED: f64 = 6.5;

/// Filtered Worley noise where a small footprint changes nothing but the distances themselves:
/// it stays inside one lattice cell along each axis to 6.5 of that axis's spreads (so the search
/// visits the same cells), and the features
/// ranked nearest keep their ranks (consecutive distances more than twice its reach apart) and
/// lie beyond its reach. Then cell values (style 1) are constant, and each distance `|x − f|`
/// is smooth over the footprint: its mean is the value at the centre plus
/// `(tr Σ − uᵀΣu) / 2d` (`u` the unit direction from the feature, `Σ = diag(s²)`; the next term
/// is `O(σ⁴/d³)`, below 1e-4 σ here), its gradient `u`, its variance `uᵀΣu`. `None` where the
/// footprint is not small enough; the quadrature then decides.
fn worley_settled<const D: usize>(
    p: [f64; D],
    s: [f64; D],
    jitter: f32,
    style: i32,
    n: usize,
) -> Option<[NoiseMoments<D>; 3]>
where
    Dim<D>: Neighbourhood<D>,
{
    let reach = WORLEY_SETTLED * s.iter().map(|x| x * x).sum::<f64>().sqrt();
    if !(reach < 0.25) {
        return None;
    }
    let pf = p.map(|x| x as f32);
    // Inside the cell along every axis the footprint spreads on (one without spread, such as a
    // surface's normal axis in 3D, may lie on a cell face).
    for ((&x, &xf), &sa) in p.iter().zip(&pf).zip(&s) {
        let (f, r) = (x - f64::from(ifloor(xf)), WORLEY_SETTLED * sa);
        if !(sa == 0.0 || (f > r && f < 1.0 - r)) {
            return None;
        }
    }
    let (d2, at) = worley_ranked(pf, jitter);
    let d = d2.map(|x| f64::from(x).sqrt());
    let ranked = if style == 1 { 1 } else { n };
    if !(d[0] > reach) || (0..ranked).any(|k| !(d[k + 1] - d[k] > 2.0 * reach)) {
        return None;
    }
    // The point value from the same search (its three nearest, in its order).
    let v = worley_values(pf, [d2[0], d2[1], d2[2]], at[0], style, n);
    let mut out = [NoiseMoments::<D>::default(); 3];
    for (k, o) in out.iter_mut().enumerate().take(n) {
        o.mean = f64::from(v[k]);
        if style == 1 {
            continue;
        }
        let dk = d[k];
        let u: [f64; D] = std::array::from_fn(|a| -f64::from(at[k][a]) / dk);
        let trace: f64 = s.iter().map(|x| x * x).sum();
        let along: f64 = u.iter().zip(&s).map(|(u, s)| u * u * s * s).sum();
        o.mean += (trace - along) / (2.0 * dk);
        o.grad = u;
        o.var = along;
    }
    Some(out)
}

pub(super) fn worley_stats(jitter: f32, n: usize) -> PatternStats {
    let (mut s, mut s2) = ([0.0f64; 3], [0.0f64; 3]);
    let res = 40;
    let count = (res * res) as f64;
    for i in 0..res {
        for j in 0..res {
            let p = Vec2::new(3.0 + 6.0 * (i as f32 + 0.5) / res as f32, -7.0 + 6.0 * (j as f32 + 0.5) / res as f32);
            let v = worley_point(p, jitter, 0, n);
            for k in 0..3 {
                s[k] += v[k] as f64;
                s2[k] += (v[k] as f64).powi(2);
            }
        }
    }
    let mut st = PatternStats::default();
    for k in 0..3 {
        st.mean[k] = (s[k] / count) as f32;
        st.var[k] = (s2[k] / count - (s[k] / count).powi(2)).max(0.0) as f32;
    }
    st
}

pub(super) fn worley2d(stats: &PatternStats, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (p, s, j) = coordinate(&ins[0]);
    let (jitter, style) = (ins[1].ch[0].mean, ins[2].ch[0].mean.round() as i32);
    let global = if style == 1 { ([0.5; 3], [1.0 / 12.0; 3]) } else { (stats.mean, stats.var) };
    // Noise-space moments rounded to f32 before the Jacobian, as the 2D nodes do.
    let finish = |m: NoiseMoments<2>| to_uv(&moments2(&m, |x| x as f32), &j);
    worley_filtered(ty, p.to_array(), s.to_array(), s.x.max(s.y), jitter, style, global, finish, ctx)
}

/// Cells' feature offsets, computed on first use, over the block of cells a filtered 2D Worley
/// evaluation's quadrature nodes can reach (nodes within 2.86σ of the centre, σ < 2 cells, and
/// each node's 3 × 3 neighbourhood: at most 16 cells per axis): the nodes' neighbourhoods
/// overlap, so each cell's feature point is hashed once.
struct FeatureCells {
    x0: i32,
    y0: i32,
    known: [u16; FEATURE_BLOCK],
    offsets: [[[f32; 2]; FEATURE_BLOCK]; FEATURE_BLOCK],
}

/// Cells per axis of a [`FeatureCells`] block.
const FEATURE_BLOCK: usize = 16;

impl FeatureCells {
    /// The block whose lower corner is one cell below the lowest node's cell (in f32, as the
    /// nodes' cells are found).
    fn around(p: DVec2, s: DVec2) -> FeatureCells {
        // The outermost node of the widest rule.
        let reach = gaussian::HERMITE5[4].0 * s;
        let lo = (p - reach).as_vec2();
        FeatureCells {
            x0: ifloor(lo.x).wrapping_sub(2),
            y0: ifloor(lo.y).wrapping_sub(2),
            known: [0; FEATURE_BLOCK],
            offsets: [[[0.0; 2]; FEATURE_BLOCK]; FEATURE_BLOCK],
        }
    }

    /// Cell `c`'s feature offset ([`feature_offset`]), from the block when the cell is in it
    /// (always, for the nodes the block was made for).
    #[inline(always)]
    fn offset(&mut self, c: [i32; 2], jitter: f32) -> [f32; 2] {
        let (i, j) = (c[0].wrapping_sub(self.x0) as u32 as usize, c[1].wrapping_sub(self.y0) as u32 as usize);
        if i >= FEATURE_BLOCK || j >= FEATURE_BLOCK {
            return feature_offset(c, jitter);
        }
        if self.known[j] & (1 << i) == 0 {
            self.known[j] |= 1 << i;
            self.offsets[j][i] = feature_offset(c, jitter);
        }
        self.offsets[j][i]
    }
}

/// Planes of the statistics table: `PLANES` bins of a lattice coordinate's fraction.
pub(super) const PLANES: usize = 16;

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
pub(super) fn worley3_stats(jitter: f32, n: usize) -> WorleyStats {
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
    pub(super) fn wide(&self, thin: Option<(f64, f64)>) -> PatternStats {
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

pub(super) fn worley3d(stats: &WorleyStats, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (p, s, j) = coordinate3(&ins[0]);
    let (jitter, style) = (ins[1].ch[0].mean, ins[2].ch[0].mean.round() as i32);
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
    let finish = |m: NoiseMoments<3>| to_uv3(&m, &j);
    worley_filtered(ty, p.to_array(), s.to_array(), smax, jitter, style, (gmean, gvar), finish, ctx)
}

/// What filtered Worley noise does differently in 2D and 3D, each as it always did: 3D gives an
/// axis without spread a single node (2D repeats the full rule along it), the two round the
/// nodes' weighted offsets in different orders, and 2D hashes each cell's feature point once
/// per evaluation ([`FeatureCells`]) where 3D hashes it at every node.
trait WorleyFilter<const D: usize>: Neighbourhood<D> {
    /// Whether an axis without spread gets a single node (the mean).
    const SINGLE_NODE_WITHOUT_SPREAD: bool;
    /// The cells' feature offsets over one filtered evaluation.
    type Features;
    /// The features for the nodes of a footprint at `p` with spreads `s`.
    fn features(p: [f64; D], s: [f64; D]) -> Self::Features;
    /// Unfiltered Worley noise at node `p`.
    fn point(features: &mut Self::Features, p: [f32; D], jitter: f32, style: i32, n: usize) -> [f32; 3];
    /// A node's term `w z v` of `E[z f]` (weight `w`, offset `z` in σ, value `v`).
    fn weighted_offset(w: f64, z: f64, v: f64) -> f64;
}

impl WorleyFilter<2> for Dim<2> {
    const SINGLE_NODE_WITHOUT_SPREAD: bool = false;
    type Features = FeatureCells;
    #[inline(always)]
    fn features(p: [f64; 2], s: [f64; 2]) -> FeatureCells {
        FeatureCells::around(DVec2::from_array(p), DVec2::from_array(s))
    }
    #[inline(always)]
    fn point(features: &mut FeatureCells, p: [f32; 2], jitter: f32, style: i32, n: usize) -> [f32; 3] {
        worley_with(p, style, n, |c| features.offset(c, jitter))
    }
    #[inline(always)]
    fn weighted_offset(w: f64, z: f64, v: f64) -> f64 {
        w * z * v
    }
}

impl WorleyFilter<3> for Dim<3> {
    const SINGLE_NODE_WITHOUT_SPREAD: bool = true;
    type Features = ();
    #[inline(always)]
    fn features(_: [f64; 3], _: [f64; 3]) {}
    #[inline(always)]
    fn point(_: &mut (), p: [f32; 3], jitter: f32, style: i32, n: usize) -> [f32; 3] {
        worley(p, jitter, style, n)
    }
    #[inline(always)]
    fn weighted_offset(w: f64, z: f64, v: f64) -> f64 {
        z * (w * v)
    }
}

/// Filtered Worley noise at noise-space coordinate `p` with per-axis spreads `s` (largest
/// `smax`): a small footprint that changes no cell and no rank is the point value with its
/// second-order correction ([`worley_settled`]); otherwise Gauss–Hermite over the footprint (3 nodes per axis below 0.2 cells or when all three
/// axes spread, 5 beyond) up to σ = 1 cell, blended into the pattern's `global` (mean,
/// variance) by σ = 2, then the global statistics alone; the gradient by Stein's identity
/// (`dE/dm = E[z f] / σ` per axis). `finish` maps a channel's noise-space moments to uv.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn worley_filtered<const D: usize>(
    ty: ValueType,
    p: [f64; D],
    s: [f64; D],
    smax: f64,
    jitter: f32,
    style: i32,
    (gmean, gvar): ([f32; 3], [f32; 3]),
    finish: impl Fn(NoiseMoments<D>) -> Moments,
    ctx: &mut Ctx,
) -> Filtered
where
    Dim<D>: WorleyFilter<D>,
{
    let n = ty.channels();
    let mut out = Filtered::zero(ty);
    let cells = 3u64.pow(D as u32);
    if smax == 0.0 {
        let v = worley(p.map(|x| x as f32), jitter, style, n);
        for k in 0..n {
            out.ch[k] = Moments::constant(v[k]);
        }
        ctx.work.lattice += cells;
        return out;
    }
    if let Some(m) = worley_settled(p, s, jitter, style, n) {
        for k in 0..n {
            out.ch[k] = finish(m[k]);
        }
        ctx.work.lattice += 2 * cells;
        return out;
    }
    let w_global = (smax - 1.0).clamp(0.0, 1.0);
    if w_global >= 1.0 {
        for k in 0..n {
            out.ch[k] = Moments { mean: gmean[k], grad: Vec2::ZERO, var: gvar[k] };
        }
        return out;
    }
    let spreading = s.iter().filter(|&&x| x > 0.0).count();
    let fine: &[(f64, f64)] = if smax < 0.2 || spreading > 2 { &gaussian::HERMITE3 } else { &gaussian::HERMITE5 };
    let single: &[(f64, f64)] = &[(0.0, 1.0)];
    let mut rules = [fine; D];
    for (rule, &sa) in rules.iter_mut().zip(&s) {
        // NaN counts as no spread, as in 3D's `s > 0` test.
        let spreads = sa > 0.0;
        if Dim::<D>::SINGLE_NODE_WITHOUT_SPREAD && !spreads {
            *rule = single;
        }
    }
    let (mut e, mut e2, mut ez) = ([0.0f64; 3], [0.0f64; 3], [[0.0f64; D]; 3]);
    let mut features = Dim::<D>::features(p, s);
    // The nodes in order, x fastest (an odometer over the axes' rules).
    let nodes: usize = rules.iter().map(|r| r.len()).product();
    let mut at = [0usize; D];
    for _ in 0..nodes {
        let (mut z, mut q) = ([0.0; D], [0.0f32; D]);
        let mut w = 1.0;
        for a in 0..D {
            let (za, wa) = rules[a][at[a]];
            z[a] = za;
            q[a] = (p[a] + za * s[a]) as f32;
            w = if a == 0 { wa } else { w * wa };
        }
        let v = Dim::<D>::point(&mut features, q, jitter, style, n);
        for k in 0..n {
            let vk = v[k] as f64;
            e[k] += w * vk;
            e2[k] += w * vk * vk;
            for (eza, za) in ez[k].iter_mut().zip(z) {
                *eza += Dim::<D>::weighted_offset(w, za, vk);
            }
        }
        for a in 0..D {
            at[a] += 1;
            if at[a] < rules[a].len() {
                break;
            }
            at[a] = 0;
        }
    }
    ctx.work.lattice += cells * nodes as u64;
    let wl = 1.0 - w_global;
    for k in 0..n {
        let var = (e2[k] - e[k] * e[k]).max(0.0);
        let mut grad = [0.0; D];
        for a in 0..D {
            let g = if s[a] > 0.0 { ez[k][a] / s[a] } else { 0.0 };
            grad[a] = g * wl;
        }
        let m = NoiseMoments {
            mean: wl * e[k] + w_global * gmean[k] as f64,
            grad,
            var: wl * var + w_global * gvar[k] as f64,
        };
        out.ch[k] = finish(m);
    }
    out
}

#[cfg(test)]
mod settled_tests {
    use super::*;

    /// Where [`worley_settled`] answers, its moments are those of the point function over the
    /// footprint, by brute force (4096 draws of `N(p, diag(s²))`): the mean within four standard
    /// errors (plus 2e-6 for the f32 point values), the variance within 10 %, each gradient
    /// component (by the draws' covariance with their offsets, Stein's identity) within five of
    /// its standard errors (plus 0.02);
    /// cell values (style 1) constant over every draw. 2D and 3D (some on a lattice plane with
    /// no spread across it), 1 to 3 distances. And it answers for most footprints under 1e-3
    /// cells.
    #[test]
    fn settled_worley_matches_brute_force() {
        let mut rnd = crate::testing::uniform(0x1319_8a2e_0370_7344);
        let normal = move |r: &mut dyn FnMut() -> f64| {
            let (u, v) = (r().max(1e-300), r());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let (mut answered, mut small) = (0, 0);
        for case in 0..600 {
            let sigma = 10f64.powf(-4.5 + 2.5 * rnd());
            let (jitter, style, n) = (if case % 3 == 0 { 1.0 } else { 0.75 }, (case % 4 == 3) as i32, 1 + case % 3);
            small += (sigma < 1e-3) as i32;
            macro_rules! check {
                ($d:expr) => {{
                    const D: usize = $d;
                    let mut p: [f64; D] = std::array::from_fn(|_| rnd() * 40.0 - 20.0);
                    let mut s: [f64; D] = std::array::from_fn(|_| sigma * (0.3 + 0.7 * rnd()));
                    if D == 3 && case % 3 == 1 {
                        // A surface on a lattice plane: no spread across it, on a cell face.
                        // (`D - 1`: the last axis, which clippy sees in bounds for D = 2 too.)
                        p[D - 1] = p[D - 1].round();
                        s[D - 1] = 0.0;
                    }
                    if let Some(m) = worley_settled::<D>(p, s, jitter, style, n) {
                        answered += (sigma < 1e-3) as i32;
                        let draws = 4096;
                        let (mut sum, mut sq) = ([0.0f64; 3], [0.0f64; 3]);
                        let (mut sz, mut sz2) = ([[0.0f64; D]; 3], [[0.0f64; D]; 3]);
                        for _ in 0..draws {
                            let z: [f64; D] = std::array::from_fn(|_| normal(&mut rnd));
                            let q: [f32; D] = std::array::from_fn(|a| (p[a] + s[a] * z[a]) as f32);
                            let v = worley(q, jitter, style, n);
                            for k in 0..n {
                                let x = f64::from(v[k]);
                                if style == 1 {
                                    assert_eq!(x, m[k].mean, "style 1 at {q:?}: not constant");
                                }
                                sum[k] += x;
                                sq[k] += x * x;
                                // Centred on the claimed mean: E[Z] = 0 keeps Stein's identity,
                                // and the draws' noise scales with the spread, not the value.
                                for a in (0..D).filter(|&a| s[a] > 0.0) {
                                    let w = (x - m[k].mean) * z[a] / s[a];
                                    sz[k][a] += w;
                                    sz2[k][a] += w * w;
                                }
                            }
                        }
                        for k in 0..n {
                            let mean = sum[k] / draws as f64;
                            let var = (sq[k] / draws as f64 - mean * mean).max(0.0);
                            let se = (var / draws as f64).sqrt();
                            assert!(
                                (m[k].mean - mean).abs() <= 4.0 * se + 2e-6,
                                "{D}D p {p:?} s {s:?} ch {k}: mean {} vs {mean} (se {se:.2e})",
                                m[k].mean
                            );
                            if style == 0 {
                                assert!((m[k].var / var - 1.0).abs() < 0.1, "{D}D ch {k}: var {} vs {var}", m[k].var);
                                // Along the axes the footprint spreads on (Stein's identity
                                // measures nothing across the others).
                                for a in (0..D).filter(|&a| s[a] > 0.0) {
                                    let g = sz[k][a] / draws as f64;
                                    let se = ((sz2[k][a] / draws as f64 - g * g).max(0.0) / draws as f64).sqrt();
                                    assert!(
                                        (g - m[k].grad[a]).abs() < 5.0 * se + 0.02,
                                        "{D}D ch {k} axis {a}: gradient {} vs {g} (se {se:.3})",
                                        m[k].grad[a]
                                    );
                                }
                            }
                        }
                    }
                }};
            }
            check!(2);
            check!(3);
        }
        assert!(answered as f64 > 0.8 * (2 * small) as f64, "answered {answered} of {} small footprints", 2 * small);
    }
}
