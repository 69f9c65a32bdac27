//! Colour adjustment: `luminance`, `saturate`, `contrast`, `rgbtohsv`, `hsvtorgb`, `hsvadjust`.
//! The alpha of color4 inputs passes through.
//!
//! | node | inputs (default) | filtered evaluation |
//! |---|---|---|
//! | `luminance` | `in` (0), `lumacoeffs` (0.2722287, 0.6740818, 0.0536895) | exact (linear) |
//! | `saturate` | `in` (0), `amount` (1), `lumacoeffs` (as above) | exact for uniform `amount` (linear); product moments otherwise |
//! | `contrast` | `in` (0), `amount` (1), `pivot` (0.5) | exact for uniform `amount` and `pivot` |
//! | `rgbtohsv`, `hsvtorgb` | `in` (0) | cubature over the three channels |
//! | `hsvadjust` | `in` (0), `amount` (0, 1, 1) | cubature over colour and amount |

use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::Source;
use crate::moments::{add_scaled, mix, mul, nary};
use crate::value::{Filtered, Moments, ValueType};

pub(crate) const CATEGORIES: &[&str] = &["luminance", "saturate", "contrast", "rgbtohsv", "hsvtorgb", "hsvadjust"];

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

pub(crate) fn eval(op: &ColorOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let a = &ins[0];
    let mut out = *a;
    out.ty = ty;
    match op {
        ColorOp::Luminance => {
            let l = luminance(a, &ins[1], ctx);
            out.ch[..3].fill(l);
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
