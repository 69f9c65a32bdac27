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
//! a Gaussian-smoothed chord length. A disk, hexagon or capsule far smaller than its footprint
//! (every point within 0.02 of the narrower σ of its centre) is instead the density at its
//! centre times its area, with the second-moment correction (`coverage::small_coverage`). Most pieces of a small footprint need no quadrature: where
//! no boundary of a piece is within 6.5 |σ| of the centre (under 1e-9 of the mass lies beyond),
//! the piece is wholly in or out, its coverage 1 or 0; where one strip's or rectangle's boundary
//! alone is, its coverage is in closed form (the interval mass of `n · X`, or a product of two).
//! The distances are lower bounds (exact for disks, capsules and strips, short of the truth
//! off a hexagon's or rectangle's corners), so a shortcut is taken only where it is exact.
//!
//! The tiled patterns (`crosshatch`, `tiledcircles`, `tiledhexagons`, `tiledcloverleafs`) visit
//! the cells within ±6σ while the footprint is under 0.1 cells (rows) on either axis. From 0.1
//! on both, they are the exact Gaussian convolution of their Fourier series over one period (1
//! cell by 2 rows; |k| ≤ 12 per axis, from 256 × 256 point samples made once per pattern and
//! thread), correlation of the footprint's axes included: every mode is damped by
//! `e^{−2π² kᵀΣk}`, so at 0.1 cells the modes left out weigh below 1e-5 and at wide footprints
//! only the mean (the coverage) remains; only the modes damped by less than 1e-12 are visited
//! (found from the quadratic form, not by computing every mode's damping). A footprint wide (over 0.6 cells) along one axis only
//! and narrow along the other (a grazing view) takes the pattern's average along the wide axis,
//! a 256-bin profile filtered along the narrow one. Unions are sums of disjoint pieces (inclusion–exclusion
//! for the crosshatch's overlapping strips), or, for overlapping disks (the cloverleafs', and
//! staggered circles' and hexagons' past size 1), the merged chords of all pieces at each
//! height.

use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::Source;
use crate::value::{Filtered, Moments, ValueType};
use coverage::{coverage, interval, small_coverage, union_coverage, Piece, Prim};
use glam::{DVec2, Vec2};
use tiled::{tiled, Tiled};

mod coverage;
#[cfg(test)]
mod tests;
mod tiled;

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
            let att = crate::gaussian::exp_damping(-2.0 * PI * PI * nf * nf * s * s);
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
                let (p, dp) = match live.then(|| small_coverage(&prim, m, s)) {
                    None => (0.0, DVec2::ZERO),
                    Some(Some(small)) => small,
                    Some(None) => coverage(&[Piece::one(prim)], m, s),
                };
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
