//! Math and conditional nodes, per channel (a float second operand is broadcast).
//!
//! | node | inputs (default) | filtered evaluation |
//! |---|---|---|
//! | `add`, `subtract` | `in1` (0), `in2` (0) | exact (covariance of the operands from their gradients) |
//! | `multiply` | `in1` (0), `in2` (1) | exact for a uniform factor; Gaussian product moments otherwise |
//! | `divide` | `in1` (0), `in2` (1) | exact for a uniform divisor; cubature otherwise |
//! | `invert` | `in` (0), `amount` (1) | exact (`amount − in`) |
//! | `remap` | `in` (0), `inlow` (0), `inhigh` (1), `outlow` (0), `outhigh` (1) | exact for uniform ranges; cubature otherwise |
//! | `range` | `in`, `inlow` (0), `inhigh` (1), `gamma` (1), `outlow` (0), `outhigh` (1), `doclamp` (false) | Gauss–Hermite on the remapped value (exact when `gamma` = 1 and no clamp) |
//! | `absval`, `clamp`, `min`, `max` (uniform bound), `smoothstep` (uniform edges) | `in`/`in1`, bounds | closed form: piecewise polynomial × Gaussian |
//! | `min`, `max` (two varying operands) | `in1`, `in2` (0) | Clark's max of two Gaussians |
//! | `floor`, `ceil`, `round`, `fract`, `modulo` | `in`/`in1`, `in2` (1) | closed form: step masses (σ < 0.4 periods) or damped Fourier series of the sawtooth |
//! | `sign` | `in` (0) | `2Φ(m/σ) − 1` |
//! | `sin`, `cos` | `in` (0) | closed form (`e^{−σ²/2}` damping) |
//! | `trianglewave` (float) | `in` (0) | `0.5 − |mod(|x|, 1) − 0.5|`: closed form (linear pieces under the Gaussian below 0.4 periods, damped Fourier series above) |
//! | `exp` | `in` (0) | closed form (log-normal) |
//! | `sqrt`, `ln` (`in` = 1), `power` (`in2` = 1), `tan`, `asin`, `acos` | | 5-point Gauss–Hermite (uniform exponent), cubature otherwise, on the total point functions: `sqrt` of a negative is 0, `ln` of x ≤ 0 is ln 1e-30, `asin`/`acos` clamp to [−1, 1], `power` is OSL's `safe_pow` (x⁰ = 1, 0ʸ = 0, a negative base with a fractional exponent 0) |
//! | `atan2` | `iny` (0), `inx` (1) | cubature |
//! | `dotproduct`, `magnitude`, `distance`, `normalize` | vectors | exact for a uniform operand of `dotproduct`; cubature otherwise |
//! | `and`, `or`, `xor`, `not` | booleans `in1`, `in2` (false) / `in` (false) | a boolean's mean is the probability that it is true over the footprint; the operands are taken as independent: `p1 p2`, `p1 + p2 − p1 p2`, `p1 + p2 − 2 p1 p2`, `1 − p` (exact at points) |
//! | `ifgreater`, `ifgreatereq`, `ifequal` | `value1` (1), `value2` (0), `in1` (0), `in2` (0) | `mix(in2, in1, P(value1 > value2))` with the probability from the difference's Gaussian; boolean variants output the probability itself |
//! | `switch` | `in1` … `in10` (0), `which` (0; float or integer) | at a point, `in1` for `which < 1`, `in2` for `which < 2`, …, `in10` for `which < 10`, 0 from 10 on (MaterialX's `NG_switch`); over a footprint, the mixture `Σ P_k in_k` with `P_k` the Gaussian mass of `which` in the k-th interval, and the mixture's variance |
//!
//! Cubature and Hermite rules treat channels as Gaussian and independent; at Σ = 0 every rule
//! reduces to the plain function of the inputs. Division by zero (`divide`, `modulo`, `remap`
//! and `range` with equal bounds) is 0, as in OSL; values beyond the f32 range saturate.

use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::gaussian::{self, poly, poly_shift_scale, Piece};
use crate::graph::Source;
use crate::moments::{
    add_scaled, affine, chain, frac_moments, mix, mul, nary, safe_div, sat, sat64, scale_grad, tri_moments, unary,
};
use crate::value::{Filtered, Footprint, Moments, ValueType};
use glam::Vec2;

pub(crate) const CATEGORIES: &[&str] = &[
    "add",
    "subtract",
    "multiply",
    "divide",
    "modulo",
    "fract",
    "invert",
    "absval",
    "sign",
    "floor",
    "ceil",
    "round",
    "power",
    "safepower",
    "sin",
    "cos",
    "tan",
    "asin",
    "acos",
    "atan2",
    "sqrt",
    "ln",
    "exp",
    "clamp",
    "min",
    "max",
    "smoothstep",
    "remap",
    "and",
    "or",
    "xor",
    "not",
    "range",
    "mix",
    "dotproduct",
    "magnitude",
    "distance",
    "normalize",
    "ifgreater",
    "ifgreatereq",
    "switch",
    "ifequal",
    "trianglewave",
];

/// Math operations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MathOp {
    /// add
    Add,
    /// subtract
    Subtract,
    /// multiply
    Multiply,
    /// divide
    Divide,
    /// modulo
    Modulo,
    /// fract
    Fract,
    /// invert
    Invert,
    /// absval
    Absval,
    /// sign
    Sign,
    /// floor
    Floor,
    /// ceil
    Ceil,
    /// round
    Round,
    /// power
    Power,
    /// safepower
    SafePower,
    /// sin
    Sin,
    /// cos
    Cos,
    /// tan
    Tan,
    /// asin
    Asin,
    /// acos
    Acos,
    /// atan2
    Atan2,
    /// sqrt
    Sqrt,
    /// ln
    Ln,
    /// exp
    Exp,
    /// clamp
    Clamp,
    /// min
    Min,
    /// max
    Max,
    /// smoothstep
    Smoothstep,
    /// remap
    Remap,
    /// range
    Range,
    /// mix
    Mix,
    /// dotproduct
    Dot,
    /// magnitude
    Magnitude,
    /// distance
    Distance,
    /// normalize
    Normalize,
    /// ifgreater
    IfGreater,
    /// switch
    Switch,
    /// ifgreatereq
    IfGreaterEq,
    /// ifequal
    IfEqual,
    /// and
    And,
    /// or
    Or,
    /// xor
    Xor,
    /// not
    Not,
    /// trianglewave
    TriangleWave,
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let unary_in: &'static [super::InputSpec] = &[inp!("in", Out, Zero)];
    let (inputs, ty): (&'static [_], fn(ValueType) -> bool) = match category {
        "add" | "subtract" | "min" | "max" => {
            (&[inp!("in1", Out, Zero), inp!("in2", OutOrFloat, Zero)], types::numeric)
        }
        "multiply" | "divide" | "modulo" | "power" | "safepower" => {
            (&[inp!("in1", Out, Zero), inp!("in2", OutOrFloat, One)], types::numeric)
        }
        // floor/ceil/round also have integer-output variants of a float input.
        "floor" | "ceil" | "round" => (&[inp!("in", OutOrFloat, Zero)], types::numeric),
        "fract" | "absval" | "sign" | "sin" | "cos" | "tan" | "asin" | "acos" | "sqrt" | "exp" | "normalize" => {
            (unary_in, types::numeric)
        }
        "ln" => (&[inp!("in", Out, One)], types::numeric),
        "trianglewave" => (unary_in, types::float),
        "invert" => (&[inp!("in", Out, Zero), inp!("amount", OutOrFloat, One)], types::numeric),
        "atan2" => (&[inp!("iny", Out, Zero), inp!("inx", Out, One)], types::numeric),
        "clamp" => {
            (&[inp!("in", Out, Zero), inp!("low", OutOrFloat, Zero), inp!("high", OutOrFloat, One)], types::numeric)
        }
        "smoothstep" => {
            (&[inp!("in", Out, Zero), inp!("low", OutOrFloat, Zero), inp!("high", OutOrFloat, One)], types::numeric)
        }
        "remap" => (
            &[
                inp!("in", Out, Zero),
                inp!("inlow", OutOrFloat, Zero),
                inp!("inhigh", OutOrFloat, One),
                inp!("outlow", OutOrFloat, Zero),
                inp!("outhigh", OutOrFloat, One),
            ],
            types::numeric,
        ),
        "range" => (
            &[
                inp!("in", Out, Zero),
                inp!("inlow", OutOrFloat, Zero),
                inp!("inhigh", OutOrFloat, One),
                inp!("gamma", OutOrFloat, One),
                inp!("outlow", OutOrFloat, Zero),
                inp!("outhigh", OutOrFloat, One),
                inp!("doclamp", Bool, Zero),
            ],
            types::numeric,
        ),
        "mix" => (&[inp!("fg", Out, Zero), inp!("bg", Out, Zero), inp!("mix", OutOrFloat, Zero)], types::numeric),
        "dotproduct" | "distance" => (&[inp!("in1", Any, Zero), inp!("in2", SameAs(0), Zero)], types::float),
        "magnitude" => (&[inp!("in", Any, Zero)], types::float),
        "and" | "or" | "xor" => (&[inp!("in1", Bool, Zero), inp!("in2", Bool, Zero)], types::boolean),
        "not" => (&[inp!("in", Bool, Zero)], types::boolean),
        "ifgreater" | "ifgreatereq" | "ifequal" => (
            &[
                inp!("value1", Scalar, One),
                inp!("value2", SameAs(0), Zero),
                inp!("in1", Out, Zero),
                inp!("in2", Out, Zero),
            ],
            types::numeric,
        ),
        "switch" => (
            &[
                inp!("in1", Out, Zero),
                inp!("in2", Out, Zero),
                inp!("in3", Out, Zero),
                inp!("in4", Out, Zero),
                inp!("in5", Out, Zero),
                inp!("in6", Out, Zero),
                inp!("in7", Out, Zero),
                inp!("in8", Out, Zero),
                inp!("in9", Out, Zero),
                inp!("in10", Out, Zero),
                inp!("which", Scalar, Zero),
            ],
            types::numeric,
        ),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types: ty, build })
}

fn build(category: &str, _: ValueType, _: &[ValueType], _: &[Source], _: &[Param]) -> Result<Op, String> {
    use MathOp::*;
    Ok(Op::Math(match category {
        "add" => Add,
        "subtract" => Subtract,
        "multiply" => Multiply,
        "divide" => Divide,
        "modulo" => Modulo,
        "fract" => Fract,
        "invert" => Invert,
        "absval" => Absval,
        "sign" => Sign,
        "floor" => Floor,
        "ceil" => Ceil,
        "round" => Round,
        "power" => Power,
        "safepower" => SafePower,
        "sin" => Sin,
        "cos" => Cos,
        "tan" => Tan,
        "asin" => Asin,
        "acos" => Acos,
        "atan2" => Atan2,
        "sqrt" => Sqrt,
        "ln" => Ln,
        "exp" => Exp,
        "clamp" => Clamp,
        "min" => Min,
        "max" => Max,
        "smoothstep" => Smoothstep,
        "remap" => Remap,
        "range" => Range,
        "mix" => Mix,
        "dotproduct" => Dot,
        "magnitude" => Magnitude,
        "distance" => Distance,
        "normalize" => Normalize,
        "ifgreater" => IfGreater,
        "switch" => Switch,
        "ifgreatereq" => IfGreaterEq,
        "and" => And,
        "or" => Or,
        "xor" => Xor,
        "not" => Not,
        "trianglewave" => TriangleWave,
        _ => IfEqual,
    }))
}

#[inline]
fn uniform(m: &Moments) -> bool {
    m.var == 0.0 && m.grad == Vec2::ZERO
}

/// `|x|`, in closed form (two linear pieces under the Gaussian).
pub(crate) fn absval(x: Moments) -> Moments {
    pieces_of(
        x,
        &[
            Piece { lo: f64::NEG_INFINITY, hi: 0.0, p: poly(&[0.0, -1.0]) },
            Piece { lo: 0.0, hi: f64::INFINITY, p: poly(&[0.0, 1.0]) },
        ],
    )
}

fn pieces_of(x: Moments, pieces: &[Piece]) -> Moments {
    chain(x, gaussian::piecewise_moments(pieces, x.mean as f64, x.sigma() as f64))
}

/// `clamp(x, lo, hi)` for uniform bounds.
fn clamp_const(x: Moments, lo: f64, hi: f64) -> Moments {
    if hi < lo {
        return Moments::constant(hi as f32);
    }
    pieces_of(
        x,
        &[
            Piece { lo: f64::NEG_INFINITY, hi: lo, p: poly(&[lo]) },
            Piece { lo, hi, p: poly(&[0.0, 1.0]) },
            Piece { lo: hi, hi: f64::INFINITY, p: poly(&[hi]) },
        ],
    )
}

/// GLSL `smoothstep(lo, hi, x)` for uniform edges.
fn smoothstep_const(x: Moments, lo: f64, hi: f64) -> Moments {
    if hi <= lo {
        return gaussian_step(x, lo);
    }
    // 3t² − 2t³ with t = (x − lo)/(hi − lo).
    let w = 1.0 / (hi - lo);
    let p = poly_shift_scale(&poly(&[0.0, 0.0, 3.0, -2.0]), -lo * w, w);
    pieces_of(x, &[Piece { lo, hi, p }, Piece { lo: hi, hi: f64::INFINITY, p: poly(&[1.0]) }])
}

fn gaussian_step(x: Moments, c: f64) -> Moments {
    chain(x, gaussian::step_moments(c, x.mean as f64, x.sigma() as f64))
}

/// `max(a, b)` of two Gaussians (Clark 1961): `b + E[max(a − b, 0)]`.
fn max2(a: Moments, b: Moments, fp: &Footprint) -> Moments {
    if uniform(&b) {
        let c = b.mean as f64;
        return pieces_of(
            a,
            &[
                Piece { lo: f64::NEG_INFINITY, hi: c, p: poly(&[c]) },
                Piece { lo: c, hi: f64::INFINITY, p: poly(&[0.0, 1.0]) },
            ],
        );
    }
    if uniform(&a) {
        return max2(b, a, fp);
    }
    let d = add_scaled(a, b, -1.0, fp);
    let relu = pieces_of(d, &[Piece { lo: 0.0, hi: f64::INFINITY, p: poly(&[0.0, 1.0]) }]);
    add_scaled(b, relu, 1.0, fp)
}

fn min2(a: Moments, b: Moments, fp: &Footprint) -> Moments {
    affine(max2(affine(a, -1.0, 0.0), affine(b, -1.0, 0.0), fp), -1.0, 0.0)
}

fn floor_of(x: Moments) -> Moments {
    let (m, s) = (x.mean as f64, x.sigma() as f64);
    let f = frac_moments(m, s);
    // floor = x − frac; Var ≈ s² + Var[frac] − 2 Cov(x, frac), Cov(x, frac) = s² E[frac'] (Stein):
    // 0 exactly for a footprint inside one cell.
    let var = (s * s + f.var - 2.0 * s * s * f.dmean).max(0.0);
    Moments { mean: f.floor as f32, grad: x.grad * (1.0 - f.dmean) as f32, var: var as f32 }
}

fn fract_of(x: Moments) -> Moments {
    let f = frac_moments(x.mean as f64, x.sigma() as f64);
    Moments { mean: f.mean as f32, grad: x.grad * f.dmean as f32, var: f.var as f32 }
}

fn sin_of(x: Moments, cosine: bool) -> Moments {
    let (m, s) = (x.mean as f64, x.sigma() as f64);
    let shift = if cosine { std::f64::consts::FRAC_PI_2 } else { 0.0 };
    let (e, de) = gaussian::sin_cos_expectation(m + shift, s);
    // E[sin²] = (1 − E[cos 2X]) / 2.
    let (_, c2) = gaussian::sin_cos_expectation(2.0 * (m + shift), 2.0 * s);
    let var = ((1.0 - c2) / 2.0 - e * e).max(0.0);
    Moments { mean: e as f32, grad: x.grad * de as f32, var: var as f32 }
}

fn exp_of(x: Moments) -> Moments {
    let (m, v) = (x.mean as f64, x.var as f64);
    let e = (m + 0.5 * v).exp();
    // (e^v − 1) e², saturated like every node's output. Where that is 0 · ∞: 0 without spread
    // (even where e² overflows), else in logs, e^{2m + v} (e^v − 1).
    let direct = (v.exp() - 1.0) * e * e;
    let var = if direct.is_finite() {
        direct
    } else if v > 0.0 {
        let ln_expm1 = if v > 30.0 { v } else { v.exp_m1().ln() };
        (2.0 * m + v + ln_expm1).exp()
    } else {
        0.0
    };
    let var = sat(var);
    Moments { mean: sat(e), grad: scale_grad(x.grad, e), var }
}

/// GLSL-style `mod(x, y) = x − y floor(x / y)`.
fn modulo(a: Moments, b: Moments, fp: &Footprint) -> Moments {
    if uniform(&b) {
        if b.mean == 0.0 {
            return Moments::constant(0.0);
        }
        let q = floor_of(affine(a, 1.0 / b.mean, 0.0));
        return add_scaled(a, q, -b.mean, fp);
    }
    nary(&[a, b], |p| if p[1] == 0.0 { 0.0 } else { p[0] - p[1] * (p[0] / p[1]).floor() })
}

/// `power`'s total definition (OSL's `safe_pow`): `x^0 = 1`, `0^y = 0` otherwise, a negative base
/// gives `x^y` for whole exponents and 0 for fractional ones; `safepower` is `sign(x) |x|^y` with
/// the same rule at 0.
#[inline]
pub(crate) fn power_point(x: f64, y: f64, safe: bool) -> f64 {
    if y == 0.0 {
        1.0
    } else if x == 0.0 {
        0.0
    } else if safe {
        sat64(x.signum() * x.abs().powf(y))
    } else if x < 0.0 && y.fract() != 0.0 {
        0.0
    } else {
        sat64(x.powf(y))
    }
}

thread_local! {
    /// A mutation switch for the totality fuzzer's own test: on this thread, `power` loses its
    /// domain guard (a negative base with a fractional exponent is NaN again), so that the test
    /// can show the fuzzer finds the NaN. Never set outside that test.
    static UNGUARDED_POWER: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Turns `power`'s domain guard off (or back on) on the calling thread; see the fuzzer's test.
#[doc(hidden)]
pub fn set_unguarded_power(on: bool) {
    UNGUARDED_POWER.with(|u| u.set(on));
}

fn power(a: Moments, b: Moments, safe: bool) -> Moments {
    // Read once per evaluation, not per quadrature point.
    let unguarded = UNGUARDED_POWER.with(|u| u.get());
    let f = move |x: f64, y: f64| if unguarded { x.powf(y) } else { power_point(x, y, safe) };
    if uniform(&b) {
        let y = b.mean as f64;
        // The derivative of x^y is y x^(y−1) = y f(x)/x away from 0; at 0 it is taken as 0.
        unary(a, move |x| f(x, y), move |x| if x == 0.0 { 0.0 } else { y * f(x, y) / x })
    } else {
        nary(&[a, b], move |p| f(p[0], p[1]))
    }
}

/// One channel of a per-channel math node, written to `o`; `x` are the node's inputs at that
/// channel. Each arm stores its own result: through a shared exit, every result went to a stack
/// slot field by field and was read back whole (a store-forwarding stall per channel).
#[inline(always)]
fn channel_into(op: MathOp, x: &[Moments], fp: &Footprint, o: &mut Moments) {
    use MathOp::*;
    let a = x[0];
    match op {
        Add => *o = add_scaled(a, x[1], 1.0, fp),
        Subtract => *o = add_scaled(a, x[1], -1.0, fp),
        Multiply => *o = mul(a, x[1], fp),
        Divide => {
            *o = {
                if uniform(&x[1]) {
                    if x[1].mean == 0.0 {
                        Moments::constant(0.0)
                    } else {
                        affine(a, 1.0 / x[1].mean, 0.0)
                    }
                } else {
                    nary(&[a, x[1]], |p| safe_div(p[0], p[1]))
                }
            }
        }
        Modulo => *o = modulo(a, x[1], fp),
        Fract => *o = fract_of(a),
        Invert => *o = add_scaled(x[1], a, -1.0, fp),
        Absval => *o = absval(a),
        Sign => {
            *o = {
                if a.var == 0.0 {
                    Moments::constant(if a.mean > 0.0 {
                        1.0
                    } else if a.mean < 0.0 {
                        -1.0
                    } else {
                        0.0
                    })
                } else {
                    affine(gaussian_step(a, 0.0), 2.0, -1.0)
                }
            }
        }
        Floor => *o = floor_of(a),
        Ceil => *o = affine(floor_of(affine(a, -1.0, 0.0)), -1.0, 0.0),
        // GLSL's round (MaterialX's bakes) sends halves to the even integer.
        Round if a.var == 0.0 => *o = Moments::constant((a.mean as f64).round_ties_even() as f32),
        Round => *o = floor_of(affine(a, 1.0, 0.5)),
        Power => *o = power(a, x[1], false),
        SafePower => *o = power(a, x[1], true),
        Sin => *o = sin_of(a, false),
        Cos => *o = sin_of(a, true),
        Tan => *o = unary(a, f64::tan, |v| 1.0 / (v.cos() * v.cos())),
        Asin => *o = unary(a, |v| v.clamp(-1.0, 1.0).asin(), |v| 1.0 / (1.0 - v * v).max(1e-12).sqrt()),
        Acos => *o = unary(a, |v| v.clamp(-1.0, 1.0).acos(), |v| -1.0 / (1.0 - v * v).max(1e-12).sqrt()),
        Atan2 => *o = nary(&[a, x[1]], |p| p[0].atan2(p[1])),
        Sqrt => *o = unary(a, |v| v.max(0.0).sqrt(), |v| if v > 0.0 { 0.5 / v.sqrt() } else { 0.0 }),
        Ln => *o = unary(a, |v| v.max(1e-30).ln(), |v| 1.0 / v.max(1e-30)),
        Exp => *o = exp_of(a),
        TriangleWave => *o = chain(a, tri_moments(a.mean as f64, a.sigma() as f64)),
        Clamp => {
            *o = {
                if uniform(&x[1]) && uniform(&x[2]) {
                    clamp_const(a, x[1].mean as f64, x[2].mean as f64)
                } else {
                    min2(max2(a, x[1], fp), x[2], fp)
                }
            }
        }
        Min => *o = min2(a, x[1], fp),
        Max => *o = max2(a, x[1], fp),
        Smoothstep => {
            *o = {
                if uniform(&x[1]) && uniform(&x[2]) {
                    smoothstep_const(a, x[1].mean as f64, x[2].mean as f64)
                } else {
                    nary(&[a, x[1], x[2]], |p| smoothstep_point(p[0], p[1], p[2]))
                }
            }
        }
        Remap => {
            *o = {
                if x[1..5].iter().all(uniform) {
                    let (il, ih, ol, oh) = (x[1].mean, x[2].mean, x[3].mean, x[4].mean);
                    // In f32, as MaterialX computes it; equal input bounds divide by zero: 0. A slope
                    // beyond the f32 range is saturated (in f64) instead.
                    let k = if ih == il { 0.0 } else { (oh - ol) / (ih - il) };
                    if k.is_finite() {
                        affine(a, k, ol - il * k)
                    } else {
                        let k = safe_div(oh as f64 - ol as f64, ih as f64 - il as f64);
                        affine(a, k as f32, sat(ol as f64 - il as f64 * k))
                    }
                } else {
                    nary(&x[..5], |p| p[3] + safe_div((p[0] - p[1]) * (p[4] - p[3]), p[2] - p[1]))
                }
            }
        }
        Range => {
            *o = {
                let doclamp = x[6].mean >= 0.5;
                let f = move |p: &[f64]| {
                    let t = safe_div(p[0] - p[1], p[2] - p[1]);
                    let t = power_point(t, safe_div(1.0, p[3]), true);
                    let r = p[4] + t * (p[5] - p[4]);
                    if doclamp {
                        r.clamp(p[4].min(p[5]), p[4].max(p[5]))
                    } else {
                        r
                    }
                };
                if x[1..6].iter().all(uniform) {
                    let p: [f64; 6] =
                        [0.0, x[1].mean as f64, x[2].mean as f64, x[3].mean as f64, x[4].mean as f64, x[5].mean as f64];
                    if p[3] == 1.0 && !doclamp {
                        let k = safe_div(p[5] - p[4], p[2] - p[1]) as f32;
                        *o = affine(a, k, p[4] as f32 - p[1] as f32 * k);
                        return;
                    }
                    unary(
                        a,
                        move |v| {
                            let mut q = p;
                            q[0] = v;
                            f(&q)
                        },
                        move |v| {
                            let h = 1e-4 * (1.0 + v.abs());
                            let (mut q0, mut q1) = (p, p);
                            q0[0] = v - h;
                            q1[0] = v + h;
                            (f(&q1) - f(&q0)) / (2.0 * h)
                        },
                    )
                } else {
                    nary(&x[..6], f)
                }
            }
        }
        Mix => *o = mix(x[1], a, x[2], fp),
        IfGreater | IfGreaterEq | IfEqual | Switch | And | Or | Xor | Not => {
            unreachable!("conditionals and logic are evaluated per node")
        }
        Dot | Magnitude | Distance | Normalize => unreachable!("vector ops are evaluated per node"),
    }
}

fn smoothstep_point(x: f64, lo: f64, hi: f64) -> f64 {
    if x >= hi {
        1.0
    } else if x <= lo {
        0.0
    } else {
        let t = (x - lo) / (hi - lo);
        t * t * (3.0 - 2.0 * t)
    }
}

/// `and`, `or`, `xor`, `not` of independent events with probabilities the operands' means:
/// the result's probability, its uv gradient by the product rule, and the Bernoulli variance.
fn logic(op: MathOp, a: &Moments, b: Option<&Moments>) -> Moments {
    let p = a.mean.clamp(0.0, 1.0);
    let (q, gq) = b.map_or((0.0, Vec2::ZERO), |b| (b.mean.clamp(0.0, 1.0), b.grad));
    let (r, grad) = match op {
        MathOp::And => (p * q, a.grad * q + gq * p),
        MathOp::Or => (p + q - p * q, a.grad * (1.0 - q) + gq * (1.0 - p)),
        MathOp::Xor => (p + q - 2.0 * p * q, a.grad * (1.0 - 2.0 * q) + gq * (1.0 - 2.0 * p)),
        _ => (1.0 - p, -a.grad),
    };
    Moments { mean: r, grad, var: r * (1.0 - r) }
}

/// Probability moments of the condition of `ifgreater` & co.
fn condition(op: MathOp, v1: Moments, v2: Moments, fp: &Footprint, integral: bool) -> Moments {
    let d = add_scaled(v1, v2, -1.0, fp);
    let (m, s) = (d.mean as f64, d.sigma() as f64);
    match op {
        MathOp::IfEqual => {
            if s == 0.0 {
                return Moments::constant(if d.mean == 0.0 { 1.0 } else { 0.0 });
            }
            let h = if integral { 0.5 } else { 0.0 };
            let p = gaussian::mass((-h - m) / s, (h - m) / s);
            Moments { mean: p as f32, grad: Vec2::ZERO, var: (p * (1.0 - p)) as f32 }
        }
        _ => {
            if s == 0.0 {
                let t = if op == MathOp::IfGreater { d.mean > 0.0 } else { d.mean >= 0.0 };
                return Moments::constant(if t { 1.0 } else { 0.0 });
            }
            gaussian_step(d, 0.0)
        }
    }
}

/// `switch`: input `k` (0-based) is chosen on `k ≤ which < k + 1`, the first below 1, and
/// from 10 on (or for a NaN) none: 0, as MaterialX's `NG_switch` chain of `ifgreater`s has it.
/// Over a footprint, `which ~ N(m, s²)` picks input `k` with the Gaussian mass `P_k` of its
/// interval, so the result is the mixture `Σ P_k in_k` (`which` taken independent of the
/// inputs; the mass from 10 on adds 0): its mean, its variance `Σ P_k (σ_k² + μ_k²) − mean²`,
/// and its gradient `Σ P_k ∇μ_k + μ_k ∇P_k`. At a point (`s` = 0) it is the plain pick.
fn switch(which: Moments, ins: &[Filtered], ty: ValueType, out: &mut Filtered) {
    let (m, s) = (which.mean as f64, which.sigma() as f64);
    if s == 0.0 {
        match (0..ins.len()).find(|&k| m < (k + 1) as f64) {
            Some(k) => {
                for c in 0..ty.channels() {
                    out.ch[c] = ins[k].at(c);
                }
            }
            None => *out = Filtered::zero(ty),
        }
        return;
    }
    let mut mean = [0.0f64; 4];
    let mut sq = [0.0f64; 4];
    let mut grad = [Vec2::ZERO; 4];
    let mut below = (0.0, 0.0); // (Φ, φ) at the interval's lower edge
    for (k, input) in ins.iter().enumerate() {
        let z = ((k + 1) as f64 - m) / s;
        let above = (gaussian::cdf(z), gaussian::pdf(z));
        let p = (above.0 - below.0).max(0.0);
        // dP/dm = (φ(z_lo) − φ(z_hi)) / s.
        let dp = (below.1 - above.1) / s;
        below = above;
        if p == 0.0 && dp == 0.0 {
            continue;
        }
        for c in 0..ty.channels() {
            let x = input.at(c);
            let mu = x.mean as f64;
            mean[c] += p * mu;
            sq[c] += p * (x.var as f64 + mu * mu);
            grad[c] += x.grad * p as f32 + which.grad * (dp * mu) as f32;
        }
    }
    for c in 0..ty.channels() {
        out.ch[c] = Moments { mean: mean[c] as f32, grad: grad[c], var: (sq[c] - mean[c] * mean[c]).max(0.0) as f32 };
    }
}

fn vector_op(op: MathOp, ins: &[Filtered], fp: &Footprint) -> Filtered {
    let mut out = Filtered::zero(ValueType::Float);
    let a = &ins[0];
    let n = a.n();
    match op {
        MathOp::Dot => {
            let b = &ins[1];
            let mut acc = Moments::default();
            for k in 0..n {
                acc = add_scaled(acc, mul(a.ch[k], b.at(k), fp), 1.0, fp);
            }
            out.ch[0] = acc;
        }
        MathOp::Magnitude => {
            out.ch[0] = nary(&a.ch[..n], |p| p.iter().map(|v| v * v).sum::<f64>().sqrt());
        }
        MathOp::Distance => {
            let mut d = [Moments::default(); 4];
            for k in 0..n {
                d[k] = add_scaled(a.ch[k], ins[1].at(k), -1.0, fp);
            }
            out.ch[0] = nary(&d[..n], |p| p.iter().map(|v| v * v).sum::<f64>().sqrt());
        }
        _ => unreachable!(),
    }
    out
}

/// Whether [`eval_into`] computes `op` channel by channel from its inputs' channels alone (the
/// arithmetic, comparisons and functions of one value each): then [`eval_channels`] can
/// compute it from inputs read where they are.
pub(crate) fn is_channelwise(op: &MathOp) -> bool {
    use MathOp::*;
    !matches!(
        op,
        Dot | Magnitude | Distance | Normalize | Switch | And | Or | Xor | Not | IfGreater | IfGreaterEq | IfEqual
    )
}

/// [`eval_into`] of an [`is_channelwise`] `op` (at most 8 inputs): each channel from the
/// inputs' same channel (a one-channel input's only one). The inputs are values or references
/// to them: the evaluator hands it the upstream values where they lie instead of copying each
/// into an input slot first.
#[inline]
pub(crate) fn eval_channels<F: std::borrow::Borrow<Filtered>>(
    op: MathOp,
    ty: ValueType,
    ins: &[F],
    fp: &Footprint,
    out: &mut Filtered,
) {
    debug_assert!(is_channelwise(&op) && ins.len() <= 8);
    *out = Filtered::zero(ty);
    let mut xs = [Moments::default(); 8];
    for k in 0..ty.channels() {
        for (x, i) in xs.iter_mut().zip(ins.iter()) {
            *x = i.borrow().at(k);
        }
        channel_into(op, &xs[..ins.len()], fp, &mut out.ch[k]);
    }
}

pub(crate) fn eval(op: &MathOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let mut out = Filtered::zero(ty);
    eval_into(op, ty, ins, ctx, &mut out);
    out
}

/// [`eval`] written into `out` channel by channel: a value built in a temporary and copied whole
/// is read back across the temporary's fresh, narrower stores (a store-forwarding stall per
/// node, most of a cheap node's cost).
#[inline]
pub(crate) fn eval_into(op: &MathOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx, out: &mut Filtered) {
    let fp = ctx.fp;
    if is_channelwise(op) {
        return eval_channels(*op, ty, ins, fp, out);
    }
    let n = ty.channels();
    *out = Filtered::zero(ty);
    match op {
        MathOp::Dot | MathOp::Magnitude | MathOp::Distance => *out = vector_op(*op, ins, fp),
        MathOp::Normalize => {
            let a = &ins[0];
            for k in 0..n {
                out.ch[k] = nary(&a.ch[..n], |p| {
                    let l = p.iter().map(|v| v * v).sum::<f64>().sqrt();
                    if l > 0.0 {
                        p[k] / l
                    } else {
                        0.0
                    }
                });
            }
        }
        MathOp::Switch => switch(ins[10].ch[0], &ins[..10], ty, out),
        MathOp::And | MathOp::Or | MathOp::Xor | MathOp::Not => {
            out.ch[0] = logic(*op, &ins[0].ch[0], ins.get(1).map(|i| &i.ch[0]));
        }
        MathOp::IfGreater | MathOp::IfGreaterEq | MathOp::IfEqual => {
            let integral = ins[0].ty != ValueType::Float;
            let p = condition(*op, ins[0].ch[0], ins[1].ch[0], fp, integral);
            if ty == ValueType::Boolean {
                // The boolean variants output the comparison itself.
                out.ch[0] = p;
            } else {
                for k in 0..n {
                    out.ch[k] = mix(ins[3].at(k), ins[2].at(k), p, fp);
                }
            }
        }
        _ => unreachable!("channel-wise operations are evaluated by eval_channels"),
    }
}
