//! Colour adjustment: `luminance`, `saturate`, `contrast`, `rgbtohsv`, `hsvtorgb`, `hsvadjust`.
//! The alpha of color4 inputs passes through.
//!
//! | node | inputs (default) | filtered evaluation |
//! |---|---|---|
//! | `luminance` | `in` (0), `lumacoeffs` (0.2722287, 0.6740818, 0.0536895) | exact (linear) |
//! | `saturate` | `in` (0), `amount` (1), `lumacoeffs` (as above) | exact for uniform `amount` and coefficients (linear in the colour, each channel's covariance with its own share of the luminance kept); product moments otherwise |
//! | `contrast` | `in` (0), `amount` (1), `pivot` (0.5) | exact for uniform `amount` and `pivot` |
//! | `rgbtohsv`, `hsvtorgb` | `in` (0) | cubature over the three channels |
//! | `hsvadjust` | `in` (0), `amount` (0, 1, 1) | cubature over colour and amount |
//! | `colorcorrect` | `in` (1, 1, 1[, 0]), `hue` (0), `saturation` (1), `gamma` (1), `lift` (0), `gain` (1), `contrast` (1), `contrastpivot` (0.5), `exposure` (0) | MaterialX's graph, each step by its node's rule: `hsvadjust` by `(hue, 1, 1)` (skipped for a uniform hue of 0, where it is the identity), `saturate`, `range` by `gamma` over [0, 1], `· (1 − lift) + lift`, `· gain`, `contrast`, `· 2^exposure`; alpha passes |

use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::Source;
use crate::moments::{add_scaled, linear, mix, mul, nary};
use crate::value::{Filtered, Moments, ValueType};

pub(crate) const CATEGORIES: &[&str] =
    &["luminance", "saturate", "contrast", "rgbtohsv", "hsvtorgb", "hsvadjust", "colorcorrect"];

/// Colour operations.
#[derive(Debug)]
pub enum ColorOp {
    /// `luminance`
    Luminance,
    /// `saturate`
    Saturate,
    /// `contrast`
    Contrast,
    /// `rgbtohsv`
    RgbToHsv,
    /// `hsvtorgb`
    HsvToRgb,
    /// `hsvadjust`
    HsvAdjust,
    /// `colorcorrect`
    ColorCorrect,
}

const LUMA: Def = Def::Triple(0.272_228_7, 0.674_081_8, 0.053_689_5);

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let (inputs, ty): (&'static [_], fn(ValueType) -> bool) = match category {
        "luminance" => (&[inp!("in", Out, Zero), inp!("lumacoeffs", C3, LUMA)], types::color),
        "saturate" => {
            (&[inp!("in", Out, Zero), inp!("amount", Float, One), inp!("lumacoeffs", C3, LUMA)], types::color)
        }
        "contrast" => {
            (&[inp!("in", Out, Zero), inp!("amount", OutOrFloat, One), inp!("pivot", OutOrFloat, Half)], types::numeric)
        }
        "rgbtohsv" | "hsvtorgb" => (&[inp!("in", Out, Zero)], types::color),
        "hsvadjust" => (&[inp!("in", Out, Zero), inp!("amount", V3, Triple(0.0, 1.0, 1.0))], types::color),
        "colorcorrect" => (
            &[
                inp!("in", Out, Quad(1.0, 1.0, 1.0, 0.0)),
                inp!("hue", Float, Zero),
                inp!("saturation", Float, One),
                inp!("gamma", Float, One),
                inp!("lift", Float, Zero),
                inp!("gain", Float, One),
                inp!("contrast", Float, One),
                inp!("contrastpivot", Float, Half),
                inp!("exposure", Float, Zero),
            ],
            types::color,
        ),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types: ty, build })
}

fn build(category: &str, _: ValueType, _: &[ValueType], _: &[Source], _: &[Param]) -> Result<Op, String> {
    Ok(Op::Color(match category {
        "luminance" => ColorOp::Luminance,
        "saturate" => ColorOp::Saturate,
        "contrast" => ColorOp::Contrast,
        "rgbtohsv" => ColorOp::RgbToHsv,
        "hsvtorgb" => ColorOp::HsvToRgb,
        "colorcorrect" => ColorOp::ColorCorrect,
        _ => ColorOp::HsvAdjust,
    }))
}

/// HSV (all in [0, 1]) to RGB, as MaterialX (after Foley & van Dam).
pub fn hsv_to_rgb(hsv: [f64; 3]) -> [f64; 3] {
    let [h, s, v] = hsv;
    if s < 0.0001 {
        return [v, v, v];
    }
    let h = 6.0 * (h - h.floor());
    let hi = h.trunc();
    let f = h - hi;
    let p = v * (1.0 - s);
    let q = v * (1.0 - s * f);
    let t = v * (1.0 - s * (1.0 - f));
    match hi as i32 {
        0 => [v, t, p],
        1 => [q, v, p],
        2 => [p, v, t],
        3 => [p, q, v],
        4 => [t, p, v],
        _ => [v, p, q],
    }
}

/// RGB to HSV, as MaterialX.
pub fn rgb_to_hsv(c: [f64; 3]) -> [f64; 3] {
    let [r, g, b] = c;
    let lo = r.min(g.min(b));
    let hi = r.max(g.max(b));
    let delta = hi - lo;
    let s = if hi > 0.0 { delta / hi } else { 0.0 };
    let mut h = 0.0;
    if s > 0.0 {
        h = if r >= hi {
            (g - b) / delta
        } else if g >= hi {
            2.0 + (b - r) / delta
        } else {
            4.0 + (r - g) / delta
        };
        h /= 6.0;
        if h < 0.0 {
            h += 1.0;
        }
    }
    [h, s, hi]
}

fn luminance(c: &Filtered, w: &Filtered, ctx: &Ctx) -> Moments {
    let mut l = Moments::default();
    for k in 0..3 {
        l = add_scaled(l, mul(c.ch[k], w.ch[k], ctx.fp), 1.0, ctx.fp);
    }
    l
}

/// `colorcorrect`'s colour, as MaterialX's graph composes it from other nodes.
fn color_correct(ins: &[Filtered], ctx: &mut Ctx) -> [Moments; 3] {
    use super::math::{eval as math, MathOp};
    use ValueType::{Color3, Float};
    let c = |x: f32| Filtered::constant(crate::value::Value::float(x));
    let (hue, sat, gamma, lift, gain, contrast, pivot, exposure) =
        (ins[1], ins[2], ins[3], ins[4], ins[5], ins[6], ins[7], ins[8]);
    let mut x = Filtered { ty: Color3, ch: [ins[0].ch[0], ins[0].ch[1], ins[0].ch[2], Moments::default()] };
    if !(hue.is_uniform() && hue.ch[0].mean == 0.0) {
        let one = Moments::constant(1.0);
        let amount = Filtered { ty: ValueType::Vector3, ch: [hue.ch[0], one, one, Moments::default()] };
        x = eval(&ColorOp::HsvAdjust, Color3, &[x, amount], ctx);
    }
    let luma = Filtered::constant(crate::value::Value::new(Color3, &[0.272_228_7, 0.674_081_8, 0.053_689_5]));
    x = eval(&ColorOp::Saturate, Color3, &[x, sat, luma], ctx);
    let no = Filtered::constant(crate::value::Value::new(ValueType::Boolean, &[0.0]));
    x = math(&MathOp::Range, Color3, &[x, c(0.0), c(1.0), gamma, c(0.0), c(1.0), no], ctx);
    let keep = math(&MathOp::Subtract, Float, &[c(1.0), lift], ctx);
    x = math(&MathOp::Multiply, Color3, &[x, keep], ctx);
    x = math(&MathOp::Add, Color3, &[x, lift], ctx);
    x = math(&MathOp::Multiply, Color3, &[x, gain], ctx);
    x = eval(&ColorOp::Contrast, Color3, &[x, contrast, pivot], ctx);
    let scale = math(&MathOp::Power, Float, &[c(2.0), exposure], ctx);
    x = math(&MathOp::Multiply, Color3, &[x, scale], ctx);
    [x.ch[0], x.ch[1], x.ch[2]]
}

pub(crate) fn eval(op: &ColorOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let a = &ins[0];
    let mut out = *a;
    out.ty = ty;
    match op {
        ColorOp::Luminance => {
            let l = luminance(a, &ins[1], ctx);
            out.ch[..3].fill(l);
        }
        ColorOp::Saturate if ins[1].is_uniform() && ins[2].is_uniform() => {
            // Channel k is linear in the colour, `Σⱼ ((1 − s) wⱼ + s δⱼₖ) cⱼ`: summed as such, the
            // channel's own share of the luminance keeps its covariance with the channel.
            // The weights in f64, saturated (the overflow rule): a huge amount times huge
            // coefficients would otherwise make infinite weights of opposite signs, whose sum
            // is NaN.
            let s = ins[1].ch[0].mean as f64;
            for k in 0..3 {
                let w =
                    |j: usize| crate::moments::sat((1.0 - s) * ins[2].ch[j].mean as f64 + if j == k { s } else { 0.0 });
                out.ch[k] = linear(&[w(0), w(1), w(2)], &a.ch[..3], ctx.fp);
            }
        }
        ColorOp::Saturate => {
            let l = luminance(a, &ins[2], ctx);
            for k in 0..3 {
                out.ch[k] = mix(l, a.ch[k], ins[1].ch[0], ctx.fp);
            }
        }
        ColorOp::Contrast => {
            for k in 0..ty.channels() {
                let (amt, piv) = (ins[1].at(k), ins[2].at(k));
                let d = add_scaled(a.ch[k], piv, -1.0, ctx.fp);
                out.ch[k] = add_scaled(mul(d, amt, ctx.fp), piv, 1.0, ctx.fp);
            }
        }
        ColorOp::RgbToHsv | ColorOp::HsvToRgb => {
            let f = if matches!(op, ColorOp::RgbToHsv) { rgb_to_hsv } else { hsv_to_rgb };
            for k in 0..3 {
                out.ch[k] = nary(&a.ch[..3], |p| f([p[0], p[1], p[2]])[k]);
            }
        }
        ColorOp::ColorCorrect => {
            let rgb = color_correct(ins, ctx);
            out.ch[..3].copy_from_slice(&rgb);
        }
        ColorOp::HsvAdjust => {
            let xs = [a.ch[0], a.ch[1], a.ch[2], ins[1].ch[0], ins[1].ch[1], ins[1].ch[2]];
            for k in 0..3 {
                out.ch[k] = nary(&xs, |p| {
                    let hsv = rgb_to_hsv([p[0], p[1], p[2]]);
                    hsv_to_rgb([hsv[0] + p[3], hsv[1] * p[4], hsv[2] * p[5]])[k]
                });
            }
        }
    }
    out
}
