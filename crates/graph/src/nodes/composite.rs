//! Compositing (MaterialX 1.39 stdlib): blends of a foreground over a background, the
//! Porter–Duff alpha operators, masks and premultiplication.
//!
//! Every blend takes `fg` (0), `bg` (0) and a float `mix` (1), and returns
//! `mix · r + (1 − mix) · bg` with `r` the blend of `fg` and `bg`: `r` itself where `mix` is 1
//! (the default), `bg` where it is 0; otherwise `bg + mix (r − bg)` with the covariance of `bg`
//! and `mix (r − bg)` from `bg`'s own variance (`mix` taken independent of the operands).
//!
//! | node | types | `r` (per channel) | filtered evaluation |
//! |---|---|---|---|
//! | `plus`, `minus` | float, color3, color4 | `bg ± fg` | exact for a uniform `mix` (linear); product moments otherwise |
//! | `difference` | float, color3, color4 | `|bg − fg|` | closed-form `|·|` of the difference's Gaussian, then product moments |
//! | `screen` | float, color3, color4 | `1 − (1 − fg)(1 − bg)` | Gaussian product moments |
//! | `overlay` | float, color3, color4 | `2 fg bg` where `bg < ½`, `1 − 2 (1 − fg)(1 − bg)` elsewhere | cubature over `fg`, `bg`, `mix` |
//! | `burn` | float, color3, color4 | `1 − (1 − bg)/fg`; the whole node is 0 where `|fg| < 1e-8` | cubature |
//! | `dodge` | float, color3, color4 | `bg/(1 − fg)`; the whole node is 0 where `|1 − fg| < 1e-8` | cubature |
//! | `over` | color4 | `fg + bg (1 − fg.a)` | Gaussian product moments |
//! | `in` | color4 | `fg · bg.a` | Gaussian product moments |
//! | `mask` | color4 | `bg · fg.a` | Gaussian product moments |
//! | `out` | color4 | `fg (1 − bg.a)` | Gaussian product moments |
//! | `matte` | color4 | colour `fg·fg.a + bg (1 − fg.a)`, alpha `fg.a + bg.a (1 − fg.a)` | as the final mix, with `fg.a` as the mix |
//! | `disjointover` | color4 | colour `fg + bg` where `fg.a + bg.a ≤ 1`, else `fg + bg (1 − fg.a)/bg.a` (0 where `|bg.a| < 1e-8`); alpha `min(fg.a + bg.a, 1)` | cubature |
//! | `inside` (`mask` 1), `outside` (`mask` 0) | float, color3, color4 | `in · mask`, `in · (1 − mask)` (no `mix`) | Gaussian product moments |
//! | `premult`, `unpremult` | color4 | `(in.rgb · in.a, in.a)`, `(in.rgb / in.a, in.a)` (`in` = 0, 0, 0, 1) | product moments; the division exact for a uniform alpha, cubature otherwise; 0 where `in.a = 0` (GLSL's is undefined there) |
//!
//! The thresholds and the per-channel treatment of color4 alpha follow MaterialX's GLSL
//! implementations: the blends treat alpha as a fourth channel, the Porter–Duff operators
//! combine it as their definitions say.

use super::{inp, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::Source;
use crate::moments::{add_scaled, affine, cov, mix, mul, nary, recip, safe_div};
use crate::value::{Filtered, Moments, ValueType};

pub(crate) const CATEGORIES: &[&str] = &[
    "plus",
    "minus",
    "difference",
    "burn",
    "dodge",
    "screen",
    "overlay",
    "disjointover",
    "in",
    "mask",
    "matte",
    "out",
    "over",
    "inside",
    "outside",
    "premult",
    "unpremult",
];

/// Compositing operations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CompositeOp {
    /// `plus`
    Plus,
    /// `minus`
    Minus,
    /// `difference`
    Difference,
    /// `burn`
    Burn,
    /// `dodge`
    Dodge,
    /// `screen`
    Screen,
    /// `overlay`
    Overlay,
    /// `disjointover`
    DisjointOver,
    /// `in`
    In,
    /// `mask`
    Mask,
    /// `matte`
    Matte,
    /// `out`
    Out,
    /// `over`
    Over,
    /// `inside`
    Inside,
    /// `outside`
    Outside,
    /// `premult`
    Premult,
    /// `unpremult`
    Unpremult,
}

/// MaterialX's `M_FLOAT_EPS`, below which `burn`, `dodge` and `disjointover` do not divide.
const EPS: f64 = 1e-8;

fn float_or_color(t: ValueType) -> bool {
    matches!(t, ValueType::Float | ValueType::Color3 | ValueType::Color4)
}

fn color4(t: ValueType) -> bool {
    t == ValueType::Color4
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    const BLEND: &[super::InputSpec] = &[inp!("fg", Out, Zero), inp!("bg", Out, Zero), inp!("mix", Float, One)];
    let (inputs, types): (&'static [_], fn(ValueType) -> bool) = match category {
        "plus" | "minus" | "difference" | "burn" | "dodge" | "screen" | "overlay" => (BLEND, float_or_color),
        "disjointover" | "in" | "mask" | "matte" | "out" | "over" => (BLEND, color4),
        "inside" => (&[inp!("in", Out, Zero), inp!("mask", Float, One)], float_or_color),
        "outside" => (&[inp!("in", Out, Zero), inp!("mask", Float, Zero)], float_or_color),
        "premult" | "unpremult" => (&[inp!("in", Out, Quad(0.0, 0.0, 0.0, 1.0))], color4),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types, build })
}

fn build(category: &str, _: ValueType, _: &[ValueType], _: &[Source], _: &[Param]) -> Result<Op, String> {
    use CompositeOp::*;
    Ok(Op::Composite(match category {
        "plus" => Plus,
        "minus" => Minus,
        "difference" => Difference,
        "burn" => Burn,
        "dodge" => Dodge,
        "screen" => Screen,
        "overlay" => Overlay,
        "disjointover" => DisjointOver,
        "in" => In,
        "mask" => Mask,
        "matte" => Matte,
        "out" => Out,
        "over" => Over,
        "inside" => Inside,
        "outside" => Outside,
        "premult" => Premult,
        _ => Unpremult,
    }))
}

/// `b + t (r − b)` for a `t` independent of `b` and `r`. Its variance takes
/// `Cov(b, t (r − b)) = E[t] (Cov(b, r) − Var b)`: `Var b` is known, where an estimate from
/// gradients alone (the `mix` node's rule) misses it once the footprint is wide enough to
/// flatten `b`'s mean. Exact for a uniform `t`.
fn lerp(b: Moments, r: Moments, t: Moments, fp: &crate::value::Footprint) -> Moments {
    let td = mul(add_scaled(r, b, -1.0, fp), t, fp);
    let var = b.var + td.var + 2.0 * t.mean * (cov(&b, &r, fp) - b.var);
    let out = Moments { mean: b.mean + td.mean, grad: b.grad + td.grad, var: var.max(0.0) };
    if (out.mean + out.grad.x + out.grad.y + out.var).is_finite() {
        out
    } else {
        mix(b, r, t, fp)
    }
}

#[inline]
fn uniform(m: &Moments) -> bool {
    m.var == 0.0 && m.grad == glam::Vec2::ZERO
}

/// The point functions of the blends that are evaluated by cubature: `(fg, bg, mix)`.
fn burn_point(f: f64, b: f64, t: f64) -> f64 {
    if f.abs() < EPS {
        0.0
    } else {
        t * (1.0 - safe_div(1.0 - b, f)) + (1.0 - t) * b
    }
}

fn dodge_point(f: f64, b: f64, t: f64) -> f64 {
    if (1.0 - f).abs() < EPS {
        0.0
    } else {
        t * safe_div(b, 1.0 - f) + (1.0 - t) * b
    }
}

fn overlay_point(f: f64, b: f64, t: f64) -> f64 {
    let r = if b >= 0.5 { 1.0 - 2.0 * (1.0 - b) * (1.0 - f) } else { 2.0 * f * b };
    b + (r - b) * t
}

/// `disjointover`'s channel `k` from `(fg_k, bg_k, fg.a, bg.a, mix)`.
fn disjointover_point(p: &[f64], alpha: bool) -> f64 {
    let (f, b, fa, ba, t) = (p[0], p[1], p[2], p[3], p[4]);
    let sum = fa + ba;
    let r = if alpha {
        sum.min(1.0)
    } else if sum <= 1.0 {
        f + b
    } else if ba.abs() < EPS {
        0.0
    } else {
        f + b * safe_div(1.0 - fa, ba)
    };
    r * t + (1.0 - t) * b
}

pub(crate) fn eval(op: &CompositeOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    use CompositeOp::*;
    let fp = ctx.fp;
    let n = ty.channels();
    let mut out = Filtered::zero(ty);
    match op {
        Inside | Outside => {
            let m = if *op == Outside { affine(ins[1].ch[0], -1.0, 1.0) } else { ins[1].ch[0] };
            for k in 0..n {
                out.ch[k] = mul(ins[0].ch[k], m, fp);
            }
        }
        Premult | Unpremult => {
            let a = ins[0].ch[3];
            for k in 0..3 {
                let c = ins[0].ch[k];
                out.ch[k] = match op {
                    Premult => mul(c, a, fp),
                    _ if uniform(&a) => affine(c, recip(a.mean), 0.0),
                    _ => nary(&[c, a], |p| safe_div(p[0], p[1])),
                };
            }
            out.ch[3] = a;
        }
        _ => {
            let (fg, bg, t) = (&ins[0], &ins[1], ins[2].ch[0]);
            let (fa, ba) = (fg.ch[3], bg.ch[3]);
            let one_minus = |x: Moments| affine(x, -1.0, 1.0);
            for k in 0..n {
                let (f, b) = (fg.ch[k], bg.ch[k]);
                // The blend `r` itself, then mixed with bg: written as `bg + mix (r − bg)` the
                // variance would need the covariance of bg and r, which only gradients estimate.
                let r = match op {
                    Plus => add_scaled(b, f, 1.0, fp),
                    Minus => add_scaled(b, f, -1.0, fp),
                    Difference => super::math::absval(add_scaled(b, f, -1.0, fp)),
                    Screen => one_minus(mul(one_minus(f), one_minus(b), fp)),
                    Over => add_scaled(f, mul(b, one_minus(fa), fp), 1.0, fp),
                    In => mul(f, ba, fp),
                    Mask => mul(b, fa, fp),
                    Out => mul(f, one_minus(ba), fp),
                    // Colour: fg over bg by fg's alpha; alpha: bg.a + fg.a (1 − bg.a).
                    Matte if k < 3 => lerp(b, f, fa, fp),
                    Matte => lerp(ba, Moments::constant(1.0), fa, fp),
                    // These include the mix in their point functions (burn and dodge give 0 at
                    // their poles, mix or not).
                    Burn => nary(&[f, b, t], |p| burn_point(p[0], p[1], p[2])),
                    Dodge => nary(&[f, b, t], |p| dodge_point(p[0], p[1], p[2])),
                    Overlay => nary(&[f, b, t], |p| overlay_point(p[0], p[1], p[2])),
                    DisjointOver => nary(&[f, b, fa, ba, t], |p| disjointover_point(p, k == 3)),
                    Inside | Outside | Premult | Unpremult => unreachable!("evaluated above"),
                };
                out.ch[k] = match op {
                    Burn | Dodge | Overlay | DisjointOver => r,
                    _ if uniform(&t) && t.mean == 1.0 => r,
                    _ if uniform(&t) && t.mean == 0.0 => b,
                    _ => lerp(b, r, t, fp),
                };
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blends equal MaterialX's own formulas, `mix·r + (1 − mix)·bg`, at points.
    #[test]
    fn rearranged_blends_match_the_definitions() {
        use crate::value::Footprint;
        use glam::Vec2;
        let fp = Footprint::point(Vec2::ZERO);
        let mut work = crate::eval::Work::default();
        let vals = [-0.7f32, 0.0, 0.3, 0.5, 0.9, 1.0, 1.6];
        for &f in &vals {
            for &b in &vals {
                for &t in &[0.0f32, 0.4, 1.0] {
                    for &fa in &[0.0f32, 0.35, 1.0] {
                        for &ba in &[0.0f32, 0.8, 1.0] {
                            let fg = Filtered::constant(crate::value::Value::new(ValueType::Color4, &[f, f, f, fa]));
                            let bg = Filtered::constant(crate::value::Value::new(ValueType::Color4, &[b, b, b, ba]));
                            let mx = Filtered::constant(crate::value::Value::float(t));
                            let (f, b, t, fa, ba) = (f as f64, b as f64, t as f64, fa as f64, ba as f64);
                            let def = |r: f64, bg: f64| t * r + (1.0 - t) * bg;
                            let want: [(CompositeOp, [f64; 4]); 7] = [
                                (CompositeOp::Plus, [def(b + f, b), 0.0, 0.0, def(ba + fa, ba)]),
                                (CompositeOp::Minus, [def(b - f, b), 0.0, 0.0, def(ba - fa, ba)]),
                                (CompositeOp::Difference, [def((b - f).abs(), b), 0.0, 0.0, def((ba - fa).abs(), ba)]),
                                (CompositeOp::Screen, [def(1.0 - (1.0 - f) * (1.0 - b), b), 0.0, 0.0, 0.0]),
                                (
                                    CompositeOp::Over,
                                    [def(f + b * (1.0 - fa), b), 0.0, 0.0, def(fa + ba * (1.0 - fa), ba)],
                                ),
                                (CompositeOp::In, [def(f * ba, b), 0.0, 0.0, def(fa * ba, ba)]),
                                (
                                    CompositeOp::Matte,
                                    [def(f * fa + b * (1.0 - fa), b), 0.0, 0.0, def(fa + ba * (1.0 - fa), ba)],
                                ),
                            ];
                            for (op, w) in want {
                                let mut ctx = Ctx { fp: &fp, point: true, work: &mut work };
                                let got = eval(&op, ValueType::Color4, &[fg, bg, mx], &mut ctx);
                                for k in [0, 3] {
                                    if op == CompositeOp::Screen && k == 3 {
                                        continue;
                                    }
                                    let g = got.ch[k].mean as f64;
                                    assert!((g - w[k]).abs() < 1e-5, "{op:?} ch{k}: {g} vs {}", w[k]);
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}
