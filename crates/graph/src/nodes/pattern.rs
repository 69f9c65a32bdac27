//! Shapes, ramps, splits and random values: `checkerboard`, `ramplr`, `ramptb`, `ramp4`,
//! `splitlr`, `splittb`, `randomfloat`, `randomcolor`.
//!
//! | node | inputs (default) | unfiltered | filtered evaluation |
//! |---|---|---|---|
//! | `checkerboard` | `color1` (1,1,1), `color2` (0,0,0), `uvtiling` (8,8), `uvoffset` (0,0), `texcoord` (UV0) | `color1` where `floor(u')+floor(v')` is odd, `color2` where even; `u' = t·tiling − offset` | product of the two axes' square-wave expectations (step masses for σ < 0.4 cells, damped Fourier series above; nothing evaluated above 3.5 cells); exact for axis-aligned footprints |
//! | `ramplr` / `ramptb` | `valuel`,`valuer` / `valuet`,`valueb` (0), `texcoord` | `mix(l, r, clamp(u, 0, 1))` / `mix(b, t, clamp(v, 0, 1))` | closed-form moments of the clamped coordinate (piecewise polynomial × Gaussian) |
//! | `ramp4` | `valuetl`,`valuetr`,`valuebl`,`valuebr` (0), `texcoord` | bilinear in the clamped coordinates | as the ramps, per axis |
//! | `splitlr` / `splittb` | `valuel`,`valuer` / `valuet`,`valueb` (0), `center` (0.5), `texcoord` | `valuer` where `u ≥ center` / `valuet` where `v ≥ center` | the footprint's mass beyond the split, `Φ((m − c)/σ)` |
//! | `randomfloat` | `in` (0), `min` (0), `max` (1), `seed` (0) | cell noise of `(in, seed)` mapped to `[min, max]` | evaluated at the mean of `in` (a per-object value, normally uniform) |
//! | `randomcolor` | `in` (0), `huelow` (0), `huehigh` (1), `saturationlow` (0), `saturationhigh` (1), `brightnesslow` (0), `brightnesshigh` (1), `seed` (0) | HSV from three cell-noise values of `(in, seed + k)` | as `randomfloat` |

use super::hash::cell_float;
use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::gaussian::{self, poly, Piece};
use crate::graph::Source;
use crate::moments::{self, affine, chain, mix};
use crate::value::{Filtered, Moments, ValueType};
use glam::Vec2;

pub(crate) const CATEGORIES: &[&str] =
    &["checkerboard", "ramplr", "ramptb", "ramp4", "splitlr", "splittb", "randomfloat", "randomcolor"];

/// Pattern operations.
#[derive(Debug)]
pub enum PatternOp {
    /// `checkerboard`
    Checkerboard,
    /// `ramplr`
    RampLr,
    /// `ramptb`
    RampTb,
    /// `ramp4`
    Ramp4,
    /// `splitlr`
    SplitLr,
    /// `splittb`
    SplitTb,
    /// `randomfloat`
    RandomFloat,
    /// `randomcolor`
    RandomColor,
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let (inputs, types): (&'static [_], fn(ValueType) -> bool) = match category {
        "checkerboard" => (
            &[
                inp!("color1", C3, One),
                inp!("color2", C3, Zero),
                inp!("uvtiling", V2, Pair(8.0, 8.0)),
                inp!("uvoffset", V2, Zero),
                inp!("texcoord", V2, Uv),
            ],
            types::color3,
        ),
        "ramplr" => {
            (&[inp!("valuel", Out, Zero), inp!("valuer", Out, Zero), inp!("texcoord", V2, Uv)], types::float_or_vector)
        }
        "ramptb" => {
            (&[inp!("valuet", Out, Zero), inp!("valueb", Out, Zero), inp!("texcoord", V2, Uv)], types::float_or_vector)
        }
        "ramp4" => (
            &[
                inp!("valuetl", Out, Zero),
                inp!("valuetr", Out, Zero),
                inp!("valuebl", Out, Zero),
                inp!("valuebr", Out, Zero),
                inp!("texcoord", V2, Uv),
            ],
            types::float_or_vector,
        ),
        "splitlr" => (
            &[
                inp!("valuel", Out, Zero),
                inp!("valuer", Out, Zero),
                inp!("center", Float, Half),
                inp!("texcoord", V2, Uv),
            ],
            types::float_or_vector,
        ),
        "splittb" => (
            &[
                inp!("valuet", Out, Zero),
                inp!("valueb", Out, Zero),
                inp!("center", Float, Half),
                inp!("texcoord", V2, Uv),
            ],
            types::float_or_vector,
        ),
        "randomfloat" => (
            &[inp!("in", Scalar, Zero), inp!("min", Float, Zero), inp!("max", Float, One), inp!("seed", Int, Zero)],
            types::float,
        ),
        "randomcolor" => (
            &[
                inp!("in", Scalar, Zero),
                inp!("huelow", Float, Zero),
                inp!("huehigh", Float, One),
                inp!("saturationlow", Float, Zero),
                inp!("saturationhigh", Float, One),
                inp!("brightnesslow", Float, Zero),
                inp!("brightnesshigh", Float, One),
                inp!("seed", Int, Zero),
            ],
            types::color3,
        ),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types, build })
}

fn build(category: &str, _: ValueType, _: &[ValueType], _: &[Source], _: &[Param]) -> Result<Op, String> {
    Ok(Op::Pattern(match category {
        "checkerboard" => PatternOp::Checkerboard,
        "ramplr" => PatternOp::RampLr,
        "ramptb" => PatternOp::RampTb,
        "ramp4" => PatternOp::Ramp4,
        "splitlr" => PatternOp::SplitLr,
        "splittb" => PatternOp::SplitTb,
        "randomfloat" => PatternOp::RandomFloat,
        _ => PatternOp::RandomColor,
    }))
}

/// Moments of `clamp(x, 0, 1)`.
pub(crate) fn clamp01(x: Moments) -> Moments {
    let pieces = [
        Piece { lo: f64::NEG_INFINITY, hi: 0.0, p: poly(&[0.0]) },
        Piece { lo: 0.0, hi: 1.0, p: poly(&[0.0, 1.0]) },
        Piece { lo: 1.0, hi: f64::INFINITY, p: poly(&[1.0]) },
    ];
    chain(x, gaussian::piecewise_moments(&pieces, x.mean as f64, x.sigma() as f64))
}

/// Moments of the step `1{x ≥ c}`.
pub(crate) fn step(c: f32, x: Moments) -> Moments {
    chain(x, gaussian::step_moments(c as f64, x.mean as f64, x.sigma() as f64))
}

/// Per channel `mix(a, b, t)`.
fn mix_all(ty: ValueType, a: &Filtered, b: &Filtered, t: Moments, ctx: &Ctx) -> Filtered {
    let mut out = Filtered::zero(ty);
    for k in 0..ty.channels() {
        out.ch[k] = mix(a.at(k), b.at(k), t, ctx.fp);
    }
    out
}

fn checker_weight(ins: &[Filtered], ctx: &mut Ctx) -> Moments {
    let t = &ins[4];
    let u = affine(t.ch[0], ins[2].ch[0].mean, -ins[3].ch[0].mean);
    let v = affine(t.ch[1], ins[2].ch[1].mean, -ins[3].ch[1].mean);
    let (eu, du) = gaussian::square_wave_expectation(u.mean as f64, u.sigma() as f64);
    let (ev, dv) = gaussian::square_wave_expectation(v.mean as f64, v.sigma() as f64);
    ctx.work.lattice += 1;
    let s = eu * ev;
    // P(odd cell) = (1 − S)/2, a Bernoulli variable.
    let p = (1.0 - s) / 2.0;
    let ds = u.grad * (du * ev) as f32 + v.grad * (eu * dv) as f32;
    Moments { mean: p as f32, grad: -ds * 0.5, var: (p * (1.0 - p)).max(0.0) as f32 }
}

/// Unfiltered randomfloat's unit value: MaterialX cell noise at `(in, seed)`.
fn random01(x: f32, seed: f32) -> f32 {
    cell_float(x.floor() as i32, seed.floor() as i32)
}

pub(crate) fn eval(op: &PatternOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let n = ty.channels();
    let mut out = match op {
        PatternOp::Checkerboard => {
            // MaterialX puts color1 on cells with odd floor(u') + floor(v') (checked against
            // its bakes: the cell at the uv origin is color2).
            let w = checker_weight(ins, ctx);
            mix_all(ty, &ins[1], &ins[0], w, ctx)
        }
        PatternOp::RampLr => {
            let t = clamp01(ins[2].ch[0]);
            mix_all(ty, &ins[0], &ins[1], t, ctx)
        }
        PatternOp::RampTb => {
            let t = clamp01(ins[2].ch[1]);
            mix_all(ty, &ins[1], &ins[0], t, ctx)
        }
        PatternOp::Ramp4 => {
            let s = clamp01(ins[4].ch[0]);
            let t = clamp01(ins[4].ch[1]);
            let top = mix_all(ty, &ins[0], &ins[1], s, ctx);
            let bottom = mix_all(ty, &ins[2], &ins[3], s, ctx);
            mix_all(ty, &bottom, &top, t, ctx)
        }
        PatternOp::SplitLr => {
            let t = step(ins[2].ch[0].mean, ins[3].ch[0]);
            mix_all(ty, &ins[0], &ins[1], t, ctx)
        }
        PatternOp::SplitTb => {
            let t = step(ins[2].ch[0].mean, ins[3].ch[1]);
            mix_all(ty, &ins[1], &ins[0], t, ctx)
        }
        PatternOp::RandomFloat => {
            let (x, lo, hi, seed) = (ins[0].ch[0].mean, ins[1].ch[0], ins[2].ch[0], ins[3].ch[0].mean);
            let r = Moments::constant(random01(x, seed));
            let mut o = Filtered::zero(ty);
            o.ch[0] = mix(lo, hi, r, ctx.fp);
            o
        }
        PatternOp::RandomColor => {
            let x = ins[0].ch[0].mean;
            let seed = ins[7].ch[0].mean;
            let h = mix(ins[1].ch[0], ins[2].ch[0], Moments::constant(random01(x, seed)), ctx.fp);
            let s = mix(ins[3].ch[0], ins[4].ch[0], Moments::constant(random01(x, seed + 1.0)), ctx.fp);
            let v = mix(ins[5].ch[0], ins[6].ch[0], Moments::constant(random01(x, seed + 2.0)), ctx.fp);
            let mut o = Filtered::zero(ty);
            for k in 0..3 {
                o.ch[k] = moments::nary(&[h, s, v], |p| super::color::hsv_to_rgb([p[0], p[1], p[2]])[k]);
            }
            o
        }
    };
    for c in out.ch.iter_mut().skip(n) {
        *c = Moments::default();
    }
    if ctx.point {
        for c in out.ch.iter_mut() {
            c.grad = Vec2::ZERO;
        }
    }
    out
}
