//! Shapes (MaterialX 1.39 stdlib): `circle`, `line`, `hexagon`, `grid`, `crosshatch`,
//! `tiledcircles`, `tiledhexagons`.
//!
//! Every shape is an indicator (1 inside, 0 outside), so its filtered value is the probability
//! `P` that the footprint's Gaussian lands inside, `var = P (1 − P)`, and `grad = ∇P`.
//!
//! | node | inputs (default) | unfiltered (MaterialX `NG_*` graphs) | filtered evaluation |
//! |---|---|---|---|
//! | `circle` (float) | `texcoord` (UV0), `center` (0,0), `radius` (0.5) | 1 where `|t − center|² ≤ radius²` | disk coverage: Gauss–Legendre over the footprint's narrower axis of the closed-form Φ-mass of the disk's chord along the other |
//! | `line` (float) | `texcoord` (UV0), `center` (0,0), `radius` (0.1), `point1` (0.25,0.25), `point2` (0.75,0.75) | 1 where the distance from `t − center` to the segment `point1–point2` is ≤ `radius` (round caps) | capsule coverage, as `circle` (the capsule's chord is the hull of its disks' and rectangle's chords) |
//! | `hexagon` (float) | `texcoord` (UV0), `center` (0,0), `radius` (0.5) | 1 inside the regular hexagon of inradius `radius` with flat sides at `x = ±radius` (IQ's `sdHexagon` on `(|dy|, |dx|)`) | hexagon coverage, as `circle` (chords piecewise linear) |
//! | `grid` (color3) | `texcoord` (UV0), `uvtiling` (1,1), `uvoffset` (0,0), `thickness` (0.05), `staggered` (false) | 1 within `thickness/2` of an integer line of `t·tiling − offset` (odd rows shifted by ½ when staggered) | closed form, per axis: the Gaussian mass of the periodic bands (erf sums for σ < 0.4 cells, damped Fourier series above); `1 − (1 − P_x)(1 − P_y)` with row parity masses when staggered; exact for axis-aligned footprints |
//! | `crosshatch` (color3) | as `grid` | 1 within `thickness` of a cell diagonal of `2·fract(t·tiling − offset) − 1` | per cell, the two diagonal strips (minus their overlap) clipped to the cell, each as `circle`; from 0.1 cells of spread on both axes, the pattern's Fourier series (see below) |
//! | `tiledcircles` (color3) | `texcoord` (UV0), `uvtiling` (1,1), `uvoffset` (0,0), `size` (0.5), `staggered` (false) | disk of diameter `size` in each cell (clipped to it); staggered: rows of height √3/2 shifted by ½, disks of radius `size/2` at the triangle-lattice vertices | per cell, its disks clipped to the cell, as `circle`; from 0.1 cells (rows) of spread on both axes, the pattern's Fourier series |
//! | `tiledhexagons` (color3) | as `tiledcircles` | as `tiledcircles` with `hexagon`s (inradius `size/2`) | as `tiledcircles` |
//! | `cloverleaf` (float) | `texcoord` (UV0), `center` (0,0), `radius` (0.5) | the union of four disks of radius `radius/2` centred `radius/2` left, right, above and below `center` (MaterialX's `NG_cloverleaf_float`: the `max` of four `circle`s) | the union of the four disks, as `circle` with the disks' chords merged at each height |
//! | `tiledcloverleafs` (color3) | as `tiledcircles` | as `tiledcircles` with `cloverleaf`s of `radius` `size` in the cell's [−1, 1]² frame; staggered: rows of height ½ shifted by ½ every other row, cloverleafs of `radius` `size/2` at the lattice points | as `tiledcircles` |
//!
//! The coverage of a convex piece `K` under `N(m, diag(sₓ², s_y²))` (correlation ignored, like
//! the other pattern nodes; exact for axis-aligned footprints) is
//! `∫ φ(y; m_y, s_y) [Φ((hi(y) − mₓ)/sₓ) − Φ((lo(y) − mₓ)/sₓ)] dy` with `[lo(y), hi(y)]` the chord
//! of `K` at height `y`, integrated over the narrower axis (20-point Gauss–Legendre on the
//! piece's extent within ±6σ): the sharp direction is in closed form, the quadrature only sees
//! a Gaussian-smoothed chord length.
//!
//! The tiled patterns (`crosshatch`, `tiledcircles`, `tiledhexagons`, `tiledcloverleafs`) visit
//! the cells within ±6σ while the footprint is under 0.1 cells (rows) on either axis. From 0.1
//! on both, they are the exact Gaussian convolution of their Fourier series over one period (1
//! cell by 2 rows; |k| ≤ 12 per axis, from 256 × 256 point samples made once per pattern and
//! thread), correlation of the footprint's axes included: every mode is damped by
//! `e^{−2π² kᵀΣk}`, so at 0.1 cells the modes left out weigh below 1e-5 and at wide footprints
//! only the mean (the coverage) remains. A footprint wide (over 0.6 cells) along one axis only
//! and narrow along the other (a grazing view) takes the pattern's average along the wide axis,
//! a 256-bin profile filtered along the narrow one. Unions are sums of disjoint pieces (inclusion–exclusion
//! for the crosshatch's overlapping strips), or, for the cloverleafs' overlapping disks, the
//! merged chords of all pieces at each height.

use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::gaussian::{cdf, pdf};
use crate::graph::Source;
use crate::value::{Filtered, Moments, ValueType};
use glam::{DVec2, Vec2};
use std::sync::OnceLock;

pub(crate) const CATEGORIES: &[&str] = &[
    "circle",
    "line",
    "hexagon",
    "grid",
    "crosshatch",
    "tiledcircles",
    "tiledhexagons",
    "cloverleaf",
    "tiledcloverleafs",
];

/// Shape operations.
#[derive(Debug)]
pub enum ShapeOp {
    /// `circle`
    Circle,
    /// `line`
    Line,
    /// `hexagon`
    Hexagon,
    /// `grid`
    Grid,
    /// `crosshatch`
    Crosshatch,
    /// `tiledcircles`
    TiledCircles,
    /// `tiledhexagons`
    TiledHexagons,
    /// `cloverleaf`
    Cloverleaf,
    /// `tiledcloverleafs`
    TiledCloverleafs,
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let (inputs, types): (&'static [_], fn(ValueType) -> bool) = match category {
        "circle" | "hexagon" | "cloverleaf" => {
            (&[inp!("texcoord", V2, Uv), inp!("center", V2, Zero), inp!("radius", Float, Half)], types::float)
        }
        "line" => (
            &[
                inp!("texcoord", V2, Uv),
                inp!("center", V2, Zero),
                inp!("radius", Float, Splat(0.1)),
                inp!("point1", V2, Pair(0.25, 0.25)),
                inp!("point2", V2, Pair(0.75, 0.75)),
            ],
            types::float,
        ),
        "grid" | "crosshatch" => (
            &[
                inp!("texcoord", V2, Uv),
                inp!("uvtiling", V2, Pair(1.0, 1.0)),
                inp!("uvoffset", V2, Zero),
                inp!("thickness", Float, Splat(0.05)),
                inp!("staggered", Bool, Zero),
            ],
            types::color3,
        ),
        "tiledcircles" | "tiledhexagons" | "tiledcloverleafs" => (
            &[
                inp!("texcoord", V2, Uv),
                inp!("uvtiling", V2, Pair(1.0, 1.0)),
                inp!("uvoffset", V2, Zero),
                inp!("size", Float, Half),
                inp!("staggered", Bool, Zero),
            ],
            types::color3,
        ),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types, build })
}

fn build(category: &str, _: ValueType, _: &[ValueType], _: &[Source], _: &[Param]) -> Result<Op, String> {
    Ok(Op::Shape(match category {
        "circle" => ShapeOp::Circle,
        "line" => ShapeOp::Line,
        "hexagon" => ShapeOp::Hexagon,
        "grid" => ShapeOp::Grid,
        "crosshatch" => ShapeOp::Crosshatch,
        "tiledcircles" => ShapeOp::TiledCircles,
        "cloverleaf" => ShapeOp::Cloverleaf,
        "tiledcloverleafs" => ShapeOp::TiledCloverleafs,
        _ => ShapeOp::TiledHexagons,
    }))
}

// ---------------------------------------------------------------------------------------------
// Unfiltered shapes, as MaterialX's node graphs compute them (f32).

fn v2(f: &Filtered) -> Vec2 {
    Vec2::new(f.ch[0].mean, f.ch[1].mean)
}

/// MaterialX `modulo` (`x − y·floor(x/y)`).
#[inline]
fn fmod(x: f32, y: f32) -> f32 {
    x - y * (x / y).floor()
}

fn circle_point(t: Vec2, c: Vec2, r: f32) -> f32 {
    let d = t - c;
    if d.dot(d) > r * r {
        0.0
    } else {
        1.0
    }
}

fn line_point(t: Vec2, c: Vec2, r: f32, p1: Vec2, p2: Vec2) -> f32 {
    let pa = t - c - p1;
    let ba = p2 - p1;
    // Two equal end points make the segment a point (h = 0), not a NaN (division by zero is 0).
    let bb = ba.dot(ba);
    let h = if bb == 0.0 { 0.0 } else { (pa.dot(ba) / bb).clamp(0.0, 1.0) };
    if pa.distance(ba * h) > r {
        0.0
    } else {
        1.0
    }
}

/// MaterialX's `NG_cloverleaf_float`: the `max` of four `circle`s of radius `r` around `2c`,
/// read at `2t` moved by `r` along each axis.
fn clover_point(t: Vec2, c: Vec2, r: f32) -> f32 {
    let (t2, c2) = (t + t, c + c);
    let leaves =
        [Vec2::new(t2.x + r, t2.y), Vec2::new(t2.x - r, t2.y), Vec2::new(t2.x, t2.y - r), Vec2::new(t2.x, t2.y + r)];
    leaves.iter().map(|&q| circle_point(q, c2, r)).fold(0.0, f32::max)
}

fn hexagon_point(t: Vec2, c: Vec2, r: f32) -> f32 {
    let k = Vec2::new(-0.866025, 0.5);
    let kz = 0.57735f32;
    let d = (t - c).abs();
    let p = Vec2::new(d.y, d.x);
    let p1 = p - 2.0 * k * k.dot(p).min(0.0);
    let mk = Vec2::new(-k.x, k.y);
    let p2 = p1 - 2.0 * mk * mk.dot(p1).min(0.0);
    // GLSL's clamp, min(max(x, lo), hi): total when lo > hi (a negative radius).
    let p3 = p2 - Vec2::new(p2.x.max(-kz * r).min(kz * r), r);
    // ifgreater(sqrt(p3.x + p3.y), 0): NaN (a negative sum) compares false.
    if (p3.x + p3.y).sqrt() > 0.0 {
        0.0
    } else {
        1.0
    }
}

fn cell(t: Vec2, tiling: Vec2, offset: Vec2) -> Vec2 {
    t * tiling - offset
}

fn grid_point(q: Vec2, th: f32, staggered: bool) -> f32 {
    let size = 1.0 - th;
    let shift = if fmod(q.y, 2.0) > 1.0 { 0.5 } else { 0.0 };
    let x = if staggered { q.x + shift } else { q.x };
    let ax = (fmod(x, 1.0) * 2.0 - 1.0).abs();
    let ay = (fmod(q.y, 1.0) * 2.0 - 1.0).abs();
    let xd = if ax > size { 0.0 } else { 1.0 };
    let yd = if ay > size { 0.0 } else { 1.0 };
    1.0 - f32::min(xd, yd)
}

fn crosshatch_point(q: Vec2, th: f32, staggered: bool) -> f32 {
    let shift = if fmod(q.y, 2.0) > 1.0 { 0.5 } else { 0.0 };
    let x = if staggered { q.x + shift } else { q.x };
    let s = Vec2::new(fmod(x, 1.0) * 2.0 - 1.0, fmod(q.y, 1.0) * 2.0 - 1.0);
    let a = line_point(s, Vec2::ZERO, th, Vec2::new(1.0, 1.0), Vec2::new(-1.0, -1.0));
    let b = line_point(s, Vec2::ZERO, th, Vec2::new(-1.0, 1.0), Vec2::new(1.0, -1.0));
    a.max(b)
}

const ROW: f32 = 0.866025;

/// The shape a tiled pattern repeats.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Motif {
    Circle,
    Hexagon,
    Clover,
}

impl Motif {
    fn point(self, t: Vec2, r: f32) -> f32 {
        match self {
            Motif::Circle => circle_point(t, Vec2::ZERO, r),
            Motif::Hexagon => hexagon_point(t, Vec2::ZERO, r),
            Motif::Clover => clover_point(t, Vec2::ZERO, r),
        }
    }

    /// The height of a staggered row: the triangle lattice's √3/2 for circles and hexagons, ½
    /// for cloverleafs (as MaterialX's graphs have them).
    fn row(self) -> f32 {
        if self == Motif::Clover {
            0.5
        } else {
            ROW
        }
    }
}

fn tiled_point(q: Vec2, size: f32, staggered: bool, motif: Motif) -> f32 {
    if !staggered {
        let rc = Vec2::new(fmod(q.x, 1.0), fmod(q.y, 1.0)) * 2.0 - 1.0;
        return motif.point(rc, size);
    }
    // Odd rows (of two per period) are shifted by half a cell.
    let row = motif.row();
    let dx = if fmod(q.y, 2.0 * row) > row { 0.5 } else { 0.0 };
    let mx = fmod(q.x + dx, 1.0);
    let my = fmod(q.y, row);
    let h = size / 2.0;
    let a = motif.point(Vec2::new(mx, my), h);
    let b = motif.point(Vec2::new(1.0 - mx, my), h);
    let c = motif.point(Vec2::new(mx - 0.5, row - my), h);
    a.max(b).max(c)
}

// ---------------------------------------------------------------------------------------------
// Convex pieces and their Gaussian coverage.

const SQRT3: f64 = 1.732_050_807_568_877_2;

/// A convex primitive.
#[derive(Clone, Copy, Debug)]
enum Prim {
    Disk {
        c: DVec2,
        r: f64,
    },
    /// Regular hexagon of inradius `r`, flat sides at `x = c.x ± r`.
    Hex {
        c: DVec2,
        r: f64,
    },
    /// Points within `r` of the segment `a–b`.
    Capsule {
        a: DVec2,
        b: DVec2,
        r: f64,
    },
    Rect {
        lo: DVec2,
        hi: DVec2,
    },
    /// `|n · p − c| < w`.
    Strip {
        n: DVec2,
        c: f64,
        w: f64,
    },
}

const EMPTY: (f64, f64) = (f64::INFINITY, f64::NEG_INFINITY);

#[inline]
fn get(p: DVec2, k: usize) -> f64 {
    if k == 0 {
        p.x
    } else {
        p.y
    }
}

impl Prim {
    /// The chord at coordinate `k = t` along the other axis.
    fn chord(&self, k: usize, t: f64) -> (f64, f64) {
        let o = 1 - k;
        match *self {
            Prim::Disk { c, r } => {
                let d = t - get(c, k);
                if d.abs() >= r {
                    return EMPTY;
                }
                let h = (r * r - d * d).sqrt();
                (get(c, o) - h, get(c, o) + h)
            }
            Prim::Hex { c, r } => {
                let big = 2.0 * r / SQRT3;
                let d = (t - get(c, k)).abs();
                let h = if k == 0 {
                    if d >= r {
                        return EMPTY;
                    }
                    big - d / SQRT3
                } else {
                    if d >= big {
                        return EMPTY;
                    }
                    if d <= big / 2.0 {
                        r
                    } else {
                        (big - d) * SQRT3
                    }
                };
                (get(c, o) - h, get(c, o) + h)
            }
            Prim::Capsule { a, b, r } => {
                let ab = b - a;
                let len = ab.length();
                let mut lo = f64::INFINITY;
                let mut hi = f64::NEG_INFINITY;
                let mut add = |(l, h): (f64, f64)| {
                    if l < h {
                        lo = lo.min(l);
                        hi = hi.max(h);
                    }
                };
                add(Prim::Disk { c: a, r }.chord(k, t));
                add(Prim::Disk { c: b, r }.chord(k, t));
                if len > 0.0 {
                    let dir = ab / len;
                    let perp = DVec2::new(-dir.y, dir.x);
                    let s1 = Prim::Strip { n: perp, c: perp.dot(a), w: r }.chord(k, t);
                    let s2 = Prim::Strip { n: dir, c: dir.dot((a + b) * 0.5), w: len * 0.5 }.chord(k, t);
                    add((s1.0.max(s2.0), s1.1.min(s2.1)));
                }
                (lo, hi)
            }
            Prim::Rect { lo, hi } => {
                if t < get(lo, k) || t >= get(hi, k) {
                    return EMPTY;
                }
                (get(lo, o), get(hi, o))
            }
            Prim::Strip { n, c, w } => {
                let (nk, no) = (get(n, k), get(n, o));
                if no.abs() < 1e-12 {
                    return if (nk * t - c).abs() < w { (f64::NEG_INFINITY, f64::INFINITY) } else { EMPTY };
                }
                let a = (c - w - nk * t) / no;
                let b = (c + w - nk * t) / no;
                (a.min(b), a.max(b))
            }
        }
    }

    /// Extent along axis `k`.
    fn extent(&self, k: usize) -> (f64, f64) {
        match *self {
            Prim::Disk { c, r } => (get(c, k) - r, get(c, k) + r),
            Prim::Hex { c, r } => {
                let e = if k == 0 { r } else { 2.0 * r / SQRT3 };
                (get(c, k) - e, get(c, k) + e)
            }
            Prim::Capsule { a, b, r } => (get(a, k).min(get(b, k)) - r, get(a, k).max(get(b, k)) + r),
            Prim::Rect { lo, hi } => (get(lo, k), get(hi, k)),
            Prim::Strip { .. } => (f64::NEG_INFINITY, f64::INFINITY),
        }
    }
}

/// A convex piece: the intersection of up to three primitives, counted with a sign.
#[derive(Clone, Copy, Debug)]
struct Piece {
    prims: [Option<Prim>; 3],
    sign: f64,
}

impl Piece {
    fn one(p: Prim) -> Piece {
        Piece { prims: [Some(p), None, None], sign: 1.0 }
    }
    fn clipped(p: Prim, r: Prim) -> Piece {
        Piece { prims: [Some(p), Some(r), None], sign: 1.0 }
    }
    /// The cloverleaf around `c` of leaves of radius `r` (≥ 0) centred `r` from `c` along
    /// each axis, clipped to `clip`: its four disks, which overlap, for [`union_coverage`].
    fn clover(c: DVec2, r: f64, clip: Option<Prim>, out: &mut Vec<Piece>) {
        for d in [DVec2::X, DVec2::Y, -DVec2::X, -DVec2::Y] {
            out.push(Piece { prims: [Some(Prim::Disk { c: c + d * r, r }), clip, None], sign: 1.0 });
        }
    }
    fn chord(&self, k: usize, t: f64) -> (f64, f64) {
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for p in self.prims.iter().flatten() {
            let (a, b) = p.chord(k, t);
            lo = lo.max(a);
            hi = hi.min(b);
        }
        (lo, hi)
    }
    fn extent(&self, k: usize) -> (f64, f64) {
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for p in self.prims.iter().flatten() {
            let (a, b) = p.extent(k);
            lo = lo.max(a);
            hi = hi.min(b);
        }
        (lo, hi)
    }
}

const GL_N: usize = 20;
/// The shorter rule [`union_coverage`] uses on each of several spans.
const GL_SHORT: usize = 8;

/// Gauss–Legendre nodes and weights on [−1, 1].
fn gauss_legendre() -> &'static [(f64, f64); GL_N] {
    static R: OnceLock<[(f64, f64); GL_N]> = OnceLock::new();
    R.get_or_init(legendre_rule)
}

/// The 8-point Gauss–Legendre rule on [−1, 1].
fn gauss_legendre_short() -> &'static [(f64, f64); GL_SHORT] {
    static R: OnceLock<[(f64, f64); GL_SHORT]> = OnceLock::new();
    R.get_or_init(legendre_rule)
}

/// The `N`-point Gauss–Legendre nodes and weights, by Newton's method on the Legendre
/// polynomial.
fn legendre_rule<const N: usize>() -> [(f64, f64); N] {
    let n = N;
    let mut out = [(0.0, 0.0); N];
    for i in 0..n {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        out[i] = (x, 2.0 / ((1.0 - x * x) * dp * dp));
    }
    out
}

/// Φ-mass of `(lo, hi)` under `N(m, s²)` and its derivative in `m`.
#[inline]
fn interval(lo: f64, hi: f64, m: f64, s: f64) -> (f64, f64) {
    if lo >= hi {
        return (0.0, 0.0);
    }
    let (a, b) = ((lo - m) / s, (hi - m) / s);
    let p = if a > 0.0 { cdf(-a) - cdf(-b) } else { cdf(b) - cdf(a) };
    (p.max(0.0), (pdf(a) - pdf(b)) / s)
}

/// Coverage of the signed pieces under `N(m, diag(s²))`: `(P, ∂P/∂m)`.
fn coverage(pieces: &[Piece], m: DVec2, s: DVec2) -> (f64, DVec2) {
    // Integrate over the narrower axis k; closed form along the other.
    let k = if s.x <= s.y { 0 } else { 1 };
    let o = 1 - k;
    let (mk, sk) = (get(m, k), get(s, k));
    let (mo, so) = (get(m, o), get(s, o).max(1e-12));
    let mut p = 0.0;
    let mut g = [0.0f64; 2];
    for pc in pieces {
        if sk <= 0.0 {
            let (q, dq) = interval(pc.chord(k, mk).0, pc.chord(k, mk).1, mo, so);
            p += pc.sign * q;
            g[o] += pc.sign * dq;
            continue;
        }
        let (e0, e1) = pc.extent(k);
        let (a, b) = (e0.max(mk - 6.0 * sk), e1.min(mk + 6.0 * sk));
        if a >= b {
            continue;
        }
        let (half, mid) = ((b - a) * 0.5, (b + a) * 0.5);
        for &(x, w) in gauss_legendre() {
            let t = mid + half * x;
            let z = (t - mk) / sk;
            let wt = w * half * pdf(z) / sk;
            let (lo, hi) = pc.chord(k, t);
            let (q, dq) = interval(lo, hi, mo, so);
            p += pc.sign * wt * q;
            g[o] += pc.sign * wt * dq;
            g[k] += pc.sign * wt * q * z / sk;
        }
    }
    (p.clamp(0.0, 1.0), DVec2::new(g[0], g[1]))
}

/// The most pieces [`union_coverage`] takes (three clipped cloverleafs).
const MAX_UNION: usize = 12;

/// Coverage of the union of (possibly overlapping) pieces under `N(m, diag(s²))`, as
/// [`coverage`] but with the chords of all pieces at each height merged into disjoint
/// intervals first: a union with no inclusion–exclusion terms to find. The narrower axis is
/// integrated piecewise between the pieces' extents (Gauss–Legendre on each span: 20 points
/// for up to two spans, 8 for more), only the pieces whose box meets the footprint's taken,
/// so that each span sees chords that begin and end only at its ends.
fn union_coverage(pieces: &[Piece], m: DVec2, s: DVec2) -> (f64, DVec2) {
    debug_assert!(pieces.len() <= MAX_UNION && pieces.iter().all(|p| p.sign == 1.0));
    let k = if s.x <= s.y { 0 } else { 1 };
    let o = 1 - k;
    let (mk, sk) = (get(m, k), get(s, k));
    let (mo, so) = (get(m, o), get(s, o).max(1e-12));
    // Only the pieces whose box meets the footprint's (±7σ) count.
    let mut near = [pieces[0]; MAX_UNION];
    let mut n = 0;
    for pc in pieces.iter().take(MAX_UNION) {
        let meets = |axis: usize, c: f64, r: f64| {
            let (a, b) = pc.extent(axis);
            a < c + 7.0 * r && b > c - 7.0 * r
        };
        if meets(k, mk, sk) && meets(o, mo, so) {
            near[n] = *pc;
            n += 1;
        }
    }
    if n == 0 {
        return (0.0, DVec2::ZERO);
    }
    let pieces = &near[..n];
    // The mass of the union of the chords at height t, and its derivative in the centre.
    let at = |t: f64| -> (f64, f64) {
        let mut ch = [(0.0f64, 0.0f64); MAX_UNION];
        let mut n = 0;
        for pc in pieces {
            let (lo, hi) = pc.chord(k, t);
            if lo < hi {
                ch[n] = (lo, hi);
                n += 1;
            }
        }
        let ch = &mut ch[..n];
        ch.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let (mut q, mut dq) = (0.0, 0.0);
        // A merged interval's mass (none beyond 9σ, where it is below 1e-19).
        let mut add = |(a, b): (f64, f64)| {
            if b > mo - 9.0 * so && a < mo + 9.0 * so {
                let (p, d) = interval(a, b, mo, so);
                q += p;
                dq += d;
            }
        };
        let mut cur: Option<(f64, f64)> = None;
        for &(lo, hi) in ch.iter() {
            match cur {
                Some((a, b)) if lo <= b => cur = Some((a, b.max(hi))),
                _ => {
                    cur.map(&mut add);
                    cur = Some((lo, hi));
                }
            }
        }
        cur.map(&mut add);
        (q, dq)
    };
    let mut g = [0.0f64; 2];
    if sk <= 0.0 {
        let (q, dq) = at(mk);
        g[o] = dq;
        return (q.clamp(0.0, 1.0), DVec2::new(g[0], g[1]));
    }
    // Breakpoints: the pieces' extents within ±6σ.
    let (lo, hi) = (mk - 6.0 * sk, mk + 6.0 * sk);
    let mut cuts = [0.0f64; 2 * MAX_UNION + 2];
    let mut n = 0;
    for pc in pieces {
        let (e0, e1) = pc.extent(k);
        for e in [e0, e1] {
            cuts[n] = e.clamp(lo, hi);
            n += 1;
        }
    }
    let cuts = &mut cuts[..n];
    cuts.sort_unstable_by(f64::total_cmp);
    let spans = cuts.windows(2).filter(|w| w[1] > w[0]).count();
    // One span takes the long rule; several share the work, the short rule on each.
    let rule: &[(f64, f64)] = if spans <= 2 { gauss_legendre() } else { gauss_legendre_short() };
    let mut p = 0.0;
    for w in cuts.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b - a <= 0.0 {
            continue;
        }
        let (half, mid) = ((b - a) * 0.5, (b + a) * 0.5);
        for &(x, wt) in rule {
            let t = mid + half * x;
            let z = (t - mk) / sk;
            let wt = wt * half * pdf(z) / sk;
            let (q, dq) = at(t);
            p += wt * q;
            g[o] += wt * dq;
            g[k] += wt * q * z / sk;
        }
    }
    (p.clamp(0.0, 1.0), DVec2::new(g[0], g[1]))
}

/// The footprint of a coordinate: mean, per-axis spread, Jacobian rows.
fn coord(t: &Filtered, scale: DVec2, offset: DVec2) -> (DVec2, DVec2, [Vec2; 2]) {
    let m = DVec2::new(t.ch[0].mean as f64, t.ch[1].mean as f64) * scale - offset;
    let s = DVec2::new(t.ch[0].sigma() as f64, t.ch[1].sigma() as f64) * scale.abs();
    (m, s, [crate::moments::scale_grad(t.ch[0].grad, scale.x), crate::moments::scale_grad(t.ch[1].grad, scale.y)])
}

fn indicator(p: f64, dp: DVec2, j: &[Vec2; 2]) -> Moments {
    use crate::moments::{add_grad, scale_grad};
    let grad = add_grad(scale_grad(j[0], dp.x), scale_grad(j[1], dp.y));
    Moments { mean: p as f32, grad, var: (p * (1.0 - p)).max(0.0) as f32 }
}

// ---------------------------------------------------------------------------------------------
// Grid: closed form.

/// Mass of `N(m, s²)` on `∪ₖ [k + a, k + b)` (`0 ≤ b − a ≤ 1`) and its `m`-derivative.
fn periodic_mass(a: f64, b: f64, m: f64, s: f64) -> (f64, f64) {
    let w = b - a;
    if w <= 0.0 {
        return (0.0, 0.0);
    }
    if w >= 1.0 {
        return (1.0, 0.0);
    }
    if s <= 0.0 {
        let f = (m - a) - (m - a).floor();
        return (if f < w { 1.0 } else { 0.0 }, 0.0);
    }
    if s < 0.4 {
        let k0 = (m - 7.0 * s - b).floor();
        let k1 = (m + 7.0 * s - a).ceil();
        let (mut p, mut d) = (0.0, 0.0);
        for k in crate::gaussian::cells(k0, k1) {
            let (q, dq) = interval(k + a, k + b, m, s);
            p += q;
            d += dq;
        }
        (p, d)
    } else {
        use std::f64::consts::PI;
        let (mut p, mut d) = (w, 0.0);
        for n in 1..=8 {
            let nf = n as f64;
            let att = (-2.0 * PI * PI * nf * nf * s * s).exp();
            if att < 1e-14 {
                break;
            }
            let (ta, tb) = (2.0 * PI * nf * (m - a), 2.0 * PI * nf * (m - b));
            p += att * (ta.sin() - tb.sin()) / (PI * nf);
            d += att * 2.0 * (ta.cos() - tb.cos());
        }
        (p, d)
    }
}

fn grid(ins: &[Filtered]) -> Moments {
    let (tile, off) = (v2(&ins[1]).as_dvec2(), v2(&ins[2]).as_dvec2());
    // Beyond [0, 1] the point function is the same as at the nearer end (no lines below 0, all
    // lines above 1): clamped so that the two row classes of the staggered grid cannot overlap.
    let th = (ins[3].ch[0].mean as f64).clamp(0.0, 1.0);
    let staggered = ins[4].ch[0].mean > 0.5;
    let (m, s, j) = coord(&ins[0], tile, off);
    // Off a line along an axis: fract ∈ [th/2, 1 − th/2].
    let (a, b) = (th / 2.0, 1.0 - th / 2.0);
    let (qy, dqy) = periodic_mass(a, b, m.y, s.y);
    if !staggered {
        let (qx, dqx) = periodic_mass(a, b, m.x, s.x);
        let p = 1.0 - qx * qy;
        return indicator(p, DVec2::new(-dqx * qy, -qx * dqy), &j);
    }
    // Rows: y mod 2 ∈ [a, b) → shift 0; y mod 2 ∈ [1 + a, 1 + b) → shift ½ (period 2).
    let (r0, dr0) = periodic_mass(a / 2.0, b / 2.0, m.y / 2.0, s.y / 2.0);
    let (r1, dr1) = periodic_mass((1.0 + a) / 2.0, (1.0 + b) / 2.0, m.y / 2.0, s.y / 2.0);
    let (q0, dq0) = periodic_mass(a, b, m.x, s.x);
    let (q1, dq1) = periodic_mass(a, b, m.x + 0.5, s.x);
    let p = 1.0 - (r0 * q0 + r1 * q1);
    indicator(p, DVec2::new(-(r0 * dq0 + r1 * dq1), -(dr0 * q0 + dr1 * q1) / 2.0), &j)
}

// ---------------------------------------------------------------------------------------------
// Tiled patterns.

/// Per-axis spread (cells) beyond which a tiled pattern is its average along that axis.
const TILE_SIGMA_GLOBAL: f64 = 0.6;
/// Most cells visited per axis.
const MAX_CELLS: i64 = 48;

#[derive(Clone, Copy)]
enum Tiled {
    Cross { th: f64, staggered: bool },
    Shapes { size: f64, staggered: bool, motif: Motif },
}

impl Tiled {
    fn row_height(&self) -> f64 {
        match *self {
            Tiled::Shapes { staggered: true, motif, .. } => motif.row() as f64,
            _ => 1.0,
        }
    }

    fn point(&self, q: Vec2) -> f32 {
        match *self {
            Tiled::Cross { th, staggered } => crosshatch_point(q, th as f32, staggered),
            Tiled::Shapes { size, staggered, motif } => tiled_point(q, size as f32, staggered, motif),
        }
    }

    /// The pieces of cell (i, j).
    fn pieces(&self, i: i64, j: i64, out: &mut Vec<Piece>) {
        let (fi, fj) = (i as f64, j as f64);
        match *self {
            Tiled::Cross { th, staggered } => {
                let sh = if staggered && j.rem_euclid(2) == 1 { 0.5 } else { 0.0 };
                let x0 = fi - sh;
                let rect = Prim::Rect { lo: DVec2::new(x0, fj), hi: DVec2::new(x0 + 1.0, fj + 1.0) };
                let w = th / std::f64::consts::SQRT_2;
                // |sx ∓ sy| < th√2 with s = 2 (q − cell corner) − 1.
                let d1 = Prim::Strip { n: DVec2::new(1.0, -1.0), c: x0 - fj, w };
                let d2 = Prim::Strip { n: DVec2::new(1.0, 1.0), c: x0 + fj + 1.0, w };
                out.push(Piece::clipped(d1, rect));
                out.push(Piece::clipped(d2, rect));
                out.push(Piece { prims: [Some(d1), Some(d2), Some(rect)], sign: -1.0 });
            }
            Tiled::Shapes { size, staggered, motif } => {
                // `r` is the motif's radius where the cell is its own frame (a cloverleaf's
                // leaves have half of it).
                let mut shape = |c: DVec2, r: f64, rect: Prim| match motif {
                    Motif::Hexagon => out.push(Piece::clipped(Prim::Hex { c, r }, rect)),
                    Motif::Circle => out.push(Piece::clipped(Prim::Disk { c, r: r.abs() }, rect)),
                    Motif::Clover => Piece::clover(c, r.abs() / 2.0, Some(rect), out),
                };
                if !staggered {
                    let rect = Prim::Rect { lo: DVec2::new(fi, fj), hi: DVec2::new(fi + 1.0, fj + 1.0) };
                    shape(DVec2::new(fi + 0.5, fj + 0.5), size / 2.0, rect);
                    return;
                }
                let h = motif.row() as f64;
                let sh = if j.rem_euclid(2) == 1 { 0.5 } else { 0.0 };
                let x0 = fi - sh;
                let (y0, y1) = (fj * h, (fj + 1.0) * h);
                let rect = Prim::Rect { lo: DVec2::new(x0, y0), hi: DVec2::new(x0 + 1.0, y1) };
                for c in [DVec2::new(x0, y0), DVec2::new(x0 + 1.0, y0), DVec2::new(x0 + 0.5, y1)] {
                    shape(c, size / 2.0, rect);
                }
            }
        }
    }

    /// Whether a cell's pieces overlap (cloverleafs: their leaves, and staggered ones each
    /// other), so that the cell's coverage is that of their union.
    fn overlaps(&self) -> bool {
        matches!(self, Tiled::Shapes { motif: Motif::Clover, .. })
    }

    /// What identifies the pattern for the memos of its [`Series`] and profiles.
    fn key(&self) -> (u8, u64) {
        match *self {
            Tiled::Cross { th, staggered } => (staggered as u8, th.to_bits()),
            Tiled::Shapes { size, staggered, motif } => (2 + staggered as u8 + 2 * motif as u8, size.to_bits()),
        }
    }
}

/// Fourier modes a [`Series`] keeps per axis (`|k| ≤ FOURIER_K`).
const FOURIER_K: usize = 12;
const FK: usize = 2 * FOURIER_K + 1;
/// Spread (in cells along x, in rows along y) from which a tiled pattern is filtered by its
/// Fourier series: the modes it drops are then damped below 1e-5 of the fundamental.
const TILE_SIGMA_FOURIER: f64 = 0.1;

/// A tiled pattern's Fourier series over its period (1 cell along x, two rows along y):
/// `c[ky][kx]` for `kx, ky ∈ [−K, K]`, from 256 × 256 point samples.
struct Series {
    c: Box<[[(f64, f64); FK]; FK]>,
    period: DVec2,
}

impl Series {
    /// The Gaussian average at `N(m, Σ)`: `Re Σ_k c_k e^{2πi k·m/P} e^{−2π² (k/P)ᵀ Σ (k/P)}`
    /// (exact for the sampled pattern, correlation included), and its gradient in `m`.
    fn average(&self, m: DVec2, cov: [f64; 3]) -> (f64, DVec2) {
        use std::f64::consts::PI;
        let (px, py) = (self.period.x, self.period.y);
        let a = 2.0 * PI * PI * cov[0] / (px * px);
        let b = 2.0 * PI * PI * cov[2] / (py * py);
        let c = 4.0 * PI * PI * cov[1] / (px * py);
        let k = FOURIER_K as i64;
        // Powers of the unit phase e^{2πi t} for k = −K…K.
        let powers = |t: f64, out: &mut [(f64, f64); FK]| {
            let (sn, cs) = (2.0 * PI * t).sin_cos();
            out[FOURIER_K] = (1.0, 0.0);
            for j in 1..=FOURIER_K {
                let (re, im) = out[FOURIER_K + j - 1];
                out[FOURIER_K + j] = (re * cs - im * sn, re * sn + im * cs);
                out[FOURIER_K - j] = (out[FOURIER_K + j].0, -out[FOURIER_K + j].1);
            }
        };
        let (mut ux, mut uy) = ([(0.0, 0.0); FK], [(0.0, 0.0); FK]);
        powers(m.x.rem_euclid(px) / px, &mut ux);
        powers(m.y.rem_euclid(py) / py, &mut uy);
        let (mut p, mut gx, mut gy) = (0.0, 0.0, 0.0);
        for ky in -k..=k {
            let dy = (-b * (ky * ky) as f64).exp();
            if dy < 1e-12 {
                continue;
            }
            let (yr, yi) = uy[(ky + k) as usize];
            for kx in -k..=k {
                // One exponent: the quadratic form is ≥ 0, its cross term alone is not.
                let (fx, fy) = (kx as f64, ky as f64);
                let d = (-(a * fx * fx + b * fy * fy + c * fx * fy)).exp();
                if d < 1e-12 {
                    continue;
                }
                let (xr, xi) = ux[(kx + k) as usize];
                let (er, ei) = (xr * yr - xi * yi, xr * yi + xi * yr);
                let (cr, ci) = self.c[(ky + k) as usize][(kx + k) as usize];
                // Re(c e), and Re(c e · 2πi k/P) = −2π k/P · Im(c e).
                let (re, im) = (cr * er - ci * ei, cr * ei + ci * er);
                p += d * re;
                gx -= d * im * 2.0 * PI * kx as f64 / px;
                gy -= d * im * 2.0 * PI * ky as f64 / py;
            }
        }
        (p, DVec2::new(gx, gy))
    }
}

/// A per-thread memo of what a few patterns take long to make: the last few entries, oldest
/// first.
type Memo<K, V> = std::cell::RefCell<Vec<(K, V)>>;

/// Hands `f` the value remembered for `key` in `memo`, made by `make` (and remembered, the
/// oldest of four entries giving way) when absent.
fn remembered<K: PartialEq, V, R>(memo: &Memo<K, V>, key: K, make: impl FnOnce() -> V, f: impl FnOnce(&V) -> R) -> R {
    let mut memo = memo.borrow_mut();
    if let Some(k) = memo.iter().position(|(p, _)| *p == key) {
        return f(&memo[k].1);
    }
    let v = make();
    let r = f(&v);
    if memo.len() == 4 {
        memo.remove(0);
    }
    memo.push((key, v));
    r
}

/// Bins of a [`Tiled::profile`] over its period.
const PROFILE_BINS: usize = 256;

/// A [`Tiled::profile`]'s bins.
type Profile = Box<[f32; PROFILE_BINS]>;

impl Tiled {
    /// The pattern's [`Series`], handed to `f`; remembered per thread for the last few patterns.
    fn series<R>(&self, f: impl FnOnce(&Series) -> R) -> R {
        thread_local! {
            static MEMO: Memo<(u8, u64), Series> = const { std::cell::RefCell::new(Vec::new()) };
        }
        MEMO.with(|memo| remembered(memo, self.key(), || self.make_series(), f))
    }

    fn make_series(&self) -> Series {
        use std::f64::consts::TAU;
        const N: usize = 256;
        let period = DVec2::new(1.0, 2.0 * self.row_height());
        // e^{−2πi k (j + ½)/N} for k = 0…K, per sample j.
        let mut trig = vec![[(0.0f64, 0.0f64); FOURIER_K + 1]; N];
        for (j, row) in trig.iter_mut().enumerate() {
            for (k, t) in row.iter_mut().enumerate() {
                let (sn, cs) = (-TAU * k as f64 * (j as f64 + 0.5) / N as f64).sin_cos();
                *t = (cs, sn);
            }
        }
        let at = |k: i64, j: usize| {
            let (re, im) = trig[j][k.unsigned_abs() as usize];
            (re, if k < 0 { -im } else { im })
        };
        let kk = FOURIER_K as i64;
        // Along x first, per row of samples; then along y.
        let mut rows = vec![[(0.0f64, 0.0f64); FK]; N];
        for (b, row) in rows.iter_mut().enumerate() {
            let y = (b as f64 + 0.5) / N as f64 * period.y;
            for a in 0..N {
                let x = (a as f64 + 0.5) / N as f64 * period.x;
                let v = self.point(Vec2::new(x as f32, y as f32)) as f64;
                if v == 0.0 {
                    continue;
                }
                for kx in -kk..=kk {
                    let (re, im) = at(kx, a);
                    let r = &mut row[(kx + kk) as usize];
                    r.0 += v * re;
                    r.1 += v * im;
                }
            }
        }
        let mut c = Box::new([[(0.0f64, 0.0f64); FK]; FK]);
        let norm = 1.0 / (N * N) as f64;
        for ky in -kk..=kk {
            for kx in 0..FK {
                let (mut sr, mut si) = (0.0, 0.0);
                for (b, row) in rows.iter().enumerate() {
                    let (er, ei) = at(ky, b);
                    let (vr, vi) = row[kx];
                    sr += vr * er - vi * ei;
                    si += vr * ei + vi * er;
                }
                c[(ky + kk) as usize][kx] = (sr * norm, si * norm);
            }
        }
        Series { c, period }
    }

    /// The pattern averaged over the other axis, along `axis` (0: x over a period of 2 cells,
    /// 1: y over two rows), in [`PROFILE_BINS`] bins, handed to `f`; remembered per thread for
    /// the last few patterns, as the [`Series`]: the 65 536 point evaluations it takes are
    /// paid once.
    fn profile(&self, axis: usize, f: impl FnOnce(&[f32; PROFILE_BINS]) -> (f64, f64)) -> (f64, f64) {
        thread_local! {
            static MEMO: Memo<((u8, u64), usize), Profile> = const { std::cell::RefCell::new(Vec::new()) };
        }
        MEMO.with(|memo| remembered(memo, (self.key(), axis), || self.make_profile(axis), |b| f(b)))
    }

    fn make_profile(&self, axis: usize) -> Profile {
        let periods = [2.0, self.row_height() * 2.0];
        let n = PROFILE_BINS;
        let mut bins = Box::new([0.0f32; PROFILE_BINS]);
        for (b, v) in bins.iter_mut().enumerate() {
            let mut acc = 0.0f64;
            for a in 0..n {
                let along = (b as f64 + 0.5) / n as f64 * periods[axis];
                let across = (a as f64 + 0.5) / n as f64 * periods[1 - axis];
                let q = if axis == 0 {
                    Vec2::new(along as f32, across as f32)
                } else {
                    Vec2::new(across as f32, along as f32)
                };
                acc += self.point(q) as f64;
            }
            *v = (acc / n as f64) as f32;
        }
        bins
    }
}

/// The Gaussian average of a periodic piecewise-constant profile (`bins` over `period`) at
/// `N(m, s²)`, and its derivative in `m`.
fn profile_average(bins: &[f32], period: f64, m: f64, s: f64) -> (f64, f64) {
    let n = bins.len() as f64;
    let w = period / n;
    // Bins within ±7σ.
    let first = ((m - 7.0 * s) / w).floor();
    let last = ((m + 7.0 * s) / w).floor();
    let (mut p, mut d) = (0.0, 0.0);
    let edge = |e: f64| {
        let z = (e * w - m) / s;
        (cdf(z), pdf(z) / s)
    };
    let mut lo = edge(first);
    for b in crate::gaussian::cells(first, last) {
        let hi = edge(b + 1.0);
        let v = bins[b.rem_euclid(n) as usize] as f64;
        p += v * (hi.0 - lo.0);
        d += v * (lo.1 - hi.1);
        lo = hi;
    }
    (p, d)
}

fn tiled(pat: Tiled, ins: &[Filtered], ctx: &mut Ctx) -> Moments {
    // As at points: crosshatch lines and hexagons of no positive size are empty (circles see
    // only the size's square, so a negative one is its magnitude: see `pieces`).
    match pat {
        Tiled::Cross { th, .. } if th <= 0.0 => return Moments::constant(0.0),
        Tiled::Shapes { size, motif: Motif::Hexagon, .. } if size <= 0.0 => return Moments::constant(0.0),
        Tiled::Shapes { size: 0.0, .. } => return Moments::constant(0.0),
        _ => {}
    }
    let (tile, off) = (v2(&ins[1]).as_dvec2(), v2(&ins[2]).as_dvec2());
    let (m, s, j) = coord(&ins[0], tile, off);
    let h = pat.row_height();
    if s.x >= TILE_SIGMA_FOURIER && s.y / h >= TILE_SIGMA_FOURIER {
        // The footprint's covariance in cells, correlation included.
        let cxy = crate::moments::cov(&ins[0].ch[0], &ins[0].ch[1], ctx.fp) as f64 * tile.x * tile.y;
        let (p, dp) = pat.series(|series| series.average(m, [s.x * s.x, cxy, s.y * s.y]));
        ctx.work.lattice += 1;
        return indicator(p.clamp(0.0, 1.0), dp, &j);
    }
    let wide = [s.x > TILE_SIGMA_GLOBAL, s.y / h > TILE_SIGMA_GLOBAL];
    // Wide along one axis only (a grazing footprint): the pattern averaged along that axis,
    // filtered along the other. Not where the narrow spread is below two of the profile's
    // bins, whose steps would then show.
    for axis in 0..2 {
        let period = [2.0, 2.0 * h][axis];
        if wide[1 - axis] && !wide[axis] && get(s, axis) > 2.0 * period / PROFILE_BINS as f64 {
            let (p, dp) = pat.profile(axis, |bins| profile_average(bins, period, get(m, axis), get(s, axis)));
            ctx.work.lattice += 1;
            let g = if axis == 0 { DVec2::new(dp, 0.0) } else { DVec2::new(0.0, dp) };
            return indicator(p.clamp(0.0, 1.0), g, &j);
        }
    }
    let span = |m: f64, s: f64, unit: f64| {
        let lo = ((m - 6.0 * s) / unit).floor() as i64 - 1;
        let hi = ((m + 6.0 * s) / unit).floor() as i64 + 1;
        let c = (m / unit).floor() as i64;
        (lo.max(c - MAX_CELLS / 2), hi.min(c + MAX_CELLS / 2))
    };
    let (i0, i1) = span(m.x, s.x, 1.0);
    let (j0, j1) = span(m.y, s.y, h);
    thread_local! {
        // The pieces of one cell, reused: nothing is allocated per evaluation.
        static PIECES: std::cell::RefCell<Vec<Piece>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    let (mut p, mut g) = (0.0, DVec2::ZERO);
    PIECES.with_borrow_mut(|pieces| {
        for jj in j0..=j1 {
            for ii in i0..=i1 {
                pieces.clear();
                pat.pieces(ii, jj, pieces);
                let (q, dq) = if pat.overlaps() { union_coverage(pieces, m, s) } else { coverage(pieces, m, s) };
                p += q;
                g += dq;
                ctx.work.lattice += 1;
            }
        }
    });
    indicator(p.clamp(0.0, 1.0), g, &j)
}

// ---------------------------------------------------------------------------------------------

pub(crate) fn eval(op: &ShapeOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let t = v2(&ins[0]);
    let f = |x: f32| x as f64;
    let th = ins.get(3).map(|v| v.ch[0].mean).unwrap_or(0.0);
    let staggered = ins.get(4).is_some_and(|v| v.ch[0].mean > 0.5);
    let tiled_pat = match op {
        ShapeOp::Crosshatch => Some(Tiled::Cross { th: f(th), staggered }),
        ShapeOp::TiledCircles => Some(Tiled::Shapes { size: f(th), staggered, motif: Motif::Circle }),
        ShapeOp::TiledHexagons => Some(Tiled::Shapes { size: f(th), staggered, motif: Motif::Hexagon }),
        ShapeOp::TiledCloverleafs => Some(Tiled::Shapes { size: f(th), staggered, motif: Motif::Clover }),
        _ => None,
    };
    let m = if ctx.point {
        let v = match op {
            ShapeOp::Circle => circle_point(t, v2(&ins[1]), ins[2].ch[0].mean),
            ShapeOp::Hexagon => hexagon_point(t, v2(&ins[1]), ins[2].ch[0].mean),
            ShapeOp::Cloverleaf => clover_point(t, v2(&ins[1]), ins[2].ch[0].mean),
            ShapeOp::Line => line_point(t, v2(&ins[1]), ins[2].ch[0].mean, v2(&ins[3]), v2(&ins[4])),
            ShapeOp::Grid => grid_point(cell(t, v2(&ins[1]), v2(&ins[2])), th, staggered),
            _ => tiled_pat.unwrap().point(cell(t, v2(&ins[1]), v2(&ins[2]))),
        };
        Moments::constant(v)
    } else {
        match op {
            ShapeOp::Grid => grid(ins),
            ShapeOp::Cloverleaf => {
                let (c, r) = (v2(&ins[1]).as_dvec2(), f(ins[2].ch[0].mean));
                let (m, s, j) = coord(&ins[0], DVec2::ONE, DVec2::ZERO);
                let (p, dp) = if r != 0.0 {
                    thread_local! {
                        static PIECES: std::cell::RefCell<Vec<Piece>> = const { std::cell::RefCell::new(Vec::new()) };
                    }
                    PIECES.with_borrow_mut(|pieces| {
                        pieces.clear();
                        Piece::clover(c, r.abs() / 2.0, None, pieces);
                        union_coverage(pieces, m, s)
                    })
                } else {
                    (0.0, DVec2::ZERO)
                };
                ctx.work.lattice += 1;
                indicator(p, dp, &j)
            }
            ShapeOp::Circle | ShapeOp::Hexagon | ShapeOp::Line => {
                let c = v2(&ins[1]).as_dvec2();
                let r = f(ins[2].ch[0].mean);
                let (m, s, j) = coord(&ins[0], DVec2::ONE, DVec2::ZERO);
                let prim = match op {
                    ShapeOp::Circle => Prim::Disk { c, r: r.abs() },
                    ShapeOp::Hexagon => Prim::Hex { c, r },
                    _ => Prim::Capsule { a: v2(&ins[3]).as_dvec2() + c, b: v2(&ins[4]).as_dvec2() + c, r },
                };
                // A circle only sees r²; the hexagon and the capsule are empty for r ≤ 0.
                let live = if matches!(op, ShapeOp::Circle) { r != 0.0 } else { r > 0.0 };
                let (p, dp) = if live { coverage(&[Piece::one(prim)], m, s) } else { (0.0, DVec2::ZERO) };
                ctx.work.lattice += 1;
                indicator(p, dp, &j)
            }
            _ => tiled(tiled_pat.unwrap(), ins, ctx),
        }
    };
    let mut out = Filtered::zero(ty);
    for k in 0..ty.channels() {
        out.ch[k] = m;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pieces reproduce the point functions (at a point footprint the coverage is the
    /// indicator) away from edges.
    #[test]
    fn pieces_match_points() {
        let s = DVec2::splat(1e-7);
        let mut bad = 0;
        let mut n = 0;
        for a in 0..60 {
            for b in 0..60 {
                let q = Vec2::new(-1.3 + a as f32 * 0.0613, -1.1 + b as f32 * 0.0571);
                let m = q.as_dvec2();
                let c = Vec2::new(0.2, -0.1);
                let pc = coverage(&[Piece::one(Prim::Disk { c: c.as_dvec2(), r: 0.7 })], m, s).0;
                bad += ((pc - circle_point(q, c, 0.7) as f64).abs() > 0.5) as i32;
                let ph = coverage(&[Piece::one(Prim::Hex { c: c.as_dvec2(), r: 0.6 })], m, s).0;
                bad += ((ph - hexagon_point(q, c, 0.6) as f64).abs() > 0.5) as i32;
                let (p1, p2) = (Vec2::new(-0.5, 0.3), Vec2::new(0.6, -0.4));
                let cap = Prim::Capsule { a: (p1 + c).as_dvec2(), b: (p2 + c).as_dvec2(), r: 0.2 };
                let pl = coverage(&[Piece::one(cap)], m, s).0;
                bad += ((pl - line_point(q, c, 0.2, p1, p2) as f64).abs() > 0.5) as i32;
                let mut clover = Vec::new();
                Piece::clover(c.as_dvec2(), 0.35, None, &mut clover);
                let pc4 = union_coverage(&clover, m, s).0;
                bad += ((pc4 - clover_point(q, c, 0.7) as f64).abs() > 0.5) as i32;
                for pat in [
                    Tiled::Cross { th: 0.1, staggered: false },
                    Tiled::Cross { th: 0.1, staggered: true },
                    Tiled::Shapes { size: 0.7, staggered: false, motif: Motif::Circle },
                    Tiled::Shapes { size: 0.7, staggered: true, motif: Motif::Circle },
                    Tiled::Shapes { size: 0.7, staggered: false, motif: Motif::Hexagon },
                    Tiled::Shapes { size: 0.9, staggered: true, motif: Motif::Hexagon },
                    Tiled::Shapes { size: 0.8, staggered: false, motif: Motif::Clover },
                    Tiled::Shapes { size: 0.9, staggered: true, motif: Motif::Clover },
                ] {
                    let h = pat.row_height();
                    let (i, j) = ((m.x).floor() as i64, (m.y / h).floor() as i64);
                    let mut pieces = Vec::new();
                    let mut p = 0.0;
                    for jj in j - 1..=j + 1 {
                        for ii in i - 1..=i + 1 {
                            pieces.clear();
                            pat.pieces(ii, jj, &mut pieces);
                            p += if pat.overlaps() {
                                union_coverage(&pieces, m, s).0
                            } else {
                                coverage(&pieces, m, s).0
                            };
                        }
                    }
                    bad += ((p - pat.point(q) as f64).abs() > 0.5) as i32;
                    n += 1;
                }
                n += 4;
            }
        }
        assert!(bad <= n / 500, "{bad} of {n} points disagree");
    }
}
