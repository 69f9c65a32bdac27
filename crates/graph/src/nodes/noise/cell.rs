//! Cell noise.

use super::perlin::M3;
use super::{coordinate, coordinate3, to_uv, to_uv3};
use crate::gaussian;
use crate::nodes::hash::{cell3_float, cell3_vec3, cell_float, cell_vec3, ifloor};
use crate::nodes::Ctx;
use crate::value::{Filtered, Moments, ValueType};
use glam::{DVec2, DVec3, Vec2};

/// Per-axis spread (cells) up to which cell noise is filtered exactly.
pub const CELL_SIGMA_EXACT: f64 = 0.5;

pub(super) fn cell_value(ix: i32, iy: i32, k: usize, vector: bool) -> f32 {
    if vector {
        cell_vec3(ix, iy, k as i32)
    } else {
        cell_float(ix, iy)
    }
}

pub(super) fn cellnoise2d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (p, s, j) = coordinate(&ins[0]);
    let vector = ty == ValueType::Vector3;
    let n = ty.channels();
    let mut out = Filtered::zero(ty);
    if s.x == 0.0 && s.y == 0.0 {
        let (ix, iy) = (ifloor(p.x as f32), ifloor(p.y as f32));
        for k in 0..n {
            out.ch[k] = Moments::constant(cell_value(ix, iy, k, vector));
        }
        ctx.work.lattice += 1;
        return out;
    }
    let shrink =
        (CELL_SIGMA_EXACT / s.x.max(CELL_SIGMA_EXACT)).sqrt() * (CELL_SIGMA_EXACT / s.y.max(CELL_SIGMA_EXACT)).sqrt();
    if shrink < 0.02 {
        for k in 0..n {
            out.ch[k] = Moments { mean: 0.5, grad: Vec2::ZERO, var: 1.0 / 12.0 };
        }
        return out;
    }
    let se = s.min(DVec2::splat(CELL_SIGMA_EXACT));
    // Per-axis cell masses and their derivatives with respect to the mean.
    let axis = |m: f64, s: f64, buf: &mut [(i32, f64, f64); 8]| -> usize {
        if s.is_nan() || s <= 1e-12 {
            // No spread along this axis (e.g. a constant coordinate channel): one cell, all mass.
            buf[0] = (m.floor() as i32, 1.0, 0.0);
            return 1;
        }
        let lo = (m - 4.0 * s).floor() as i32;
        let hi = (m + 4.0 * s).floor() as i32;
        // One erfc and one exp per cell boundary, each shared by the cells on both sides.
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
    };
    let mut xs = [(0, 0.0, 0.0); 8];
    let mut ys = [(0, 0.0, 0.0); 8];
    let nx = axis(p.x, se.x, &mut xs);
    let ny = axis(p.y, se.y, &mut ys);
    ctx.work.lattice += (nx * ny) as u64;
    for k in 0..n {
        let (mut e, mut e2, mut dx, mut dy) = (0.0, 0.0, 0.0, 0.0);
        for &(cy, wy, dwy) in &ys[..ny] {
            for &(cx, wx, dwx) in &xs[..nx] {
                let h = cell_value(cx, cy, k, vector) as f64;
                e += wx * wy * h;
                e2 += wx * wy * h * h;
                dx += dwx * wy * h;
                dy += wx * dwy * h;
            }
        }
        let var = if shrink < 1.0 { 1.0 / 12.0 - ((e - 0.5) * shrink).powi(2) } else { e2 - e * e };
        let m = Moments {
            mean: (0.5 + (e - 0.5) * shrink) as f32,
            grad: Vec2::new((dx * shrink) as f32, (dy * shrink) as f32),
            var: var.max(0.0) as f32,
        };
        out.ch[k] = to_uv(&m, &j);
    }
    out
}

pub(super) fn cell_value3(c: [i32; 3], k: usize, vector: bool) -> f32 {
    if vector {
        cell3_vec3(c[0], c[1], c[2], k as i32)
    } else {
        cell3_float(c[0], c[1], c[2])
    }
}

/// Cells an axis's footprint covers: (cell, mass, d mass / d mean); `None`-like single cell
/// with all the mass when the axis has no spread.
pub(super) fn cell_axis(m: f64, s: f64, buf: &mut [(i32, f64, f64); 8]) -> usize {
    if s.is_nan() || s <= 1e-12 {
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

pub(super) fn cellnoise3d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (p, s, j) = coordinate3(&ins[0]);
    let vector = ty == ValueType::Vector3;
    let n = ty.channels();
    let mut out = Filtered::zero(ty);
    if s == DVec3::ZERO {
        let c = [ifloor(p.x as f32), ifloor(p.y as f32), ifloor(p.z as f32)];
        for k in 0..n {
            out.ch[k] = Moments::constant(cell_value3(c, k, vector));
        }
        ctx.work.lattice += 1;
        return out;
    }
    let shrink_axis = |s: f64| (CELL_SIGMA_EXACT / s.max(CELL_SIGMA_EXACT)).sqrt();
    let shrink = shrink_axis(s.x) * shrink_axis(s.y) * shrink_axis(s.z);
    if shrink < 0.02 {
        for k in 0..n {
            out.ch[k] = Moments { mean: 0.5, grad: Vec2::ZERO, var: 1.0 / 12.0 };
        }
        return out;
    }
    let se = s.min(DVec3::splat(CELL_SIGMA_EXACT));
    let mut axes = [[(0i32, 0.0f64, 0.0f64); 8]; 3];
    let mut na = [0usize; 3];
    for k in 0..3 {
        na[k] = cell_axis(p[k], se[k], &mut axes[k]);
    }
    ctx.work.lattice += (na[0] * na[1] * na[2]) as u64;
    for k in 0..n {
        let (mut e, mut e2, mut d) = (0.0, 0.0, DVec3::ZERO);
        for &(cz, wz, dwz) in &axes[2][..na[2]] {
            for &(cy, wy, dwy) in &axes[1][..na[1]] {
                for &(cx, wx, dwx) in &axes[0][..na[0]] {
                    let h = cell_value3([cx, cy, cz], k, vector) as f64;
                    let w = wx * wy * wz;
                    e += w * h;
                    e2 += w * h * h;
                    d += DVec3::new(dwx * wy * wz, wx * dwy * wz, wx * wy * dwz) * h;
                }
            }
        }
        let var = if shrink < 1.0 { 1.0 / 12.0 - ((e - 0.5) * shrink).powi(2) } else { e2 - e * e };
        let m = M3 { mean: 0.5 + (e - 0.5) * shrink, grad: d * shrink, var: var.max(0.0) };
        out.ch[k] = to_uv3(&m, &j);
    }
    out
}
