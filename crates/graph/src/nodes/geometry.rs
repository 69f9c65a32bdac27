//! Coordinates and constants: `texcoord`, `constant`, `place2d`, `rotate2d`, `dot`.
//!
//! | node | inputs (default) | filtered evaluation |
//! |---|---|---|
//! | `texcoord` | `index` (0) | mean `uv`, gradient the identity, variance `diag Σ` (exact) |
//! | `constant` | `value` (0) | exact, zero spread |
//! | `place2d` | `texcoord` (UV0), `pivot` (0,0), `scale` (1,1), `rotate` (0°), `offset` (0,0), `operationorder` (0 = SRT) | affine in `texcoord`: exact when the other inputs are uniform, cubature otherwise |
//! | `rotate2d` | `in` (0,0), `amount` (0°) | linear: exact for uniform `amount` |
//! | `dot` | `in` (0) | pass-through |
//!
//! `place2d` follows MaterialX's nodegraph: SRT is `((t − pivot) / scale)` rotated by `rotate`
//! degrees (`rotate2d`: `(c x + s y, −s x + c y)`), minus `offset`, plus `pivot`; TRS subtracts
//! `offset` before rotating and divides by `scale` after.

use super::{inp, types, Ctx, Def, InType, NodeDef, Op};
use crate::moments::{self, add_scaled, affine};
use crate::value::{Filtered, Moments, ValueType};
use glam::Vec2;

pub(crate) const CATEGORIES: &[&str] = &["texcoord", "constant", "place2d", "rotate2d", "dot"];

/// Geometry operations.
#[derive(Debug)]
pub enum GeometryOp {
    /// `texcoord`
    Texcoord,
    /// `constant`
    Constant,
    /// `place2d`
    Place2d,
    /// `rotate2d`
    Rotate2d,
    /// `dot`
    Dot,
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let (inputs, types): (&'static [_], fn(ValueType) -> bool) = match category {
        "texcoord" => (&[inp!("index", Int, Zero)], |t| matches!(t, ValueType::Vector2 | ValueType::Vector3)),
        "constant" => (&[inp!("value", Out, Zero)], types::numeric),
        "place2d" => (
            &[
                inp!("texcoord", V2, Uv),
                inp!("pivot", V2, Zero),
                inp!("scale", V2, One),
                inp!("rotate", Float, Zero),
                inp!("offset", V2, Zero),
                inp!("operationorder", Int, Zero),
            ],
            types::vector2,
        ),
        "rotate2d" => (&[inp!("in", V2, Zero), inp!("amount", Float, Zero)], types::vector2),
        "dot" => (&[inp!("in", Out, Zero)], types::numeric),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types, build })
}

fn build(
    category: &str,
    _: ValueType,
    _: &[ValueType],
    _: &[crate::graph::Source],
    _: &[super::Param],
) -> Result<Op, String> {
    Ok(Op::Geometry(match category {
        "texcoord" => GeometryOp::Texcoord,
        "constant" => GeometryOp::Constant,
        "place2d" => GeometryOp::Place2d,
        "rotate2d" => GeometryOp::Rotate2d,
        _ => GeometryOp::Dot,
    }))
}

/// The filtered texture coordinate itself.
pub(crate) fn texcoord(ctx: &Ctx) -> Filtered {
    let fp = ctx.fp;
    let mut f = Filtered::zero(ValueType::Vector2);
    f.ch[0] = Moments { mean: fp.uv.x, grad: Vec2::X, var: fp.cov.x_axis.x.max(0.0) };
    f.ch[1] = Moments { mean: fp.uv.y, grad: Vec2::Y, var: fp.cov.y_axis.y.max(0.0) };
    f
}

/// Rotates `(x, y)` by `deg` degrees the way MaterialX's `rotate2d` does.
pub(crate) fn rotate(x: Moments, y: Moments, deg: f32, ctx: &Ctx) -> (Moments, Moments) {
    let (s, c) = deg.to_radians().sin_cos();
    let rx = add_scaled(affine(x, c, 0.0), y, s, ctx.fp);
    let ry = add_scaled(affine(y, c, 0.0), x, -s, ctx.fp);
    (rx, ry)
}

fn uniform(ins: &[Filtered], idx: &[usize]) -> bool {
    idx.iter().all(|&i| ins[i].is_uniform())
}

pub(crate) fn eval(op: &GeometryOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    match op {
        GeometryOp::Texcoord => {
            let mut f = texcoord(ctx);
            f.ty = ty;
            f
        }
        GeometryOp::Constant | GeometryOp::Dot => ins[0],
        GeometryOp::Rotate2d => {
            let mut out = Filtered::zero(ValueType::Vector2);
            if ins[1].is_uniform() {
                let (x, y) = rotate(ins[0].ch[0], ins[0].ch[1], ins[1].ch[0].mean, ctx);
                out.ch[0] = x;
                out.ch[1] = y;
            } else {
                for k in 0..2 {
                    out.ch[k] = moments::nary(&[ins[0].ch[0], ins[0].ch[1], ins[1].ch[0]], |p| {
                        let (s, c) = p[2].to_radians().sin_cos();
                        if k == 0 {
                            c * p[0] + s * p[1]
                        } else {
                            -s * p[0] + c * p[1]
                        }
                    });
                }
            }
            out
        }
        GeometryOp::Place2d => place2d(ins, ctx),
    }
}

fn place2d(ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let t = &ins[0];
    let mut out = Filtered::zero(ValueType::Vector2);
    if uniform(ins, &[1, 2, 3, 4, 5]) {
        let pivot = Vec2::new(ins[1].ch[0].mean, ins[1].ch[1].mean);
        let scale = Vec2::new(ins[2].ch[0].mean, ins[2].ch[1].mean);
        let deg = ins[3].ch[0].mean;
        let offset = Vec2::new(ins[4].ch[0].mean, ins[4].ch[1].mean);
        let trs = ins[5].ch[0].mean >= 1.0;
        let (x, y) = (affine(t.ch[0], 1.0, -pivot.x), affine(t.ch[1], 1.0, -pivot.y));
        let (x, y) = if !trs {
            let (x, y) = rotate(affine(x, 1.0 / scale.x, 0.0), affine(y, 1.0 / scale.y, 0.0), deg, ctx);
            (affine(x, 1.0, -offset.x), affine(y, 1.0, -offset.y))
        } else {
            let (x, y) = rotate(affine(x, 1.0, -offset.x), affine(y, 1.0, -offset.y), deg, ctx);
            (affine(x, 1.0 / scale.x, 0.0), affine(y, 1.0 / scale.y, 0.0))
        };
        out.ch[0] = affine(x, 1.0, pivot.x);
        out.ch[1] = affine(y, 1.0, pivot.y);
        return out;
    }
    let xs = [
        t.ch[0],
        t.ch[1],
        ins[1].ch[0],
        ins[1].ch[1],
        ins[2].ch[0],
        ins[2].ch[1],
        ins[3].ch[0],
        ins[4].ch[0],
        ins[4].ch[1],
        ins[5].ch[0],
    ];
    for k in 0..2 {
        out.ch[k] = moments::nary(&xs, |p| place2d_point(p)[k]);
    }
    out
}

/// Unfiltered `place2d` from `[tx, ty, px, py, sx, sy, deg, ox, oy, order]`.
fn place2d_point(p: &[f64]) -> [f64; 2] {
    let (x, y) = (p[0] - p[2], p[1] - p[3]);
    let (s, c) = p[6].to_radians().sin_cos();
    let rot = |x: f64, y: f64| (c * x + s * y, -s * x + c * y);
    let (x, y) = if p[9] < 1.0 {
        let (x, y) = rot(x / p[4], y / p[5]);
        (x - p[7], y - p[8])
    } else {
        let (x, y) = rot(x - p[7], y - p[8]);
        (x / p[4], y / p[5])
    };
    [x + p[2], y + p[3]]
}
