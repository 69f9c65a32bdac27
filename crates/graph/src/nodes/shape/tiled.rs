//! Tiled patterns.

use super::coverage::{coverage, get, union_coverage, Piece, Prim};
use super::{coord, crosshatch_point, indicator, tiled_point, v2, Ctx, Motif};
use crate::gaussian::{cdf, pdf};
use crate::value::{Filtered, Moments};
use glam::{DVec2, Vec2};

/// Per-axis spread (cells) beyond which a tiled pattern is its average along that axis.
const TILE_SIGMA_GLOBAL: f64 = 0.6;
/// Most cells visited per axis.
const MAX_CELLS: i64 = 48;

#[derive(Clone, Copy)]
pub(super) enum Tiled {
    Cross { th: f64, staggered: bool },
    Shapes { size: f64, staggered: bool, motif: Motif },
}

impl Tiled {
    pub(super) fn row_height(&self) -> f64 {
        match *self {
            Tiled::Shapes { staggered: true, motif, .. } => motif.row() as f64,
            _ => 1.0,
        }
    }

    /// Whether odd rows are shifted by half a cell.
    fn staggered(&self) -> bool {
        match *self {
            Tiled::Cross { staggered, .. } | Tiled::Shapes { staggered, .. } => staggered,
        }
    }

    pub(super) fn point(&self, q: Vec2) -> f32 {
        match *self {
            Tiled::Cross { th, staggered } => crosshatch_point(q, th as f32, staggered),
            Tiled::Shapes { size, staggered, motif } => tiled_point(q, size as f32, staggered, motif),
        }
    }

    /// The pieces of cell (i, j).
    pub(super) fn pieces(&self, i: i64, j: i64, out: &mut Vec<Piece>) {
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
    /// other; staggered circles and hexagons once `size` passes 1, the lattice's spacing), so
    /// that the cell's coverage is that of their union.
    pub(super) fn overlaps(&self) -> bool {
        match *self {
            Tiled::Shapes { motif: Motif::Clover, .. } => true,
            Tiled::Shapes { size, staggered: true, .. } => size.abs() > 1.0,
            Tiled::Cross { .. } | Tiled::Shapes { .. } => false,
        }
    }

    /// What identifies the pattern for the memos of its [`Series`] and profiles.
    pub(super) fn key(&self) -> (u8, u64) {
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
        // The modes the loop below keeps (damped by 1e-12 or less) lie where the damping's
        // exponent `a kx² + c kx ky + b ky²` is at most −ln 1e-12 (below `CUT`). Its smallest
        // value over whole nonzero modes is at least its form's smaller eigenvalue: above the
        // cut, only the mean (mode 0) is left.
        const CUT: f64 = 27.64;
        let lambda_min = 0.5 * (a + b) - (0.25 * (a - b) * (a - b) + 0.25 * c * c).sqrt();
        if lambda_min > CUT {
            return (self.c[FOURIER_K][FOURIER_K].0, DVec2::ZERO);
        }
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
        // The kept modes lie in rows |ky| up to √(CUT / (b − c²/4a)), and within a row between
        // the exponent's roots in kx. Visiting only those (a mode wider on each side, the tests
        // below still deciding) skips the modes a wide footprint damps away without computing
        // their damping, and changes no result.
        let det = b - c * c / (4.0 * a);
        let bounded = a > 0.0 && det > 0.0;
        let clamp = |x: f64| (x.max(-(k as f64)).min(k as f64)) as i64;
        let ky_max = if bounded { clamp((CUT / det).sqrt().floor() + 1.0) } else { k };
        let (mut p, mut gx, mut gy) = (0.0, 0.0, 0.0);
        for ky in -ky_max..=ky_max {
            let dy = crate::gaussian::exp_damping(-b * (ky * ky) as f64);
            if dy < 1e-12 {
                continue;
            }
            let (yr, yi) = uy[(ky + k) as usize];
            let (kx0, kx1) = if bounded {
                let fy = ky as f64;
                let disc = (c * c * fy * fy - 4.0 * a * (b * fy * fy - CUT)).max(0.0).sqrt();
                (
                    clamp(((-c * fy - disc) / (2.0 * a)).floor() - 1.0),
                    clamp(((-c * fy + disc) / (2.0 * a)).ceil() + 1.0),
                )
            } else {
                (-k, k)
            };
            for kx in kx0..=kx1 {
                // One exponent: the quadratic form is ≥ 0, its cross term alone is not.
                let (fx, fy) = (kx as f64, ky as f64);
                let d = crate::gaussian::exp_damping(-(a * fx * fx + b * fy * fy + c * fx * fy));
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

pub(super) fn tiled(pat: Tiled, ins: &[Filtered], ctx: &mut Ctx) -> Moments {
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
    // The cells that meet ±6σ (every piece is clipped to its cell): rows of height h, and
    // cells along a row found from the unshifted grid, one more at the top for rows shifted by
    // half a cell (cell i of such a row begins at i − ½).
    let span = |m: f64, s: f64, unit: f64, shift: i64| {
        let lo = ((m - 6.0 * s) / unit).floor() as i64;
        let hi = ((m + 6.0 * s) / unit).floor() as i64 + shift;
        let c = (m / unit).floor() as i64;
        (lo.max(c - MAX_CELLS / 2), hi.min(c + MAX_CELLS / 2))
    };
    let staggered = pat.staggered();
    let (i0, i1) = span(m.x, s.x, 1.0, staggered as i64);
    let (j0, j1) = span(m.y, s.y, h, 0);
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
