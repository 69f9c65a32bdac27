//! Vector nodes of three channels (MaterialX 1.39 stdlib): `crossproduct`, `reflect`, `refract`.
//!
//! | node | inputs (default) | unfiltered | filtered evaluation |
//! |---|---|---|---|
//! | `crossproduct` | `in1` (0), `in2` (0) | `in1 × in2` | Gaussian product moments (exact for a uniform operand) |
//! | `reflect` | `in` (1, 0, 0), `normal` (the shading normal) | `in − 2 (in · normal) normal`, GLSL's `reflect` (no normalisation) | product moments (exact for a uniform normal and the linear part) |
//! | `refract` | `in` (1, 0, 0), `normal` (the shading normal), `ior` (1) | GLSL's `refract`: with `d = in · normal`, `k = 1 − ior² (1 − d²)`: 0 where `k < 0`, else `ior · in − (ior d + √k) normal` | cubature over the seven channels that vary |

use super::{inp, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::{GeomProp, Source};
use crate::moments::{add_scaled, mul, nary};
use crate::value::{Filtered, Moments, ValueType};

pub(crate) const CATEGORIES: &[&str] = &["crossproduct", "reflect", "refract"];

/// Vector operations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VectorOp {
    /// `crossproduct`
    Cross,
    /// `reflect`
    Reflect,
    /// `refract`
    Refract,
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let inputs: &'static [_] = match category {
        "crossproduct" => &[inp!("in1", Out, Zero), inp!("in2", Out, Zero)],
        "reflect" => &[inp!("in", Out, Triple(1.0, 0.0, 0.0)), inp!("normal", Out, Geom(GeomProp::Normal))],
        "refract" => &[
            inp!("in", Out, Triple(1.0, 0.0, 0.0)),
            inp!("normal", Out, Geom(GeomProp::Normal)),
            inp!("ior", Float, One),
        ],
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types: |t| t == ValueType::Vector3, build })
}

fn build(category: &str, _: ValueType, _: &[ValueType], _: &[Source], _: &[Param]) -> Result<Op, String> {
    Ok(Op::Vector(match category {
        "crossproduct" => VectorOp::Cross,
        "reflect" => VectorOp::Reflect,
        _ => VectorOp::Refract,
    }))
}

/// GLSL's `refract` of `p = (in, normal, ior)`, channel `k`.
fn refract_point(p: &[f64], k: usize) -> f64 {
    let (i, n, eta) = ([p[0], p[1], p[2]], [p[3], p[4], p[5]], p[6]);
    let d = i[0] * n[0] + i[1] * n[1] + i[2] * n[2];
    let disc = 1.0 - eta * eta * (1.0 - d * d);
    if disc < 0.0 {
        0.0
    } else {
        eta * i[k] - (eta * d + disc.sqrt()) * n[k]
    }
}

pub(crate) fn eval(op: &VectorOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let fp = ctx.fp;
    let mut out = Filtered::zero(ty);
    let (a, b) = (&ins[0], &ins[1]);
    match op {
        VectorOp::Cross => {
            for k in 0..3 {
                let (u, v) = ((k + 1) % 3, (k + 2) % 3);
                out.ch[k] = add_scaled(mul(a.ch[u], b.ch[v], fp), mul(a.ch[v], b.ch[u], fp), -1.0, fp);
            }
        }
        VectorOp::Reflect => {
            let mut d = Moments::default();
            for k in 0..3 {
                d = add_scaled(d, mul(a.ch[k], b.ch[k], fp), 1.0, fp);
            }
            for k in 0..3 {
                out.ch[k] = add_scaled(a.ch[k], mul(d, b.ch[k], fp), -2.0, fp);
            }
        }
        VectorOp::Refract => {
            let xs = [a.ch[0], a.ch[1], a.ch[2], b.ch[0], b.ch[1], b.ch[2], ins[2].ch[0]];
            for k in 0..3 {
                out.ch[k] = nary(&xs, |p| refract_point(p, k));
            }
        }
    }
    out
}
