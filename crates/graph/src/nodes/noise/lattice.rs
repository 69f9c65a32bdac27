//! Unfiltered MaterialX Perlin lattices (f32, as GLSL computes them).

use super::cell::{cell_axis, cell_axis_shared};
use super::perlin::{
    share_model, PERLIN3_SLICE_KAPPA, PERLIN3_SLICE_SHARE, PERLIN_KAPPA, PERLIN_SHARE, PERLIN_VARIANCE,
};
use crate::nodes::hash::{self, ifloor};
use glam::{DVec2, Vec2, Vec3};

#[inline]
pub(super) fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline]
pub(super) fn gradient(h: u32, x: f32, y: f32) -> f32 {
    let h = h & 7;
    let u = if h < 4 { x } else { y };
    let v = 2.0 * if h < 4 { y } else { x };
    (if h & 1 != 0 { -u } else { u }) + (if h & 2 != 0 { -v } else { v })
}

/// The gradient vector `g` with `gradient(h, x, y) = g · (x, y)`.
#[inline]
pub(super) fn gradient_vector(h: u32) -> DVec2 {
    let h = h & 7;
    let s1 = if h & 1 != 0 { -1.0 } else { 1.0 };
    let s2 = if h & 2 != 0 { -2.0 } else { 2.0 };
    if h < 4 {
        DVec2::new(s1, s2)
    } else {
        DVec2::new(s2, s1)
    }
}

/// Which lattice a Perlin evaluation uses: which bits of a corner hash choose the 2D gradient
/// (the whole hash for float noise, one byte for channel `k` of vector noise), or the slice
/// `z = const` of MaterialX's 3D float noise (`fractal3d` inside `unifiednoise2d`).
#[derive(Clone, Copy, Debug)]
pub(super) enum HashSel {
    Full,
    Byte(u32),
    Slice(f32),
}

impl HashSel {
    #[inline]
    pub(super) fn pick(self, h: u32) -> u32 {
        match self {
            HashSel::Full | HashSel::Slice(_) => h,
            HashSel::Byte(k) => (h >> (8 * k)) & 0xff,
        }
    }

    /// The lattice's gradient scale (MaterialX `mx_gradient_scale2d` / `3d`).
    #[inline]
    pub(super) fn scale(self) -> f64 {
        match self {
            HashSel::Slice(_) => GRADIENT_SCALE_3D as f64,
            _ => GRADIENT_SCALE_2D as f64,
        }
    }

    /// Variance of the lattice's noise over the plane (measured; a 3D slice's varies with
    /// `z` between 0.064 and 0.077).
    #[inline]
    pub(super) fn variance(self) -> f64 {
        match self {
            HashSel::Slice(_) => PERLIN3_SLICE_VARIANCE,
            _ => PERLIN_VARIANCE,
        }
    }

    /// Gaussian damping rate per axis beyond [`PERLIN_SIGMA_EXACT`].
    #[inline]
    pub(super) fn kappa(self) -> f64 {
        match self {
            HashSel::Slice(_) => PERLIN3_SLICE_KAPPA,
            _ => PERLIN_KAPPA,
        }
    }

    /// The share of the lattice's variance that the filtered mean keeps at per-axis spreads
    /// `s` (the rest is variance within the footprint).
    #[inline]
    pub(super) fn mean_share(self, s: DVec2) -> f64 {
        share_model(
            match self {
                HashSel::Slice(_) => PERLIN3_SLICE_SHARE,
                _ => PERLIN_SHARE,
            },
            s,
        )
    }

    /// Corner `(cx, cy)`'s kernel `g · (p − c) + k`: its in-plane gradient `g` and constant
    /// `k` (a 3D slice folds both z layers, weighted by the z fade, into them). `h2` is the
    /// corner's 2D hash.
    #[inline]
    pub(super) fn corner(self, cx: i32, cy: i32, h2: u32) -> (DVec2, f64) {
        self.corners().corner(cx, cy, h2)
    }

    /// What [`Self::corner`] needs for every corner of this lattice, computed once.
    #[inline]
    pub(super) fn corners(self) -> CornerSel {
        match self {
            HashSel::Slice(z) => {
                let z0 = z.floor();
                let fz = (z - z0) as f64;
                let wz = fade(fz as f32) as f64;
                CornerSel::Slice { z0: z0 as i32, fz, w: [1.0 - wz, wz] }
            }
            sel => CornerSel::Plane(sel),
        }
    }
}

/// A [`HashSel`] prepared for reading many corners: a slice's z layers and their fade weights
/// are the same for every corner. (Computed per corner they cost a `floorf` call per filtered
/// octave even on the plane lattices, where the compiler hoisted it ahead of the variant test.)
#[derive(Clone, Copy, Debug)]
pub(super) enum CornerSel {
    Plane(HashSel),
    Slice { z0: i32, fz: f64, w: [f64; 2] },
}

impl CornerSel {
    /// [`HashSel::corner`].
    #[inline(always)]
    pub(super) fn corner(self, cx: i32, cy: i32, h2: u32) -> (DVec2, f64) {
        match self {
            CornerSel::Slice { z0, fz, w } => {
                let mut g = DVec2::ZERO;
                let mut k = 0.0;
                for (l, w) in [(0, w[0]), (1, w[1])] {
                    if w == 0.0 {
                        continue;
                    }
                    let g3 = gradient3_vector(hash::hash3(cx, cy, z0.wrapping_add(l)));
                    g += DVec2::new(g3[0], g3[1]) * w;
                    k += g3[2] * (fz - l as f64) * w;
                }
                (g, k)
            }
            CornerSel::Plane(sel) => (gradient_vector(sel.pick(h2)), 0.0),
        }
    }
}

/// The gradient vector of MaterialX's 3D `mx_gradient_float(hash, x, y, z)`.
#[inline]
pub(super) fn gradient3_vector(h: u32) -> [f64; 3] {
    let h = h & 15;
    let mut g = [0.0; 3];
    let u = if h < 8 { 0 } else { 1 };
    let v = if h < 4 {
        1
    } else if h == 12 || h == 14 {
        0
    } else {
        2
    };
    g[u] += if h & 1 != 0 { -1.0 } else { 1.0 };
    g[v] += if h & 2 != 0 { -1.0 } else { 1.0 };
    g
}

#[inline]
pub(super) fn gradient3(h: u32, x: f32, y: f32, z: f32) -> f32 {
    let h = h & 15;
    let u = if h < 8 { x } else { y };
    let v = if h < 4 {
        y
    } else if h == 12 || h == 14 {
        x
    } else {
        z
    };
    (if h & 1 != 0 { -u } else { u }) + (if h & 2 != 0 { -v } else { v })
}

/// MaterialX `mx_perlin_noise_float(vec3)` (f32, as GLSL computes it).
#[inline]
pub fn perlin3_float(p: [f32; 3]) -> f32 {
    perlin(p, Sel::Full)
}

pub(super) const GRADIENT_SCALE_3D: f32 = 0.9820;
/// Variance of a `z = const` slice of MaterialX's 3D Perlin noise over the plane (measured,
/// averaged over `z`).
pub const PERLIN3_SLICE_VARIANCE: f64 = 0.072;
pub(super) const GRADIENT_SCALE_2D: f32 = 0.6616;

/// MaterialX `mx_perlin_noise_float(vec2)` / channel of `mx_perlin_noise_vec3(vec2)`.
pub(super) fn perlin_point(p: Vec2, sel: HashSel) -> f32 {
    if let HashSel::Slice(z) = sel {
        return perlin3_float([p.x, p.y, z]);
    }
    perlin(p.to_array(), sel)
}

/// The gradient of unfiltered Perlin noise at `p` (f64, from the corner kernels).
pub(super) fn perlin_gradient(p: DVec2, sel: HashSel) -> DVec2 {
    let (x0, y0) = (p.x.floor(), p.y.floor());
    let w = |d: f64| {
        let t = d.abs();
        let f = t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let df = 30.0 * t * t * (t - 1.0) * (t - 1.0);
        (1.0 - f, -df * d.signum())
    };
    let mut g = DVec2::ZERO;
    for (cx, cy) in [(x0, y0), (x0 + 1.0, y0), (x0, y0 + 1.0), (x0 + 1.0, y0 + 1.0)] {
        let (gv, k) = sel.corner(cx as i32, cy as i32, hash::hash2(cx as i32, cy as i32));
        let d = p - DVec2::new(cx, cy);
        let (wx, dwx) = w(d.x);
        let (wy, dwy) = w(d.y);
        let dot = gv.dot(d) + k;
        g.x += (gv.x * wx + dot * dwx) * wy;
        g.y += (gv.y * wy + dot * dwy) * wx;
    }
    g * sel.scale()
}

/// Beyond this magnitude an f32 coordinate has no fraction: Perlin noise is 0 there.
pub(crate) const LATTICE_PRECISION_LIMIT: f64 = 16_777_216.0;

/// Whether f32 resolves the lattice cell of a noise-space coordinate (`|x|, |y|` below
/// [`LATTICE_PRECISION_LIMIT`]; false for NaN too).
#[inline]
pub(crate) fn within_lattice_precision(p: DVec2) -> bool {
    p.x.abs() < LATTICE_PRECISION_LIMIT && p.y.abs() < LATTICE_PRECISION_LIMIT
}

/// Unfiltered float Perlin noise at `p` (MaterialX `mx_perlin_noise_float(vec2)`).
pub fn perlin_float(p: Vec2) -> f32 {
    perlin_point(p, HashSel::Full)
}

/// Which lattice a 3D Perlin evaluation uses: the whole corner hash (float noise) or byte `k`
/// of it (channel `k` of vector noise).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Sel {
    Full,
    Byte(u32),
}

impl Sel {
    #[inline]
    pub(super) fn pick(self, h: u32) -> u32 {
        match self {
            Sel::Full => h,
            Sel::Byte(k) => (h >> (8 * k)) & 0xff,
        }
    }
}

/// MaterialX `mx_perlin_noise_float(vec3)` (`Sel::Full`) or channel `k` of
/// `mx_perlin_noise_vec3(vec3)` (`Sel::Byte(k)`).
#[inline]
pub(super) fn perlin3_point(p: Vec3, sel: Sel) -> f32 {
    perlin(p.to_array(), sel)
}

/// Unfiltered float 3D Perlin noise (MaterialX `mx_perlin_noise_float(vec3)`).
pub fn perlin3(p: Vec3) -> f32 {
    perlin3_point(p, Sel::Full)
}

/// The integer lattice of `D`-dimensional noise (`D` = 2 or 3). [`Lattice`] holds what differs
/// between the dimensions (the corner hash, MaterialX's gradient functions and their scale), so
/// that the algorithms over the lattice ([`perlin`], the filtered corner sums, cell and Worley
/// noise) are written once; each monomorphises to straight-line code for its `D`.
pub(super) struct Dim<const D: usize>;

/// A `D`-dimensional integer lattice: its corner hash and Perlin gradients.
pub(super) trait Lattice<const D: usize> {
    /// Which lattice of corner gradients a Perlin evaluation reads (per output channel).
    type Sel: Copy;
    /// MaterialX's hash of lattice cell `c` (`mx_hash_int`).
    fn hash(c: [i32; D]) -> u32;
    /// The bits of corner hash `h` that choose the gradient of lattice `sel`.
    fn pick(sel: Self::Sel, h: u32) -> u32;
    /// MaterialX `mx_gradient_float(h, d)`: the gradient chosen by `h` dotted with `d`.
    fn gradient(h: u32, d: [f32; D]) -> f32;
    /// MaterialX `mx_gradient_scale2d` / `3d`, applied to the corner sum (f32).
    const GRADIENT_SCALE: f32;
    /// Corner `c`'s kernel coefficients on lattice `sel` (`h` its hash): `D` gradient components
    /// (each multiplying the offset along its own axis), then for 2D a constant (a `z = const`
    /// slice of the 3D lattice folds its z layers into it; 0 otherwise). Filtered corner sums
    /// read these.
    fn corner(sel: Self::Corners, c: [i32; D], h: u32) -> [f64; 3];
    /// A lattice selection prepared for [`Self::corner`] (what is the same for every corner).
    type Corners: Copy;
    /// [`Self::Corners`] of lattice `sel`.
    fn corners(sel: Self::Sel) -> Self::Corners;
    /// The gradient scale of lattice `sel`, for the filtered corner sums (f64).
    fn scale(sel: Self::Sel) -> f64;
    /// Cell noise of cell `c`: MaterialX `mx_cell_noise_float`, or channel `k` of
    /// `mx_cell_noise_vec3` when `vector`.
    fn cell(c: [i32; D], k: usize, vector: bool) -> f32;
    /// The footprint's cell masses along one axis (`N(m, s²)`): (cell, mass, d mass / d m) per
    /// cell, returning how many. The dimensions compute the masses with different rounding
    /// ([`cell_axis_shared`], [`cell_axis`]), each kept as it was.
    fn cell_axis(m: f64, s: f64, buf: &mut [(i32, f64, f64); 8]) -> usize;
}

impl Lattice<2> for Dim<2> {
    type Sel = HashSel;
    #[inline(always)]
    fn hash(c: [i32; 2]) -> u32 {
        hash::hash2(c[0], c[1])
    }
    #[inline(always)]
    fn pick(sel: HashSel, h: u32) -> u32 {
        sel.pick(h)
    }
    #[inline(always)]
    fn gradient(h: u32, d: [f32; 2]) -> f32 {
        gradient(h, d[0], d[1])
    }
    const GRADIENT_SCALE: f32 = GRADIENT_SCALE_2D;
    #[inline(always)]
    fn corner(sel: CornerSel, c: [i32; 2], h: u32) -> [f64; 3] {
        let (g, k) = sel.corner(c[0], c[1], h);
        [g.x, g.y, k]
    }
    type Corners = CornerSel;
    #[inline(always)]
    fn corners(sel: HashSel) -> CornerSel {
        sel.corners()
    }
    #[inline(always)]
    fn scale(sel: HashSel) -> f64 {
        sel.scale()
    }
    #[inline(always)]
    fn cell(c: [i32; 2], k: usize, vector: bool) -> f32 {
        if vector {
            hash::cell_vec3(c[0], c[1], k as i32)
        } else {
            hash::cell_float(c[0], c[1])
        }
    }
    #[inline(always)]
    fn cell_axis(m: f64, s: f64, buf: &mut [(i32, f64, f64); 8]) -> usize {
        cell_axis_shared(m, s, buf)
    }
}

impl Lattice<3> for Dim<3> {
    type Sel = Sel;
    #[inline(always)]
    fn hash(c: [i32; 3]) -> u32 {
        hash::hash3(c[0], c[1], c[2])
    }
    #[inline(always)]
    fn pick(sel: Sel, h: u32) -> u32 {
        sel.pick(h)
    }
    #[inline(always)]
    fn gradient(h: u32, d: [f32; 3]) -> f32 {
        gradient3(h, d[0], d[1], d[2])
    }
    const GRADIENT_SCALE: f32 = GRADIENT_SCALE_3D;
    #[inline(always)]
    fn corner(sel: Sel, _: [i32; 3], h: u32) -> [f64; 3] {
        gradient3_vector(sel.pick(h))
    }
    type Corners = Sel;
    #[inline(always)]
    fn corners(sel: Sel) -> Sel {
        sel
    }
    #[inline(always)]
    fn scale(_: Sel) -> f64 {
        GRADIENT_SCALE_3D as f64
    }
    #[inline(always)]
    fn cell(c: [i32; 3], k: usize, vector: bool) -> f32 {
        if vector {
            hash::cell3_vec3(c[0], c[1], c[2], k as i32)
        } else {
            hash::cell3_float(c[0], c[1], c[2])
        }
    }
    #[inline(always)]
    fn cell_axis(m: f64, s: f64, buf: &mut [(i32, f64, f64); 8]) -> usize {
        cell_axis(m, s, buf)
    }
}

/// MaterialX Perlin noise at `p` on lattice `sel` (f32, as GLSL computes it): the corners'
/// gradient dot products, interpolated by the fade of the fraction one axis after another
/// (x first), times the gradient scale.
#[inline(always)]
pub(super) fn perlin<const D: usize>(p: [f32; D], sel: <Dim<D> as Lattice<D>>::Sel) -> f32
where
    Dim<D>: Lattice<D>,
{
    let c0 = p.map(ifloor);
    // The fraction from f32's own floor: the same as `p − c0` wherever `c0` fits an i32, and 0
    // (a lattice point, where the noise is 0) beyond, where every f32 is a whole number.
    let f = p.map(|x| x - x.floor());
    // Corner `k` has offset bit `a` of `k` along axis `a`.
    let mut v = [0.0f32; 8];
    for (k, vk) in v.iter_mut().enumerate().take(1 << D) {
        let (mut c, mut d) = (c0, f);
        for a in 0..D {
            if k >> a & 1 == 1 {
                c[a] = c[a].wrapping_add(1);
                d[a] -= 1.0;
            }
        }
        *vk = Dim::<D>::gradient(Dim::<D>::pick(sel, Dim::<D>::hash(c)), d);
    }
    let mut n = 1 << D;
    for fa in f {
        let u = fade(fa);
        n /= 2;
        for i in 0..n {
            v[i] = v[2 * i] * (1.0 - u) + v[2 * i + 1] * u;
        }
    }
    Dim::<D>::GRADIENT_SCALE * v[0]
}
