//! Worley noise.

use super::perlin::NoiseMoments;
use super::{coordinate, coordinate3, to_uv, to_uv3, PatternStats};
use crate::gaussian;
use crate::nodes::hash::{cell3_float, cell3_vec3, cell_float, cell_vec3, ifloor};
use crate::nodes::Ctx;
use crate::value::{Filtered, Moments, ValueType};
use glam::{DVec2, DVec3, Vec2, Vec3};

/// Unfiltered MaterialX `mx_worley_noise_*(vec2)` (Euclidean metric): the `n` nearest
/// distances (style 0) or the nearest feature's cell value(s) (style 1).
pub fn worley_point(p: Vec2, jitter: f32, style: i32, n: usize) -> [f32; 3] {
    worley_point_with(p, style, n, |cx, cy| feature_offset(cx, cy, jitter))
}

/// Where cell `(cx, cy)`'s feature point lies within the cell (MaterialX's jittered offset).
#[inline(always)]
fn feature_offset(cx: i32, cy: i32, jitter: f32) -> Vec2 {
    let off = Vec2::new(cell_vec3(cx, cy, 0), cell_vec3(cx, cy, 1));
    (off - 0.5) * jitter + 0.5
}

/// [`worley_point`] with the cells' feature offsets from `offset(cx, cy)`.
#[inline(always)]
fn worley_point_with(p: Vec2, style: i32, n: usize, mut offset: impl FnMut(i32, i32) -> Vec2) -> [f32; 3] {
    let (x0, y0) = (ifloor(p.x), ifloor(p.y));
    let local = Vec2::new(p.x - x0 as f32, p.y - y0 as f32);
    let mut d = [1e6f32; 3];
    let mut minpos = Vec2::ZERO;
    for x in -1..=1 {
        for y in -1..=1 {
            let (cx, cy) = (x0.wrapping_add(x), y0.wrapping_add(y));
            let off = offset(cx, cy);
            let cell = Vec2::new(x as f32, y as f32) + off - local;
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
    if style == 1 {
        let q = minpos + p;
        let (ix, iy) = (ifloor(q.x), ifloor(q.y));
        if n == 1 {
            [cell_float(ix, iy), 0.0, 0.0]
        } else {
            [cell_vec3(ix, iy, 0), cell_vec3(ix, iy, 1), cell_vec3(ix, iy, 2)]
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
    // The nodes' 3 × 3 cell neighbourhoods overlap: each cell's feature point is hashed once.
    let mut features = FeatureCells::around(p, s);
    for &(zy, wy) in rule {
        for &(zx, wx) in rule {
            let q = p + DVec2::new(zx * s.x, zy * s.y);
            let v = worley_point_with(q.as_vec2(), style, n, |cx, cy| features.offset(cx, cy, jitter));
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

/// Cells' feature offsets, computed on first use, over the block of cells a filtered Worley
/// evaluation's quadrature nodes can reach (nodes within 2.86σ of the centre, σ < 2 cells, and
/// each node's 3 × 3 neighbourhood: at most 16 cells per axis).
struct FeatureCells {
    x0: i32,
    y0: i32,
    known: [u16; FEATURE_BLOCK],
    offsets: [[Vec2; FEATURE_BLOCK]; FEATURE_BLOCK],
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
            offsets: [[Vec2::ZERO; FEATURE_BLOCK]; FEATURE_BLOCK],
        }
    }

    /// Cell `(cx, cy)`'s feature offset ([`feature_offset`]), from the block when the cell is in
    /// it (always, for the nodes the block was made for).
    #[inline(always)]
    fn offset(&mut self, cx: i32, cy: i32, jitter: f32) -> Vec2 {
        let (i, j) = (cx.wrapping_sub(self.x0) as u32 as usize, cy.wrapping_sub(self.y0) as u32 as usize);
        if i >= FEATURE_BLOCK || j >= FEATURE_BLOCK {
            return feature_offset(cx, cy, jitter);
        }
        if self.known[j] & (1 << i) == 0 {
            self.known[j] |= 1 << i;
            self.offsets[j][i] = feature_offset(cx, cy, jitter);
        }
        self.offsets[j][i]
    }
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
