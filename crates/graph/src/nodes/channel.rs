//! Channel nodes: `combine2`, `combine3`, `combine4`, `extract`, `separate2`, `separate3`,
//! `separate4`, `convert`. All are exact (they only move channels), except `convert` of an
//! integer to a boolean.
//!
//! | node | inputs (default) | output |
//! |---|---|---|
//! | `combineN` | `in1` … `inN` (0); inputs may be vectors (`combine2` of a color3 and a float gives a color4) | channels concatenated |
//! | `extract` | `in` (0), `index` (0) | channel `index` |
//! | `separateN` | `in` (0) | multi-output: `outx`/`outr`, `outy`/`outg`, ... (a connection picks one channel) |
//! | `convert` | `in` (0) | a float is broadcast; extra channels are 0 (alpha / w: 1); surplus channels dropped; integer to boolean is `in != 0` |

use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::Source;
use crate::value::{Filtered, Moments, ValueType};

pub(crate) const CATEGORIES: &[&str] =
    &["combine2", "combine3", "combine4", "extract", "separate2", "separate3", "separate4", "convert"];

/// Channel operations.
#[derive(Debug)]
pub enum ChannelOp {
    /// `combineN`
    Combine,
    /// `extract`
    Extract,
    /// `separateN` (the node's value is its input; connections pick channels)
    Separate,
    /// `convert`
    Convert,
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let (inputs, ty): (&'static [_], fn(ValueType) -> bool) = match category {
        "combine2" => (&[inp!("in1", Any, Zero), inp!("in2", Any, Zero)], types::multichannel),
        "combine3" => (&[inp!("in1", Any, Zero), inp!("in2", Any, Zero), inp!("in3", Any, Zero)], types::multichannel),
        "combine4" => (
            &[inp!("in1", Any, Zero), inp!("in2", Any, Zero), inp!("in3", Any, Zero), inp!("in4", Any, Zero)],
            types::multichannel,
        ),
        "extract" => (&[inp!("in", Any, Zero), inp!("index", Int, Zero)], types::float),
        "separate2" | "separate3" | "separate4" => (&[inp!("in", Out, Zero)], types::multichannel),
        "convert" => (&[inp!("in", Any, Zero)], types::numeric),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types: ty, build })
}

fn build(category: &str, ty: ValueType, tys: &[ValueType], _: &[Source], _: &[Param]) -> Result<Op, String> {
    Ok(Op::Channel(match category {
        "combine2" | "combine3" | "combine4" => {
            let total: usize = tys.iter().map(|t| t.channels()).sum();
            if total != ty.channels() {
                return Err(format!(
                    "{category} inputs carry {total} channels but the output {ty} has {}",
                    ty.channels()
                ));
            }
            ChannelOp::Combine
        }
        "extract" => ChannelOp::Extract,
        "convert" => ChannelOp::Convert,
        _ => ChannelOp::Separate,
    }))
}

/// Channel index of a multi-output name (`outx`, `outg`, ...).
pub fn output_channel(name: &str) -> Option<u8> {
    match name.strip_prefix("out")? {
        "x" | "r" => Some(0),
        "y" | "g" => Some(1),
        "z" | "b" => Some(2),
        "w" | "a" => Some(3),
        _ => None,
    }
}

pub(crate) fn eval(op: &ChannelOp, ty: ValueType, ins: &[Filtered], _ctx: &mut Ctx) -> Filtered {
    let mut out = Filtered::zero(ty);
    let n = ty.channels();
    match op {
        ChannelOp::Combine => {
            let mut k = 0;
            for i in ins {
                for c in &i.ch[..i.n()] {
                    if k < 4 {
                        out.ch[k] = *c;
                    }
                    k += 1;
                }
            }
        }
        ChannelOp::Extract => {
            let idx = (ins[1].ch[0].mean.round().max(0.0) as usize).min(ins[0].n() - 1);
            out.ch[0] = ins[0].ch[idx];
        }
        ChannelOp::Separate => out.ch = ins[0].ch,
        ChannelOp::Convert if ty == ValueType::Boolean && ins[0].ty == ValueType::Integer => {
            out.ch[0] = nonzero(ins[0].ch[0]);
        }
        ChannelOp::Convert => {
            let a = &ins[0];
            for k in 0..n {
                out.ch[k] = if a.n() == 1 {
                    a.ch[0]
                } else if k < a.n() {
                    a.ch[k]
                } else if k == 3 {
                    Moments::constant(1.0)
                } else {
                    Moments::default()
                };
            }
        }
    }
    out
}

/// An integer's `in != 0` (MaterialX's `NG_convert_integer_boolean`): at a point the plain test;
/// over a footprint, with the integer taken as `N(m, s²)` rounded, the probability that it is
/// not 0, as `ifequal` of integers does.
fn nonzero(x: Moments) -> Moments {
    let (m, s) = (x.mean as f64, x.sigma() as f64);
    if s == 0.0 {
        return Moments::constant(if x.mean != 0.0 { 1.0 } else { 0.0 });
    }
    let p = 1.0 - crate::gaussian::mass((-0.5 - m) / s, (0.5 - m) / s);
    Moments { mean: p as f32, grad: glam::Vec2::ZERO, var: (p * (1.0 - p)) as f32 }
}
