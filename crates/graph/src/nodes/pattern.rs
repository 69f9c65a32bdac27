//! Shapes, ramps, splits and random values: `checkerboard`, `ramplr`, `ramptb`, `ramp4`, `ramp`,
//! `ramp_gradient`, `splitlr`, `splittb`, `randomfloat`, `randomcolor`.
//!
//! | node | inputs (default) | unfiltered | filtered evaluation |
//! |---|---|---|---|
//! | `checkerboard` | `color1` (1,1,1), `color2` (0,0,0), `uvtiling` (8,8), `uvoffset` (0,0), `texcoord` (UV0) | `color1` where `floor(u')+floor(v')` is odd, `color2` where even; `u' = t·tiling − offset` | the parity's mean over the footprint's ellipse (`gaussian::checker_expectation`): uncorrelated, the product of the two axes' square-wave expectations (step masses for σ < 0.4 cells, damped Fourier series above; nothing evaluated above 3.5 cells); correlated ones by Mehler's expansion (\|ρ\| ≤ 0.6), else a double Fourier series over the band of terms the ellipse does not damp, or (small, very thin ellipses) exact line integrals along it; within 1.3e-4 of brute force over 108 ellipses |
//! | `ramplr` / `ramptb` | `valuel`,`valuer` / `valuet`,`valueb` (0), `texcoord` | `mix(l, r, clamp(u, 0, 1))` / `mix(b, t, clamp(v, 0, 1))` | closed-form moments of the clamped coordinate (piecewise polynomial × Gaussian) |
//! | `ramp4` | `valuetl`,`valuetr`,`valuebl`,`valuebr` (0), `texcoord` | bilinear in the clamped coordinates | as the ramps, per axis |
//! | `ramp` (color4) | `texcoord` (UV0), `type` (0), `interpolation` (1), `num_intervals` (2), `interval1` (0), `color1` (0,0,0,1), `interval2`…`interval10` (1), `color2`…`color10` (1,1,1,1) | see below | the ramp is a piecewise polynomial `f(x)` (degree ≤ 3) of one coordinate `x`: exact closed-form mean, variance and slope of `f(X)` for Gaussian `X` (piece moments plus the jumps' densities); `x` is exactly Gaussian for `type` 0 (`u`), and for types 1–3 its mean and variance come from cubature over the texcoord's spread (radial: unwrapped around the centre's angle and the ramp extended periodically) |
//! | `splitlr` / `splittb` | `valuel`,`valuer` / `valuet`,`valueb` (0), `center` (0.5), `texcoord` | `valuer` where `u ≥ center` / `valuet` where `v ≥ center` | the footprint's mass beyond the split, `Φ((m − c)/σ)` |
//! | `randomfloat` | `in` (0), `min` (0), `max` (1), `seed` (0) | cell noise of `(in · 4096, seed)` (`(in, seed)` for an integer `in`) mapped to `[min, max]`, as MaterialX's graphs | evaluated at the mean of `in` (a per-object value, normally uniform) |
//! | `ramp_gradient` (color4) | `x` (0), `interval1` (0), `interval2` (1), `color1` (0,0,0,1), `color2` (1,1,1,1), `interpolation` (1), `prev_color` (0,0,0,1), `interval_num` (1), `num_intervals` (2) | one interval of `ramp`, as MaterialX's `NG_ramp_gradient`: `prev_color` where `interval_num ≥ num_intervals` or `x ≤ interval1`, else `mix(color1, color2, t)` with `t` the clamped linear (0) or smoothstep (1) position in the interval, or `color1` below `interval2` and `color2` from it (2) | MaterialX's graph, each step by its node's rule (`clamp`, `remap`, `smoothstep`, `switch`, `mix`, `ifgreater`, `ifgreatereq`) |
//! | `randomcolor` | `in` (0), `huelow` (0), `huehigh` (1), `saturationlow` (0), `saturationhigh` (1), `brightnesslow` (0), `brightnesshigh` (1), `seed` (0) | HSV from three `randomfloat`s of the float `in` with seeds `ceil(seed + 413.3)`, `ceil(seed + 1522.4)`, `ceil(seed + 1813.8)`, as MaterialX's graph | as `randomfloat` |

//!
//! `ramp` is MaterialX 1.39's gradient (its `NG_ramp` graph): `x` is `u` (`type` 0, standard),
//! `atan2(u − ½, v − ½)/6.28319 + ½` (1, radial), `1.414·|uv − ½|` (2, circular) or
//! `2·max(|u − ½|, |v − ½|)` (3, box; any other type gives `x = 0`). Starting from `color1`, each
//! interval `k = 1…9` with `k < num_intervals` replaces the colour where `x > interval_k` by
//! `mix(color_k, color_k+1, t)`: `t` = `(clamp(x, i_k, i_k+1) − i_k)/(i_k+1 − i_k)` (`interpolation`
//! 0, linear), `smoothstep(i_k, i_k+1, x)` (1, smooth), or `color_k` below `i_k+1` and
//! `color_k+1` from it (2, step); other interpolations give zero. An empty or reversed interval
//! (`i_k+1 ≤ i_k`, where MaterialX divides by zero) gives `color_k+1`. Intervals, counts and
//! modes are read at their filtered mean (they are uniform in practice); colours that vary add
//! their own slope and spread, weighted by each colour's filtered weight.
use super::hash::cell_float;
use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::gaussian::{self, poly, Piece};
use crate::graph::Source;
use crate::moments::{self, affine, chain, mix};
use crate::value::{Filtered, Moments, ValueType};

pub(crate) const CATEGORIES: &[&str] = &[
    "checkerboard",
    "ramplr",
    "ramptb",
    "ramp4",
    "ramp",
    "ramp_gradient",
    "splitlr",
    "splittb",
    "randomfloat",
    "randomcolor",
];

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
    /// `ramp`
    Ramp,
    /// `ramp_gradient`
    RampGradient,
    /// `splitlr`
    SplitLr,
    /// `splittb`
    SplitTb,
    /// `randomfloat`; `in` is scaled by `scale` before its cell is taken: 4096 for a float `in`,
    /// 1 for an integer one, as MaterialX's `NG_randomfloat_float` and `NG_randomfloat_integer`.
    RandomFloat { scale: f32 },
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
        "ramp_gradient" => (
            &[
                inp!("x", Float, Zero),
                inp!("interval1", Float, Zero),
                inp!("interval2", Float, One),
                inp!("color1", Out, Quad(0.0, 0.0, 0.0, 1.0)),
                inp!("color2", Out, One),
                inp!("interpolation", Int, One),
                inp!("prev_color", Out, Quad(0.0, 0.0, 0.0, 1.0)),
                inp!("interval_num", Int, One),
                inp!("num_intervals", Int, Splat(2.0)),
            ],
            |t| t == ValueType::Color4,
        ),
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
        "ramp" => (
            &[
                inp!("texcoord", V2, Uv),
                inp!("type", Int, Zero),
                inp!("interpolation", Int, One),
                inp!("num_intervals", Int, Splat(2.0)),
                inp!("interval1", Float, Zero),
                inp!("color1", Out, Quad(0.0, 0.0, 0.0, 1.0)),
                inp!("interval2", Float, One),
                inp!("color2", Out, One),
                inp!("interval3", Float, One),
                inp!("color3", Out, One),
                inp!("interval4", Float, One),
                inp!("color4", Out, One),
                inp!("interval5", Float, One),
                inp!("color5", Out, One),
                inp!("interval6", Float, One),
                inp!("color6", Out, One),
                inp!("interval7", Float, One),
                inp!("color7", Out, One),
                inp!("interval8", Float, One),
                inp!("color8", Out, One),
                inp!("interval9", Float, One),
                inp!("color9", Out, One),
                inp!("interval10", Float, One),
                inp!("color10", Out, One),
            ],
            |t| t == ValueType::Color4,
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

/// The factor MaterialX's `NG_randomfloat_float` applies to a float `in` before the cell noise.
const RANDOM_SCALE: f32 = 4096.0;

/// MaterialX's `NG_randomcolor_float` seeds: hue, saturation and brightness draw `randomfloat`
/// with seed `ceil(seed + offset)`.
const RANDOM_COLOR_SEEDS: [f32; 3] = [413.3, 1522.4, 1813.8];

fn build(category: &str, _: ValueType, in_types: &[ValueType], _: &[Source], _: &[Param]) -> Result<Op, String> {
    Ok(Op::Pattern(match category {
        "checkerboard" => PatternOp::Checkerboard,
        "ramplr" => PatternOp::RampLr,
        "ramptb" => PatternOp::RampTb,
        "ramp4" => PatternOp::Ramp4,
        "ramp" => PatternOp::Ramp,
        "ramp_gradient" => PatternOp::RampGradient,
        "splitlr" => PatternOp::SplitLr,
        "splittb" => PatternOp::SplitTb,
        "randomfloat" => PatternOp::RandomFloat {
            scale: if in_types.first() == Some(&ValueType::Integer) { 1.0 } else { RANDOM_SCALE },
        },
        _ => PatternOp::RandomColor,
    }))
}

mod ramp {
    //! MaterialX's `ramp`: its unfiltered value and the closed-form moments of its colour over a
    //! Gaussian coordinate.

    use super::Ctx;
    use crate::gaussian::{self, poly, poly_deriv, poly_eval, poly_expectation, poly_mul, poly_shift_scale, Poly};
    use crate::moments::{self, chain};
    use crate::value::{Filtered, Moments, ValueType};
    use glam::Vec2;

    /// The ramp's uniform settings: `x`'s kind, interpolation, active intervals, positions and
    /// colours.
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Spec {
        pub kind: i32,
        pub interp: i32,
        /// `num_intervals` (the intervals `k < num_intervals` apply).
        pub count: i32,
        pub at: [f64; 10],
        pub color: [[f64; 4]; 10],
    }

    /// MaterialX's constant in the radial type (`atan2 / 6.28319`), deliberately its rounded 2π.
    #[allow(clippy::approx_constant)]
    const TWO_PI_MX: f64 = 6.28319;

    /// The ramp coordinate `x` at uv `(u, v)` for `kind`.
    pub(crate) fn coordinate(kind: i32, u: f64, v: f64) -> f64 {
        let (du, dv) = (u - 0.5, v - 0.5);
        match kind {
            k if k < 1 => u,
            1 => du.atan2(dv) / TWO_PI_MX + 0.5,
            2 => (du * 1.414).hypot(dv * 1.414),
            3 => {
                let (ax, ay) = (du.abs(), dv.abs());
                if ax > ay {
                    2.0 * ax
                } else {
                    2.0 * ay
                }
            }
            _ => 0.0,
        }
    }

    impl Spec {
        /// The last interval that applies (1-based; 0: none, the ramp is `color1`).
        fn last(&self) -> usize {
            (self.count - 1).clamp(0, 9) as usize
        }

        /// Interval `k` (1-based) as `(lo, hi, color lo, color hi)`.
        fn interval(&self, k: usize) -> (f64, f64, [f64; 4], [f64; 4]) {
            (self.at[k - 1], self.at[k], self.color[k - 1], self.color[k])
        }

        /// The blend weight `t` of interval `k` at `x > lo`, and whether it is constant there.
        fn weight(&self, k: usize, x: f64) -> f64 {
            let (lo, hi, _, _) = self.interval(k);
            match self.interp {
                i if i < 2 => {
                    if hi <= lo || x >= hi {
                        1.0
                    } else {
                        let y = (x - lo) / (hi - lo);
                        if i < 1 {
                            y
                        } else {
                            y * y * (3.0 - 2.0 * y)
                        }
                    }
                }
                2 => {
                    if hi > x {
                        0.0
                    } else {
                        1.0
                    }
                }
                _ => f64::NAN,
            }
        }

        /// The unfiltered ramp at coordinate `x` (MaterialX's chain of `ramp_gradient`s).
        pub(crate) fn at_x(&self, x: f64) -> [f64; 4] {
            let mut c = self.color[0];
            for k in 1..=self.last() {
                let (lo, _, c0, c1) = self.interval(k);
                if x > lo {
                    let t = self.weight(k, x);
                    c = if t.is_nan() { [0.0; 4] } else { std::array::from_fn(|i| c0[i] + (c1[i] - c0[i]) * t) };
                }
            }
            c
        }

        /// The ramp as polynomial pieces of `x`: `(lo, hi, channel polynomials)` over the whole line.
        fn pieces(&self, out: &mut [(f64, f64, [Poly; 4]); 12]) -> usize {
            let last = self.last();
            let mut cuts = [0.0f64; 10];
            let mut nc = 0;
            for &a in &self.at[..=last.min(9)] {
                if a.is_finite() && !cuts[..nc].contains(&a) {
                    cuts[nc] = a;
                    nc += 1;
                }
            }
            cuts[..nc].sort_by(f64::total_cmp);
            let mut n = 0;
            for j in 0..=nc {
                let lo = if j == 0 { f64::NEG_INFINITY } else { cuts[j - 1] };
                let hi = if j == nc { f64::INFINITY } else { cuts[j] };
                let probe = match (lo.is_finite(), hi.is_finite()) {
                    (true, true) => 0.5 * (lo + hi),
                    (false, true) => hi - 1.0,
                    (true, false) => lo + 1.0,
                    (false, false) => 0.0,
                };
                // The interval that sets the colour here: the last applying one with x > lo.
                let k = (1..=last).rev().find(|&k| probe > self.at[k - 1]);
                let mut ps = [poly(&[0.0]); 4];
                match k {
                    None => {
                        for (p, c) in ps.iter_mut().zip(self.color[0]) {
                            *p = poly(&[c]);
                        }
                    }
                    Some(k) => {
                        let (lo_k, hi_k, c0, c1) = self.interval(k);
                        // t(x) as a polynomial on this piece.
                        let t = match self.interp {
                            i if i < 2 && hi_k > lo_k && probe < hi_k => {
                                let (m, s) = (-lo_k / (hi_k - lo_k), 1.0 / (hi_k - lo_k));
                                let y = if i < 1 { poly(&[0.0, 1.0]) } else { poly(&[0.0, 0.0, 3.0, -2.0]) };
                                Some(poly_shift_scale(&y, m, s))
                            }
                            i if i < 3 => Some(poly(&[self.weight(k, probe)])),
                            _ => None,
                        };
                        for i in 0..4 {
                            ps[i] = match &t {
                                Some(t) => {
                                    let mut p = t.map(|a| a * (c1[i] - c0[i]));
                                    p[0] += c0[i];
                                    p
                                }
                                None => poly(&[0.0]),
                            };
                        }
                    }
                }
                out[n] = (lo, hi, ps);
                n += 1;
            }
            n
        }
    }

    /// Mean, variance and `dE/dm` of channel `c` of the ramp at `X ~ N(m, s²)`, or with
    /// `periodic`, of the ramp of `frac(X)` (radial `x` is an angle).
    fn channel_moments(pieces: &[(f64, f64, [Poly; 4])], c: usize, m: f64, s: f64, periodic: bool) -> (f64, f64, f64) {
        // E[p 1_piece], E[p² 1_piece], E[p' 1_piece].
        let terms = |lo: f64, hi: f64, p: &Poly| {
            (
                piece_expectation(p, lo, hi, m, s),
                piece_expectation(&poly_mul(p, p), lo, hi, m, s),
                piece_expectation(&poly_deriv(p), lo, hi, m, s),
            )
        };
        // A jump from `left` to `right` at `b` moves the mean by (jump) × density.
        let jump = |b: f64, left: f64, right: f64| {
            let z = (b - m) / s;
            if z.abs() < 40.0 {
                (right - left) * gaussian::pdf(z) / s
            } else {
                0.0
            }
        };
        let (mut e, mut e2, mut de) = (0.0, 0.0, 0.0);
        if !periodic {
            for (j, (lo, hi, ps)) in pieces.iter().enumerate() {
                let (a, b, d) = terms(*lo, *hi, &ps[c]);
                e += a;
                e2 += b;
                de += d;
                if j > 0 {
                    de += jump(*lo, poly_eval(&pieces[j - 1].2[c], *lo), poly_eval(&ps[c], *lo));
                }
            }
            return (e, (e2 - e * e).max(0.0), de);
        }
        // The ramp over one turn [0, 1), repeated: shifts k cover ±6σ around m.
        let (k0, k1) = ((m - 6.0 * s).floor() as i64, (m + 6.0 * s).floor() as i64);
        if k1 - k0 > 12 {
            // The footprint spans many turns: x is uniform over the turn.
            for (lo, hi, ps) in pieces {
                let (a, b) = (lo.max(0.0), hi.min(1.0));
                if a < b {
                    e += integral(&ps[c], a, b);
                    e2 += integral(&poly_mul(&ps[c], &ps[c]), a, b);
                }
            }
            return (e, (e2 - e * e).max(0.0), 0.0);
        }
        // The value just below x = 1 (where the turn wraps to 0).
        let below_one =
            pieces.iter().find(|(lo, hi, _)| *lo < 1.0 && 1.0 <= *hi).map_or(0.0, |(_, _, ps)| poly_eval(&ps[c], 1.0));
        for k in k0..=k1 {
            let kf = k as f64;
            let mut left = below_one;
            for (lo, hi, ps) in pieces {
                let (a, b) = (lo.max(0.0), hi.min(1.0));
                if a >= b {
                    continue;
                }
                let shifted = poly_shift_scale(&ps[c], -kf, 1.0);
                let (t0, t1, t2) = terms(a + kf, b + kf, &shifted);
                e += t0;
                e2 += t1;
                de += t2;
                // The jump at the piece's lower end (at the turn's start, from the previous
                // turn's end).
                de += jump(a + kf, left, poly_eval(&shifted, a + kf));
                left = poly_eval(&shifted, b + kf);
            }
        }
        (e, (e2 - e * e).max(0.0), de)
    }

    /// Gauss–Legendre nodes and weights on [−1, 1], 6 points.
    const LEGENDRE6: [(f64, f64); 6] = [
        (-0.932_469_514_203_152, 0.171_324_492_379_170_4),
        (-0.661_209_386_466_264_5, 0.360_761_573_048_138_6),
        (-0.238_619_186_083_197, 0.467_913_934_572_691),
        (0.238_619_186_083_197, 0.467_913_934_572_691),
        (0.661_209_386_466_264_5, 0.360_761_573_048_138_6),
        (0.932_469_514_203_152, 0.171_324_492_379_170_4),
    ];

    /// `E[p(X) 1{lo ≤ X < hi}]` for `X ~ N(m, s²)`. A piece much narrower than `s` is
    /// integrated by Gauss–Legendre in `x` (the density is nearly polynomial across it), where
    /// the partial-moment closed form would cancel catastrophically (its coefficients grow like
    /// `(s / width)^degree`).
    fn piece_expectation(p: &Poly, lo: f64, hi: f64, m: f64, s: f64) -> f64 {
        if !(lo.is_finite() && hi.is_finite() && hi - lo < 0.25 * s) {
            return poly_expectation(p, lo, hi, m, s);
        }
        let (c, h) = (0.5 * (lo + hi), 0.5 * (hi - lo));
        LEGENDRE6
            .iter()
            .map(|(z, w)| {
                let x = c + h * z;
                w * poly_eval(p, x) * gaussian::pdf((x - m) / s)
            })
            .sum::<f64>()
            * h
            / s
    }

    /// `∫_a^b p(x) dx`.
    fn integral(p: &Poly, a: f64, b: f64) -> f64 {
        let anti = |x: f64| p.iter().enumerate().rev().fold(0.0, |acc, (k, c)| acc * x + c / (k + 1) as f64) * x;
        anti(b) - anti(a)
    }

    /// The filtered ramp coordinate for kinds 1–3 (mean and spread by cubature over the
    /// texcoord's spread; the radial angle unwrapped around the centre's).
    fn coordinate_moments(kind: i32, u: Moments, v: Moments) -> Moments {
        if kind != 1 {
            return moments::nary(&[u, v], |p| coordinate(kind, p[0], p[1]));
        }
        let centre = coordinate(1, u.mean as f64, v.mean as f64);
        moments::nary(&[u, v], |p| {
            let x = coordinate(1, p[0], p[1]);
            centre + (x - centre - (x - centre).round())
        })
    }

    pub(crate) fn eval(ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
        let uniform = |f: &Filtered| f.ch[0].mean.round() as i32;
        let mut spec = Spec {
            kind: uniform(&ins[1]),
            interp: uniform(&ins[2]),
            count: uniform(&ins[3]),
            at: [0.0; 10],
            color: [[0.0; 4]; 10],
        };
        for k in 0..10 {
            spec.at[k] = ins[4 + 2 * k].ch[0].mean as f64;
            spec.color[k] = std::array::from_fn(|i| ins[5 + 2 * k].ch[i].mean as f64);
        }
        let (u, v) = (ins[0].ch[0], ins[0].ch[1]);
        let mut out = Filtered::zero(ValueType::Color4);
        let x = if spec.kind < 1 { u } else { coordinate_moments(spec.kind, u, v) };
        let s = x.sigma() as f64;
        if s == 0.0 {
            let c = spec.at_x(x.mean as f64);
            for i in 0..4 {
                out.ch[i] = Moments::constant(c[i] as f32);
            }
            ctx.work.lattice += 1;
        } else {
            let mut pieces = [(0.0, 0.0, [poly(&[0.0]); 4]); 12];
            let n = spec.pieces(&mut pieces);
            let periodic = spec.kind == 1;
            for i in 0..4 {
                out.ch[i] = chain(x, channel_moments(&pieces[..n], i, x.mean as f64, s, periodic));
            }
            ctx.work.lattice += n as u64;
        }
        // Colours that vary over the footprint: their own slope and spread, weighted by their
        // filtered weight in the ramp (`E[f] = Σ E[w_j] E[c_j]` for independent colours).
        for j in 0..10 {
            let col = &ins[5 + 2 * j];
            if col.is_uniform() {
                continue;
            }
            let mut one = spec;
            one.color = [[0.0; 4]; 10];
            one.color[j] = [1.0; 4];
            let w = if s == 0.0 {
                one.at_x(x.mean as f64)[0]
            } else {
                let mut pieces = [(0.0, 0.0, [poly(&[0.0]); 4]); 12];
                let n = one.pieces(&mut pieces);
                channel_moments(&pieces[..n], 0, x.mean as f64, s, spec.kind == 1).0
            } as f32;
            for i in 0..4 {
                out.ch[i].grad += col.ch[i].grad * w;
                out.ch[i].var += col.ch[i].var * w * w;
            }
        }
        if ctx.point {
            for c in out.ch.iter_mut() {
                c.grad = Vec2::ZERO;
            }
        }
        out
    }
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
    // The parity's mean over the footprint's ellipse (its u–v correlation included); the slope
    // is the product rule's, from the axes' own expectations.
    let c = crate::moments::cov(&u, &v, ctx.fp) as f64;
    let s = gaussian::checker_expectation([u.mean as f64, v.mean as f64], [u.var as f64, c, v.var as f64], [eu, ev]);
    // P(odd cell) = (1 − S)/2, a Bernoulli variable.
    let p = (1.0 - s) / 2.0;
    let ds = u.grad * (du * ev) as f32 + v.grad * (eu * dv) as f32;
    Moments { mean: p as f32, grad: -ds * 0.5, var: (p * (1.0 - p)).max(0.0) as f32 }
}

/// Unfiltered randomfloat's unit value: MaterialX cell noise at `(in · scale, seed)`.
fn random01(x: f32, scale: f32, seed: f32) -> f32 {
    cell_float((x * scale).floor() as i32, seed.floor() as i32)
}

/// `ramp_gradient`, as MaterialX's graph composes it from other nodes.
fn ramp_gradient(ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    use super::math::{eval as math, MathOp};
    use ValueType::{Color4, Float};
    let [x, i1, i2, c1, c2, interp, prev, num, count] =
        [ins[0], ins[1], ins[2], ins[3], ins[4], ins[5], ins[6], ins[7], ins[8]];
    let clamped = math(&MathOp::Clamp, Float, &[x, i1, i2], ctx);
    let (zero, one) =
        (Filtered::constant(crate::value::Value::float(0.0)), Filtered::constant(crate::value::Value::float(1.0)));
    let linear = math(&MathOp::Remap, Float, &[clamped, i1, i2, zero, one], ctx);
    let smooth = math(&MathOp::Smoothstep, Float, &[x, i1, i2], ctx);
    let mut choice = [zero; 11];
    (choice[0], choice[1], choice[10]) = (linear, smooth, interp);
    let t = math(&MathOp::Switch, Float, &choice, ctx);
    let blended = math(&MathOp::Mix, Color4, &[c2, c1, t], ctx);
    let step = math(&MathOp::IfGreater, Color4, &[i2, x, c1, c2], ctx);
    let mut choice = [Filtered::zero(Color4); 11];
    (choice[0], choice[1], choice[2], choice[10]) = (blended, blended, step, interp);
    let within = math(&MathOp::Switch, Color4, &choice, ctx);
    let above = math(&MathOp::IfGreater, Color4, &[x, i1, within, prev], ctx);
    math(&MathOp::IfGreaterEq, Color4, &[num, count, prev, above], ctx)
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
        PatternOp::Ramp => ramp::eval(ins, ctx),
        PatternOp::RampGradient => ramp_gradient(ins, ctx),
        PatternOp::SplitLr => {
            let t = step(ins[2].ch[0].mean, ins[3].ch[0]);
            mix_all(ty, &ins[0], &ins[1], t, ctx)
        }
        PatternOp::SplitTb => {
            let t = step(ins[2].ch[0].mean, ins[3].ch[1]);
            mix_all(ty, &ins[1], &ins[0], t, ctx)
        }
        PatternOp::RandomFloat { scale } => {
            let (x, lo, hi, seed) = (ins[0].ch[0].mean, ins[1].ch[0], ins[2].ch[0], ins[3].ch[0].mean);
            let r = Moments::constant(random01(x, *scale, seed));
            let mut o = Filtered::zero(ty);
            o.ch[0] = mix(lo, hi, r, ctx.fp);
            o
        }
        PatternOp::RandomColor => {
            let x = ins[0].ch[0].mean;
            let seed = ins[7].ch[0].mean;
            // An integer `in` is converted to float first (NG_randomcolor_integer), so both
            // variants scale it.
            let draw = |k: usize| Moments::constant(random01(x, RANDOM_SCALE, (seed + RANDOM_COLOR_SEEDS[k]).ceil()));
            let h = mix(ins[1].ch[0], ins[2].ch[0], draw(0), ctx.fp);
            let s = mix(ins[3].ch[0], ins[4].ch[0], draw(1), ctx.fp);
            let v = mix(ins[5].ch[0], ins[6].ch[0], draw(2), ctx.fp);
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
    out
}
