//! Cell noise: the hash of the lattice cell, filtered by the footprint's mass over each cell.

use super::lattice::{Dim, Lattice};
use super::perlin::NoiseMoments;
use super::{coordinate, coordinate3, to_uv, to_uv3};
use crate::gaussian;
use crate::nodes::hash::ifloor;
use crate::nodes::Ctx;
use crate::value::{Filtered, Moments, ValueType};
use glam::Vec2;

/// Per-axis spread (cells) up to which cell noise is filtered exactly.
pub const CELL_SIGMA_EXACT: f64 = 0.5;

pub(super) fn cellnoise2d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (p, s, j) = coordinate(&ins[0]);
    // Noise-space moments rounded to f32 before the Jacobian, as the 2D nodes do.
    let finish = |mean: f64, g: [f64; 2], var: f64| {
        let m = Moments { mean: mean as f32, grad: Vec2::new(g[0] as f32, g[1] as f32), var: var as f32 };
        to_uv(&m, &j)
    };
    cellnoise(ty, p.to_array(), s.to_array(), finish, ctx)
}

pub(super) fn cellnoise3d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (p, s, j) = coordinate3(&ins[0]);
    let finish = |mean: f64, g: [f64; 3], var: f64| to_uv3(&NoiseMoments { mean, grad: g, var }, &j);
    cellnoise(ty, p.to_array(), s.to_array(), finish, ctx)
}

/// Filtered cell noise at noise-space coordinate `p` with per-axis spreads `s`: exact cell
/// masses up to [`CELL_SIGMA_EXACT`] per axis; beyond, the residual around the mean 0.5 shrinks
/// like white noise (`√(σ₀/σ)` per axis). `finish` maps a channel's noise-space moments (mean,
/// gradient, variance) to uv.
#[inline(always)]
fn cellnoise<const D: usize>(
    ty: ValueType,
    p: [f64; D],
    s: [f64; D],
    finish: impl Fn(f64, [f64; D], f64) -> Moments,
    ctx: &mut Ctx,
) -> Filtered
where
    Dim<D>: Lattice<D>,
{
    let vector = ty == ValueType::Vector3;
    let n = ty.channels();
    let mut out = Filtered::zero(ty);
    if s.iter().all(|&x| x == 0.0) {
        let c = p.map(|x| ifloor(x as f32));
        for k in 0..n {
            out.ch[k] = Moments::constant(Dim::<D>::cell(c, k, vector));
        }
        ctx.work.lattice += 1;
        return out;
    }
    let shrink_axis = |s: f64| (CELL_SIGMA_EXACT / s.max(CELL_SIGMA_EXACT)).sqrt();
    let shrink = s[1..].iter().fold(shrink_axis(s[0]), |acc, &x| acc * shrink_axis(x));
    if shrink < 0.02 {
        for k in 0..n {
            out.ch[k] = Moments { mean: 0.5, grad: Vec2::ZERO, var: 1.0 / 12.0 };
        }
        return out;
    }
    let se = s.map(|x| x.min(CELL_SIGMA_EXACT));
    // Per-axis cell masses and their derivatives with respect to the mean.
    let mut axes = [[(0i32, 0.0f64, 0.0f64); 8]; D];
    let mut na = [0usize; D];
    for a in 0..D {
        na[a] = Dim::<D>::cell_axis(p[a], se[a], &mut axes[a]);
    }
    ctx.work.lattice += na.iter().product::<usize>() as u64;
    let outer: usize = na[1..].iter().product();
    for k in 0..n {
        let (mut e, mut e2, mut d) = (0.0, 0.0, [0.0; D]);
        // The outer cells in order, axis 1 fastest; x innermost. Each cell's weight is the
        // product of its axes' masses from x on (and with one axis's mass derivative for the
        // gradient).
        let mut at = [0usize; D];
        for _ in 0..outer {
            for &(cx, wx, dwx) in &axes[0][..na[0]] {
                let mut c = [cx; D];
                let (mut w, mut dw) = (wx, [wx; D]);
                dw[0] = dwx;
                for a in 1..D {
                    let (ca, wa, dwa) = axes[a][at[a]];
                    c[a] = ca;
                    w *= wa;
                    for (b, db) in dw.iter_mut().enumerate() {
                        *db *= if b == a { dwa } else { wa };
                    }
                }
                let h = Dim::<D>::cell(c, k, vector) as f64;
                e += w * h;
                e2 += w * h * h;
                for (da, dwa) in d.iter_mut().zip(dw) {
                    *da += dwa * h;
                }
            }
            for a in 1..D {
                at[a] += 1;
                if at[a] < na[a] {
                    break;
                }
                at[a] = 0;
            }
        }
        let var = if shrink < 1.0 { 1.0 / 12.0 - ((e - 0.5) * shrink).powi(2) } else { e2 - e * e };
        out.ch[k] = finish(0.5 + (e - 0.5) * shrink, d.map(|x| x * shrink), var.max(0.0));
    }
    out
}

/// Whether `N(m, s²)` lies within one cell to 6.5σ (under 1e-10 of its mass beyond): that cell
/// then takes all of it, with no erfc or exp (a small footprint away from the cell's edges; the
/// general sums would give it all but the 4σ tails they leave out).
#[inline]
fn settled(m: f64, s: f64) -> bool {
    (m - 6.5 * s).floor() == (m + 6.5 * s).floor()
}

/// 2D cell masses along one axis: (cell, mass, d mass / d mean), one erfc and one exp per cell
/// boundary, each shared by the cells on both sides; a single cell with all the mass when the
/// axis has no spread (e.g. a constant coordinate channel).
pub(super) fn cell_axis_shared(m: f64, s: f64, buf: &mut [(i32, f64, f64); 8]) -> usize {
    if s.is_nan() || s <= 1e-12 || settled(m, s) {
        buf[0] = (m.floor() as i32, 1.0, 0.0);
        return 1;
    }
    let lo = (m - 4.0 * s).floor() as i32;
    let hi = (m + 4.0 * s).floor() as i32;
    let edge = |c: i32| {
        let z = (c as f64 - m) / s;
        let (below, above) = gaussian::tails(z);
        (z, below, above, gaussian::pdf(z))
    };
    let mut a = edge(lo);
    let mut n = 0;
    for c in lo..=hi.min(lo + 7) {
        let b = edge(c + 1);
        let ((za, below_a, above_a, pdf_a), (_, below_b, above_b, pdf_b)) = (a, b);
        // Φ(b) − Φ(a), from the upper tails when both lie above the mean.
        let mass = if za > 0.0 { above_a - above_b } else { below_b - below_a };
        buf[n] = (c, mass, (pdf_a - pdf_b) / s);
        n += 1;
        a = b;
    }
    n
}

/// 3D cell masses along one axis: as [`cell_axis_shared`], each cell's mass from
/// [`gaussian::mass`] on its own (which rounds differently where a cell straddles the mean).
pub(super) fn cell_axis(m: f64, s: f64, buf: &mut [(i32, f64, f64); 8]) -> usize {
    if s.is_nan() || s <= 1e-12 || settled(m, s) {
        buf[0] = (m.floor() as i32, 1.0, 0.0);
        return 1;
    }
    let lo = (m - 4.0 * s).floor() as i32;
    let hi = (m + 4.0 * s).floor() as i32;
    let mut n = 0;
    for c in lo..=hi.min(lo + 7) {
        let (a, b) = ((c as f64 - m) / s, (c as f64 + 1.0 - m) / s);
        buf[n] = (c, gaussian::mass(a, b), (gaussian::pdf(a) - gaussian::pdf(b)) / s);
        n += 1;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A footprint taken as settled has all but 1e-9 of its mass in the cell it is given (its
    /// mass there by the Gaussian's own CDF), and both axis functions return that cell alone;
    /// an unsettled one is spread over the cells the general sums find, whose masses add to 1.
    #[test]
    fn settled_footprints_keep_their_cell() {
        let mut rnd = crate::testing::uniform(0x243f_6a88_85a3_08d3);
        let (mut seen, mut taken) = (0, 0);
        for _ in 0..20_000 {
            let m = rnd() * 200.0 - 100.0;
            let s = 10f64.powf(-6.0 + 5.5 * rnd());
            let mut buf = [(0, 0.0, 0.0); 8];
            if settled(m, s) {
                taken += 1;
                let c = m.floor();
                let inside = gaussian::mass((c - m) / s, (c + 1.0 - m) / s);
                assert!(inside > 1.0 - 1e-9, "m {m} s {s}: {inside} in its cell");
                for n in [cell_axis_shared(m, s, &mut buf), cell_axis(m, s, &mut buf)] {
                    assert_eq!((n, buf[0]), (1, (c as i32, 1.0, 0.0)), "m {m} s {s}");
                }
            } else if s > 1e-12 {
                for n in [cell_axis_shared(m, s, &mut buf), cell_axis(m, s, &mut buf)] {
                    let total: f64 = buf[..n].iter().map(|c| c.1).sum();
                    assert!((total - 1.0).abs() < 1e-4 || n == 8, "m {m} s {s}: masses add to {total}");
                }
            }
            seen += (s < 1e-2) as i32;
        }
        assert!(taken as f64 > 0.5 * seen as f64, "{taken} settled of {seen} small footprints");
    }
}
