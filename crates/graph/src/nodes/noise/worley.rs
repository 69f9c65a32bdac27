//! Worley noise.

use super::lattice::{Dim, Lattice};
use super::perlin::NoiseMoments;
use super::{coordinate, coordinate3, to_uv, to_uv3, PatternStats};
use crate::gaussian;
use crate::nodes::hash::ifloor;
use crate::nodes::Ctx;
use crate::value::{Filtered, Moments, ValueType};
use glam::{DVec2, DVec3, Vec2, Vec3};

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
    let c0 = p.map(ifloor);
    let mut local = p;
    for (l, c) in local.iter_mut().zip(c0) {
        *l -= c as f32;
    }
    let mut d = [1e6f32; 3];
    let mut minpos = [0.0f32; D];
    Dim::<D>::neighbours(|o| {
        let mut c = c0;
        for (c, o) in c.iter_mut().zip(o) {
            *c = c.wrapping_add(o);
        }
        let mut cell = [0.0f32; D];
        for (a, x) in cell.iter_mut().enumerate() {
            let off = (Dim::<D>::cell(c, a, true) - 0.5) * jitter + 0.5;
            *x = o[a] as f32 + off - local[a];
        }
        let dist = cell[1..].iter().fold(cell[0] * cell[0], |acc, x| acc + x * x);
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
    if style == 1 {
        let mut q = minpos;
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
    let jitter = ins[1].ch[0].mean;
    let style = ins[2].ch[0].mean.round() as i32;
    let n = ty.channels();
    let mut out = Filtered::zero(ty);
    let (gmean, gvar) = if style == 1 { ([0.5; 3], [1.0 / 12.0; 3]) } else { (stats.mean, stats.var) };
    let smax = s.x.max(s.y);
    if smax == 0.0 {
        let v = worley_point(p.as_vec2(), jitter, style, n);
        for k in 0..n {
            out.ch[k] = Moments::constant(v[k]);
        }
        ctx.work.lattice += 9;
        return out;
    }
    let w_global = ((smax - 1.0) / 1.0).clamp(0.0, 1.0);
    if w_global >= 1.0 {
        for k in 0..n {
            out.ch[k] = Moments { mean: gmean[k], grad: Vec2::ZERO, var: gvar[k] };
        }
        return out;
    }
    let (mut e, mut e2, mut ex, mut ey) = ([0.0f64; 3], [0.0f64; 3], [0.0f64; 3], [0.0f64; 3]);
    // 3×3 nodes suffice while the footprint is small against a cell; 5×5 beyond.
    let rule: &[(f64, f64)] = if smax < 0.2 { &gaussian::HERMITE3 } else { &gaussian::HERMITE5 };
    for &(zy, wy) in rule {
        for &(zx, wx) in rule {
            let q = p + DVec2::new(zx * s.x, zy * s.y);
            let v = worley_point(q.as_vec2(), jitter, style, n);
            for k in 0..n {
                let w = wx * wy;
                let vk = v[k] as f64;
                e[k] += w * vk;
                e2[k] += w * vk * vk;
                ex[k] += w * zx * vk;
                ey[k] += w * zy * vk;
            }
        }
    }
    ctx.work.lattice += 9 * (rule.len() * rule.len()) as u64;
    for k in 0..n {
        let var = (e2[k] - e[k] * e[k]).max(0.0);
        let gx = if s.x > 0.0 { ex[k] / s.x } else { 0.0 };
        let gy = if s.y > 0.0 { ey[k] / s.y } else { 0.0 };
        let wl = 1.0 - w_global;
        let m = Moments {
            mean: (wl * e[k] + w_global * gmean[k] as f64) as f32,
            grad: Vec2::new((wl * gx) as f32, (wl * gy) as f32),
            var: (wl * var + w_global * gvar[k] as f64) as f32,
        };
        out.ch[k] = to_uv(&m, &j);
    }
    out
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
        let m = NoiseMoments {
            mean: wl * e[k] + w_global * gmean[k] as f64,
            grad: (g * wl).to_array(),
            var: wl * var + w_global * gvar[k] as f64,
        };
        out.ch[k] = to_uv3(&m, &j);
    }
    out
}
