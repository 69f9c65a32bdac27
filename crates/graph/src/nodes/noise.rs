//! Noise: `noise2d`, `fractal2d`, `cellnoise2d`, `worleynoise2d`, `unifiednoise2d`.
//!
//! | node | inputs (default) | unfiltered (MaterialX 1.39) | filtered evaluation |
//! |---|---|---|---|
//! | `noise2d` | `amplitude` (1), `pivot` (0), `texcoord` (UV0) | `perlin(t) · amplitude + pivot` | exact Gaussian convolution of Perlin's corner kernels for per-axis σ ≤ 0.75 lattice units (every corner whose kernel support meets ±3.5σ, at most 8 per axis); beyond, the value at σ clamped to 0.75 (its corners summed over ±2.5σ) times a per-axis Gaussian damping `exp(−κ(σ² − 0.75²))` least-squares fitted to the exact convolution up to 2.25 (κ 0.34); octave dropped (exactly its mean, 0) once damped below 1e-3; variance within the footprint blends the linearisation and the plane average (`1 −` the mean's fitted variance share) by that share |
//! | `fractal2d` | `amplitude` (1), `octaves` (3), `lacunarity` (2), `diminish` (0.5), `texcoord` (UV0) | `Σ diminishⁱ perlin(t · lacunarityⁱ) · amplitude` | each octave as `noise2d` (exact up to per-axis σ = 0.75 of its own lattice); octaves beyond the footprint's band limit (damped below 1e-3) are never evaluated |
//! | `cellnoise2d` | `texcoord` (UV0) | hash of `floor(t)` in [0, 1] | exact: cell values weighted by the footprint's mass over each cell (σ ≤ 0.5 cells); beyond, the residual around the mean 0.5 shrinks like white noise (`√(σ₀/σ)` per axis) |
//! | `worleynoise2d` | `texcoord` (UV0), `jitter` (1), `style` (0) | distance to the nearest 1–3 jittered feature points (style 0) or the nearest point's cell value (style 1) | 3×3 (σ < 0.2 cells) or 5×5 Gauss–Hermite over the footprint up to σ = 1 cell, blended into the pattern's global mean by σ = 2, then the mean alone |
//! | `unifiednoise2d` (float) | `texcoord` (UV0), `freq` (1,1), `offset` (0,0), `jitter` (1), `outmin` (0), `outmax` (1), `clampoutput` (true), `octaves` (3), `lacunarity` (2), `diminish` (0.5), `type` (0), `style` (0) | `p = t·freq + offset`; raw by `type`: 0 `0.5 + 0.5·perlin(rot(p))`, 1 `cellnoise(rot(p))`, 2 `worley(p, jitter, style)`, 3 `fractal3d(p.x, p.y, z)`, else 0; rotation by and slice `z = (jitter − 1)·90000` (degrees); out `outmin + raw·(outmax − outmin)`, raw clamped to [0, 1] if `clampoutput` | `p` and the rotation exactly (affine); each type as its node above; `fractal3d`'s slice `z = const` of 3D Perlin noise folds both z layers into per-corner in-plane gradients plus a constant, filtered by the same separable corner integrals (scale 0.9820; its own damping rate 0.25 and variance share); the clamp by clamped-ramp moments, the remap exactly |
//!
//! Perlin noise is `0.6616 Σ_c (g_c · (p − c)) W(pₓ − cₓ) W(p_y − c_y)` over lattice corners
//! `c` with `W(d) = 1 − fade(|d|)`: each corner's kernel is separable, so for a footprint with
//! per-axis spreads `σₓ, σ_y` (the marginals: correlation is ignored) its Gaussian average is a
//! sum of products of 1D expectations of piecewise polynomials, integrated exactly by
//! [`axis_terms_exact`] and read by the filters from the table of [`super::kernel_table`].
//! Vector outputs use MaterialX's per-channel hash bytes; `vector4`'s fourth channel is float
//! noise at `t + (19, 73)` (`fractal2d`: `t + (19, 193)`), `fractal2d` `vector2` is two float
//! fractals at `t` and `t + (19, 193)`.

use super::hash::{self, cell_float, cell_vec3, ifloor};
use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::gaussian::{self, poly, poly_deriv, poly_mul, Poly};
use crate::graph::Source;
use crate::moments::{add_scaled, mix, mul};
use crate::value::{Filtered, Moments, ValueType};
use glam::{DVec2, Vec2};
use std::sync::OnceLock;

pub(crate) const CATEGORIES: &[&str] = &["noise2d", "fractal2d", "cellnoise2d", "worleynoise2d", "unifiednoise2d"];

/// Global statistics of a pattern (mean and variance of each output channel over the plane).
#[derive(Clone, Copy, Debug, Default)]
pub struct PatternStats {
    /// Per-channel mean.
    pub mean: [f32; 3],
    /// Per-channel variance.
    pub var: [f32; 3],
}

/// Noise operations.
#[derive(Debug)]
pub enum NoiseOp {
    /// `noise2d`
    Noise2d,
    /// `fractal2d`
    Fractal2d,
    /// `cellnoise2d`
    Cellnoise2d,
    /// `worleynoise2d`, with its statistics for its (uniform) jitter.
    Worley2d(PatternStats),
    /// `unifiednoise2d`, with the Worley statistics for its (uniform) jitter.
    Unified2d(PatternStats),
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let (inputs, types): (&'static [_], fn(ValueType) -> bool) = match category {
        "noise2d" => (
            &[inp!("amplitude", OutOrFloat, One), inp!("pivot", Float, Zero), inp!("texcoord", V2, Uv)],
            types::float_or_vector,
        ),
        "fractal2d" => (
            &[
                inp!("amplitude", OutOrFloat, One),
                inp!("octaves", Int, Splat(3.0)),
                inp!("lacunarity", OutOrFloat, Splat(2.0)),
                inp!("diminish", OutOrFloat, Half),
                inp!("texcoord", V2, Uv),
            ],
            types::float_or_vector,
        ),
        "cellnoise2d" => (&[inp!("texcoord", V2, Uv)], |t| matches!(t, ValueType::Float | ValueType::Vector3)),
        "worleynoise2d" => (&[inp!("texcoord", V2, Uv), inp!("jitter", Float, One), inp!("style", Int, Zero)], |t| {
            matches!(t, ValueType::Float | ValueType::Vector2 | ValueType::Vector3)
        }),
        "unifiednoise2d" => (
            &[
                inp!("texcoord", V2, Uv),
                inp!("freq", V2, Pair(1.0, 1.0)),
                inp!("offset", V2, Zero),
                inp!("jitter", Float, One),
                inp!("outmin", Float, Zero),
                inp!("outmax", Float, One),
                inp!("clampoutput", Bool, One),
                inp!("octaves", Int, Splat(3.0)),
                inp!("lacunarity", Float, Splat(2.0)),
                inp!("diminish", Float, Half),
                inp!("type", Int, Zero),
                inp!("style", Int, Zero),
            ],
            types::float,
        ),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &[], types, build })
}

fn build(category: &str, ty: ValueType, _: &[ValueType], srcs: &[Source], _: &[Param]) -> Result<Op, String> {
    Ok(Op::Noise(match category {
        "noise2d" => NoiseOp::Noise2d,
        "fractal2d" => NoiseOp::Fractal2d,
        "cellnoise2d" => NoiseOp::Cellnoise2d,
        "unifiednoise2d" => {
            let jitter = match &srcs[3] {
                Source::Constant(v) => v.v[0],
                _ => 1.0,
            };
            NoiseOp::Unified2d(worley_stats(jitter, 1))
        }
        _ => {
            let jitter = match &srcs[1] {
                Source::Constant(v) => v.v[0],
                _ => 1.0,
            };
            NoiseOp::Worley2d(worley_stats(jitter, ty.channels()))
        }
    }))
}

// ---------------------------------------------------------------------------------------------
// Unfiltered MaterialX Perlin noise (f32, as GLSL computes it).

#[inline]
pub(super) fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline]
fn gradient(h: u32, x: f32, y: f32) -> f32 {
    let h = h & 7;
    let u = if h < 4 { x } else { y };
    let v = 2.0 * if h < 4 { y } else { x };
    (if h & 1 != 0 { -u } else { u }) + (if h & 2 != 0 { -v } else { v })
}

/// The gradient vector `g` with `gradient(h, x, y) = g · (x, y)`.
#[inline]
fn gradient_vector(h: u32) -> DVec2 {
    let h = h & 7;
    let s1 = if h & 1 != 0 { -1.0 } else { 1.0 };
    let s2 = if h & 2 != 0 { -2.0 } else { 2.0 };
    if h < 4 {
        DVec2::new(s1, s2)
    } else {
        DVec2::new(s2, s1)
    }
}

/// Which lattice a Perlin evaluation uses: which bits of a corner hash choose the 2D gradient
/// (the whole hash for float noise, one byte for channel `k` of vector noise), or the slice
/// `z = const` of MaterialX's 3D float noise (`fractal3d` inside `unifiednoise2d`).
#[derive(Clone, Copy, Debug)]
enum HashSel {
    Full,
    Byte(u32),
    Slice(f32),
}

impl HashSel {
    #[inline]
    fn pick(self, h: u32) -> u32 {
        match self {
            HashSel::Full | HashSel::Slice(_) => h,
            HashSel::Byte(k) => (h >> (8 * k)) & 0xff,
        }
    }

    /// The lattice's gradient scale (MaterialX `mx_gradient_scale2d` / `3d`).
    #[inline]
    fn scale(self) -> f64 {
        match self {
            HashSel::Slice(_) => GRADIENT_SCALE_3D as f64,
            _ => GRADIENT_SCALE_2D as f64,
        }
    }

    /// Variance of the lattice's noise over the plane (measured; a 3D slice's varies with
    /// `z` between 0.064 and 0.077).
    #[inline]
    fn variance(self) -> f64 {
        match self {
            HashSel::Slice(_) => PERLIN3_SLICE_VARIANCE,
            _ => PERLIN_VARIANCE,
        }
    }

    /// Gaussian damping rate per axis beyond [`PERLIN_SIGMA_EXACT`].
    #[inline]
    fn kappa(self) -> f64 {
        match self {
            HashSel::Slice(_) => PERLIN3_SLICE_KAPPA,
            _ => PERLIN_KAPPA,
        }
    }

    /// The share of the lattice's variance that the filtered mean keeps at per-axis spreads
    /// `s` (the rest is variance within the footprint).
    #[inline]
    fn mean_share(self, s: DVec2) -> f64 {
        share_model(
            match self {
                HashSel::Slice(_) => PERLIN3_SLICE_SHARE,
                _ => PERLIN_SHARE,
            },
            s,
        )
    }

    /// Corner `(cx, cy)`'s kernel `g · (p − c) + k`: its in-plane gradient `g` and constant
    /// `k` (a 3D slice folds both z layers, weighted by the z fade, into them). `h2` is the
    /// corner's 2D hash.
    #[inline]
    fn corner(self, cx: i32, cy: i32, h2: u32) -> (DVec2, f64) {
        match self {
            HashSel::Slice(z) => {
                let z0 = z.floor();
                let fz = (z - z0) as f64;
                let wz = fade(fz as f32) as f64;
                let mut g = DVec2::ZERO;
                let mut k = 0.0;
                for (l, w) in [(0, 1.0 - wz), (1, wz)] {
                    if w == 0.0 {
                        continue;
                    }
                    let g3 = gradient3_vector(hash::hash3(cx, cy, (z0 as i32).wrapping_add(l)));
                    g += DVec2::new(g3[0], g3[1]) * w;
                    k += g3[2] * (fz - l as f64) * w;
                }
                (g, k)
            }
            _ => (gradient_vector(self.pick(h2)), 0.0),
        }
    }
}

/// `((1 + a σₓ²)(1 + a σ_y²))^−c (1 + b σₓ² σ_y²)^−d` for `[a, c, b, d]`: averaging along one
/// axis alone leaves variance decaying like a power of σ, averaging along both decays faster.
#[inline]
fn share_model([a, c, b, d]: [f64; 4], s: DVec2) -> f64 {
    let (x, y) = (s.x * s.x, s.y * s.y);
    ((1.0 + a * x) * (1.0 + a * y)).powf(-c) * (1.0 + b * x * y).powf(-d)
}

/// The gradient vector of MaterialX's 3D `mx_gradient_float(hash, x, y, z)`.
#[inline]
pub(super) fn gradient3_vector(h: u32) -> [f64; 3] {
    let h = h & 15;
    let mut g = [0.0; 3];
    let u = if h < 8 { 0 } else { 1 };
    let v = if h < 4 {
        1
    } else if h == 12 || h == 14 {
        0
    } else {
        2
    };
    g[u] += if h & 1 != 0 { -1.0 } else { 1.0 };
    g[v] += if h & 2 != 0 { -1.0 } else { 1.0 };
    g
}

#[inline]
pub(super) fn gradient3(h: u32, x: f32, y: f32, z: f32) -> f32 {
    let h = h & 15;
    let u = if h < 8 { x } else { y };
    let v = if h < 4 {
        y
    } else if h == 12 || h == 14 {
        x
    } else {
        z
    };
    (if h & 1 != 0 { -u } else { u }) + (if h & 2 != 0 { -v } else { v })
}

/// MaterialX `mx_perlin_noise_float(vec3)` (f32, as GLSL computes it).
pub fn perlin3_float(p: [f32; 3]) -> f32 {
    let (x0, y0, z0) = (ifloor(p[0]), ifloor(p[1]), ifloor(p[2]));
    let (fx, fy, fz) = (p[0] - p[0].floor(), p[1] - p[1].floor(), p[2] - p[2].floor());
    let (u, v, w) = (fade(fx), fade(fy), fade(fz));
    let g = |dx: i32, dy: i32, dz: i32| {
        let h = hash::hash3(x0.wrapping_add(dx), y0.wrapping_add(dy), z0.wrapping_add(dz));
        gradient3(h, fx - dx as f32, fy - dy as f32, fz - dz as f32)
    };
    let (s1, t1, r1) = (1.0 - u, 1.0 - v, 1.0 - w);
    let r = r1 * (t1 * (g(0, 0, 0) * s1 + g(1, 0, 0) * u) + v * (g(0, 1, 0) * s1 + g(1, 1, 0) * u))
        + w * (t1 * (g(0, 0, 1) * s1 + g(1, 0, 1) * u) + v * (g(0, 1, 1) * s1 + g(1, 1, 1) * u));
    GRADIENT_SCALE_3D * r
}

pub(super) const GRADIENT_SCALE_3D: f32 = 0.9820;
/// Variance of a `z = const` slice of MaterialX's 3D Perlin noise over the plane (measured,
/// averaged over `z`).
pub const PERLIN3_SLICE_VARIANCE: f64 = 0.072;
const GRADIENT_SCALE_2D: f32 = 0.6616;

/// MaterialX `mx_perlin_noise_float(vec2)` / channel of `mx_perlin_noise_vec3(vec2)`.
fn perlin_point(p: Vec2, sel: HashSel) -> f32 {
    if let HashSel::Slice(z) = sel {
        return perlin3_float([p.x, p.y, z]);
    }
    let (x0, y0) = (ifloor(p.x), ifloor(p.y));
    // The fraction from f32's own floor: the same as `p − x0` wherever `x0` fits an i32, and 0
    // (a lattice point, where the noise is 0) beyond, where every f32 is a whole number.
    let (fx, fy) = (p.x - p.x.floor(), p.y - p.y.floor());
    let (u, v) = (fade(fx), fade(fy));
    let h = |dx: i32, dy: i32| sel.pick(hash::hash2(x0.wrapping_add(dx), y0.wrapping_add(dy)));
    let v0 = gradient(h(0, 0), fx, fy);
    let v1 = gradient(h(1, 0), fx - 1.0, fy);
    let v2 = gradient(h(0, 1), fx, fy - 1.0);
    let v3 = gradient(h(1, 1), fx - 1.0, fy - 1.0);
    let s1 = 1.0 - u;
    GRADIENT_SCALE_2D * ((1.0 - v) * (v0 * s1 + v1 * u) + v * (v2 * s1 + v3 * u))
}

/// The gradient of unfiltered Perlin noise at `p` (f64, from the corner kernels).
fn perlin_gradient(p: DVec2, sel: HashSel) -> DVec2 {
    let (x0, y0) = (p.x.floor(), p.y.floor());
    let w = |d: f64| {
        let t = d.abs();
        let f = t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let df = 30.0 * t * t * (t - 1.0) * (t - 1.0);
        (1.0 - f, -df * d.signum())
    };
    let mut g = DVec2::ZERO;
    for (cx, cy) in [(x0, y0), (x0 + 1.0, y0), (x0, y0 + 1.0), (x0 + 1.0, y0 + 1.0)] {
        let (gv, k) = sel.corner(cx as i32, cy as i32, hash::hash2(cx as i32, cy as i32));
        let d = p - DVec2::new(cx, cy);
        let (wx, dwx) = w(d.x);
        let (wy, dwy) = w(d.y);
        let dot = gv.dot(d) + k;
        g.x += (gv.x * wx + dot * dwx) * wy;
        g.y += (gv.y * wy + dot * dwy) * wx;
    }
    g * sel.scale()
}

// ---------------------------------------------------------------------------------------------
// Filtered Perlin noise.

/// Per-axis spread up to which the corner sum is evaluated exactly (lattice units). Up to here
/// every corner whose kernel support `[c − 1, c + 1]` meets `m ± PERLIN_TAIL·σ` is summed
/// (at most 8 × 8 corners). Measured against brute-force supersampling of the test graphs, a
/// limit of 1.0 gained little over 0.75 in accuracy for ~35% more lattice work.
pub const PERLIN_SIGMA_EXACT: f64 = 0.75;
/// Footprint half-width, in σ, over which corners are summed: the corners left out carry under
/// 5e-5 of filtered noise (1.5e-4 of the unfiltered noise's RMS; see the tests).
pub const PERLIN_TAIL: f64 = 3.5;
/// [`PERLIN_TAIL`] for damped octaves (per-axis spread beyond [`PERLIN_SIGMA_EXACT`]), whose value
/// is the one at σₑ times a fitted damping: the corners left out carry under 1.5e-3 of it (1.5 %
/// of its RMS; see the tests), well below the damping fit's own error, and the sum visits 6 × 6
/// corners instead of 8 × 8.
pub const PERLIN_DAMPED_TAIL: f64 = 2.5;
/// Most lattice coordinates per axis that the exact sum visits: `m ± (1 + PERLIN_TAIL·σ)`
/// spans `2 + 2·PERLIN_TAIL·σ`, which meets at most one more integer than its length.
pub(super) const MAX_AXIS: usize = (2.0 + 2.0 * PERLIN_TAIL * PERLIN_SIGMA_EXACT) as usize + 1;
/// Gaussian damping rate beyond [`PERLIN_SIGMA_EXACT`]: the filtered value at per-axis
/// spreads σ is the exact one at σ clamped to σₑ, times `exp(−κ (σ² − σₑ²))` per axis beyond
/// σₑ. κ is the least-squares fit of that prediction to the exact convolution between σₑ and
/// 3σₑ (see the tests): beyond σₑ the filtered noise decorrelates from its value at σₑ, and the
/// fit balances damping what still correlates against leaving in what no longer does.
pub const PERLIN_KAPPA: f64 = 0.34;
/// [`PERLIN_KAPPA`] for a `z = const` slice of 3D Perlin noise, whose in-plane average decays
/// more slowly (each corner also carries a constant).
pub const PERLIN3_SLICE_KAPPA: f64 = 0.25;
/// `[a, c, b, d]` of the share of the variance that the filtered mean keeps (fitted to the
/// exact convolution, see the tests; [`share_model`]).
const PERLIN_SHARE: [f64; 4] = [14.8, 0.61, 42.0, 0.24];
/// [`PERLIN_SHARE`] for a `z = const` slice of 3D Perlin noise.
const PERLIN3_SLICE_SHARE: [f64; 4] = [11.1, 0.545, 464.0, 0.015];
/// Damping below which an octave counts as fully filtered (value = its mean 0).
pub const OCTAVE_CUTOFF: f64 = 1e-3;
/// Per-axis spread (lattice units) below which an octave is evaluated at the footprint centre:
/// the Gaussian average differs from the centre value by `½ tr(H Σ)`, under 1e-4 here.
pub const PERLIN_SIGMA_POINT: f64 = 0.003;
/// Variance of MaterialX's 2D Perlin noise over the plane (measured).
pub const PERLIN_VARIANCE: f64 = 0.1055;

struct Kernel {
    /// W on [-1, 0), [0, 1); d·W on the same; and their derivatives.
    w: [Poly; 2],
    dw: [Poly; 2],
    w1: [Poly; 2],
    dw1: [Poly; 2],
    /// The pieces on [-1, 0) rewritten in `y = d + 1 ∈ [0, 1)`, the offset from the cell's lower
    /// lattice coordinate, so that both pieces read the same unit-interval moments.
    w_up: Poly,
    dw_up: Poly,
    w1_up: Poly,
    dw1_up: Poly,
}

fn kernel() -> &'static Kernel {
    static K: OnceLock<Kernel> = OnceLock::new();
    K.get_or_init(|| {
        let wn = poly(&[1.0, 0.0, 0.0, 10.0, 15.0, 6.0]);
        let wp = poly(&[1.0, 0.0, 0.0, -10.0, 15.0, -6.0]);
        let d = poly(&[0.0, 1.0]);
        let (dwn, dwp) = (poly_mul(&d, &wn), poly_mul(&d, &wp));
        let up = |p: &Poly| gaussian::poly_shift_scale(p, -1.0, 1.0);
        Kernel {
            w: [wn, wp],
            dw: [dwn, dwp],
            w1: [poly_deriv(&wn), poly_deriv(&wp)],
            dw1: [poly_deriv(&dwn), poly_deriv(&dwp)],
            w_up: up(&wn),
            dw_up: up(&dwn),
            w1_up: up(&poly_deriv(&wn)),
            dw1_up: up(&poly_deriv(&dwn)),
        }
    })
}

/// 1D expectations for lattice coordinate `c`: E[W], E[dW], dE[W]/dm, dE[dW]/dm.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct AxisTerms {
    pub w: f64,
    pub dw: f64,
    pub w1: f64,
    pub dw1: f64,
}

/// Binomial coefficients C(k, i), k, i ≤ [`gaussian::MAX_DEGREE`].
const BINOMIAL: [[f64; 8]; 8] = {
    let mut c = [[0.0; 8]; 8];
    let mut k = 0;
    while k < 8 {
        c[k][0] = 1.0;
        let mut i = 1;
        while i <= k {
            c[k][i] = c[k - 1][i - 1] + if i < k { c[k - 1][i] } else { 0.0 };
            i += 1;
        }
        k += 1;
    }
    c
};

/// `E[Y^k 1{0 ≤ Y < 1}]`, k = 0..=7, for `Y = mu + s Z`, from the interval moments `i` of `Z`
/// over the corresponding standardised interval.
#[inline]
fn unit_moments(mu: f64, s: f64, i: &Poly) -> Poly {
    let mut v = *i;
    let mut sk = 1.0;
    for vk in v.iter_mut() {
        *vk *= sk;
        sk *= s;
    }
    let mut mu_pow = [1.0; 8];
    for k in 1..8 {
        mu_pow[k] = mu_pow[k - 1] * mu;
    }
    let mut r = [0.0; 8];
    for k in 0..8 {
        let mut acc = 0.0;
        for j in 0..=k {
            acc += BINOMIAL[k][j] * mu_pow[k - j] * v[j];
        }
        r[k] = acc;
    }
    r
}

#[inline]
fn dot(p: &Poly, r: &Poly) -> f64 {
    p.iter().zip(r).map(|(a, b)| a * b).sum()
}

/// The terms of every lattice coordinate `c` in `lo..=hi` (at most `N`; returns how many).
/// Coordinate `c`'s kernel has pieces on the unit cells `[c − 1, c)` and `[c, c + 1)`; each cell's
/// moments `E[y^k 1{cell}]` (y the offset from the cell's lower end) are computed once, from tail
/// moments shared at the integer boundaries, and serve both coordinates that meet the cell.
/// The filters read these through [`axis_terms`] (tabulated); this is the table's source and the
/// tests' reference.
pub(super) fn axis_terms_exact<const N: usize>(
    m: f64,
    s: f64,
    lo: i32,
    hi: i32,
    out: &mut [(i32, AxisTerms); N],
) -> usize {
    let k = kernel();
    let z = |c: i32| (c as f64 - m) / s;
    let tail = |c: i32| gaussian::TailMoments::at(z(c));
    // A cell wholly beyond the footprint's reach (both ends past `TAIL_ZERO` σ on one side) has
    // no moments: `None`, skipped without arithmetic.
    let cell = |j: i32, a: &gaussian::TailMoments, b: &gaussian::TailMoments| {
        let (za, zb) = (z(j), z(j + 1));
        (za < gaussian::TAIL_ZERO && zb > -gaussian::TAIL_ZERO)
            .then(|| unit_moments(m - j as f64, s, &gaussian::TailMoments::between(a, b)))
    };
    let mut t1 = tail(lo);
    let mut below = cell(lo - 1, &tail(lo - 1), &t1);
    let mut n = 0;
    for c in lo..=hi {
        if n >= N {
            break;
        }
        let t2 = tail(c + 1);
        let above = cell(c, &t1, &t2);
        let mut t = AxisTerms::default();
        if let Some(r) = &below {
            t.w += dot(&k.w_up, r);
            t.dw += dot(&k.dw_up, r);
            t.w1 += dot(&k.w1_up, r);
            t.dw1 += dot(&k.dw1_up, r);
        }
        if let Some(r) = &above {
            t.w += dot(&k.w[1], r);
            t.dw += dot(&k.dw[1], r);
            t.w1 += dot(&k.w1[1], r);
            t.dw1 += dot(&k.dw1[1], r);
        }
        out[n] = (c, t);
        n += 1;
        (t1, below) = (t2, above);
    }
    n
}

/// The Gaussian averages `E[q(d + sZ)]` of the kernel's derivatives, for the table of
/// [`super::kernel_table`]: `q` = W, W′, W″, W‴, dW, (dW)′, (dW)″, (dW)‴ (`s > 0`). Each is a
/// piecewise polynomial on the two unit cells around 0, so all eight read the same two sets of
/// cell moments (the third derivatives jump at 0 and ±1 but the second are continuous, so these
/// are also the `d`-derivatives of the averages).
pub(super) fn kernel_expectations(d: f64, s: f64) -> [f64; 8] {
    let z = |c: f64| (c - d) / s;
    let (t0, t1, t2) =
        (gaussian::TailMoments::at(z(-1.0)), gaussian::TailMoments::at(z(0.0)), gaussian::TailMoments::at(z(1.0)));
    // Cell [-1, 0) in y = x + 1, cell [0, 1) in y = x.
    let below = unit_moments(d + 1.0, s, &gaussian::TailMoments::between(&t0, &t1));
    let above = unit_moments(d, s, &gaussian::TailMoments::between(&t1, &t2));
    let k = kernel();
    let up = |p: &Poly| gaussian::poly_shift_scale(p, -1.0, 1.0);
    let mut out = [0.0; 8];
    for (base, (n, p)) in [(0, (k.w[0], k.w[1])), (4, (k.dw[0], k.dw[1]))] {
        let (mut n, mut p) = (n, p);
        for k in 0..4 {
            out[base + k] = dot(&up(&n), &below) + dot(&p, &above);
            n = poly_deriv(&n);
            p = poly_deriv(&p);
        }
    }
    out
}

/// [`axis_terms_exact`] as the filters use it: from the table of [`super::kernel_table`] for
/// spreads it covers (all the filters ask for), exactly beyond.
#[inline]
pub(super) fn axis_terms<const N: usize>(m: f64, s: f64, lo: i32, hi: i32, out: &mut [(i32, AxisTerms); N]) -> usize {
    if s <= super::kernel_table::S_MAX {
        super::kernel_table::axis_terms(m, s, lo, hi, out)
    } else {
        axis_terms_exact(m, s, lo, hi, out)
    }
}

/// Filtered Perlin noise for up to 4 hash selections at once: per channel (value, ∂/∂x, ∂/∂y).
/// `s` are the per-axis spreads, each in [1e-4, [`PERLIN_SIGMA_EXACT`]].
#[cfg(test)]
fn perlin_exact(p: DVec2, s: DVec2, sels: &[HashSel], out: &mut [(f64, f64, f64); 4], work: &mut crate::eval::Work) {
    perlin_exact_n::<MAX_AXIS, true>(p, s, PERLIN_TAIL, sels, out, work)
}

/// [`perlin_exact`] with room for `N` lattice coordinates per axis, i.e. for per-axis spreads up
/// to `(N − 3) / (2·PERLIN_TAIL)` (larger ones in the tests). The Gaussian average of corner
/// `c`'s kernel is `g·E[(p − c) W W] + k E[W W]`, a product of one 1D expectation per axis,
/// so each axis's expectations are computed once per lattice coordinate and the corner sum
/// combines them with the hashed gradients. `TABLE` reads the 1D expectations from the table,
/// otherwise they are integrated exactly.
fn perlin_exact_n<const N: usize, const TABLE: bool>(
    p: DVec2,
    s: DVec2,
    tail: f64,
    sels: &[HashSel],
    out: &mut [(f64, f64, f64); 4],
    work: &mut crate::eval::Work,
) {
    let mut xs = [(0i32, AxisTerms::default()); N];
    let mut ys = [(0i32, AxisTerms::default()); N];
    let fill = |m: f64, s: f64, buf: &mut [(i32, AxisTerms); N]| -> usize {
        // Every c whose support (c − 1, c + 1) meets [m − tail, m + tail].
        let lo = (m - 1.0 - tail * s).floor() as i32 + 1;
        let hi = (m + 1.0 + tail * s).ceil() as i32 - 1;
        debug_assert!(hi - lo < N as i32, "{} lattice coordinates at σ = {s}", hi - lo + 1);
        if TABLE {
            axis_terms(m, s, lo, hi, buf)
        } else {
            axis_terms_exact(m, s, lo, hi, buf)
        }
    };
    let nx = fill(p.x, s.x, &mut xs);
    let ny = fill(p.y, s.y, &mut ys);
    for o in out.iter_mut() {
        *o = (0.0, 0.0, 0.0);
    }
    for &(cy, ty) in &ys[..ny] {
        for &(cx, tx) in &xs[..nx] {
            let h = hash::hash2(cx, cy);
            for (k, sel) in sels.iter().enumerate() {
                let (g, c) = sel.corner(cx, cy, h);
                let o = &mut out[k];
                o.0 += g.x * tx.dw * ty.w + g.y * tx.w * ty.dw + c * tx.w * ty.w;
                o.1 += g.x * tx.dw1 * ty.w + g.y * tx.w1 * ty.dw + c * tx.w1 * ty.w;
                o.2 += g.x * tx.dw * ty.w1 + g.y * tx.w * ty.dw1 + c * tx.w * ty.w1;
            }
        }
    }
    work.lattice += (nx * ny) as u64;
    for (o, sel) in out.iter_mut().zip(sels) {
        let k = sel.scale();
        *o = (o.0 * k, o.1 * k, o.2 * k);
    }
}

/// One filtered Perlin octave for several channels. Returns `false` (and zeros) when the
/// footprint filters the octave out completely.
fn perlin_octave(
    p: DVec2,
    s: DVec2,
    sels: &[HashSel],
    offsets: &[DVec2],
    out: &mut [Moments; 4],
    ctx: &mut Ctx,
) -> bool {
    ctx.work.octaves += 1;
    if offsets.iter().any(|o| !within_lattice_precision(p + *o)) {
        // Where f32 coordinates are all whole numbers, every point is a lattice point and the
        // noise is 0 (the point evaluation's own result, and the total rule for any footprint).
        for o in out.iter_mut() {
            *o = Moments::default();
        }
        return true;
    }
    if s.x.max(s.y) < PERLIN_SIGMA_POINT {
        for (k, sel) in sels.iter().enumerate() {
            let q = p + offsets[k];
            let mut m = Moments::constant(perlin_point(q.as_vec2(), *sel));
            if !ctx.point {
                let g = perlin_gradient(q, *sel);
                m.grad = g.as_vec2();
                m.var = (g.x * g.x * s.x * s.x + g.y * g.y * s.y * s.y) as f32;
            }
            out[k] = m;
        }
        ctx.work.lattice += 4;
        return true;
    }
    let kappa = sels[0].kappa();
    let damp = |s: f64| {
        if s > PERLIN_SIGMA_EXACT {
            (-kappa * (s * s - PERLIN_SIGMA_EXACT * PERLIN_SIGMA_EXACT)).exp()
        } else {
            1.0
        }
    };
    let att = damp(s.x) * damp(s.y);
    if att < OCTAVE_CUTOFF {
        for o in out.iter_mut() {
            *o = Moments { mean: 0.0, grad: Vec2::ZERO, var: sels[0].variance() as f32 };
        }
        return false;
    }
    // One axis may have no spread at all (a coordinate channel that is constant): give it a
    // negligible one, since the exact corner integrals divide by σ.
    let se = s.min(DVec2::splat(PERLIN_SIGMA_EXACT)).max(DVec2::splat(1e-4));
    let mut r = [(0.0, 0.0, 0.0); 4];
    // Channels with equal offsets share one corner sum.
    let same_offset = offsets.iter().all(|o| *o == offsets[0]);
    // A damped octave (beyond σₑ on some axis) is the value at σₑ times a fitted damping: its
    // corners are summed over the shorter tail, whose error is far below the fit's.
    let tail = if att < 1.0 { PERLIN_DAMPED_TAIL } else { PERLIN_TAIL };
    let exact = |q: DVec2, sels: &[HashSel], out: &mut [(f64, f64, f64); 4], work: &mut crate::eval::Work| {
        perlin_exact_n::<MAX_AXIS, true>(q, se, tail, sels, out, work)
    };
    if same_offset {
        exact(p + offsets[0], sels, &mut r, ctx.work);
    } else {
        for (k, sel) in sels.iter().enumerate() {
            let mut one = [(0.0, 0.0, 0.0); 4];
            exact(p + offsets[k], std::slice::from_ref(sel), &mut one, ctx.work);
            r[k] = one[0];
        }
    }
    // Variance within the footprint: locally, the linearisation through the filtered gradient;
    // on average over the plane (law of total variance), what the filtered mean does not keep
    // of the lattice's variance. Blended by that share: the linearisation while the mean keeps
    // most of the variance (small footprints), the plane average as it keeps little.
    let share = sels[0].mean_share(s);
    let v_glob = sels[0].variance() * (1.0 - share);
    for k in 0..sels.len() {
        let (v, dx, dy) = (r[k].0 * att, r[k].1 * att, r[k].2 * att);
        let v_lin = dx * dx * s.x * s.x + dy * dy * s.y * s.y;
        let var = share * v_lin + (1.0 - share) * v_glob;
        out[k] = Moments { mean: v as f32, grad: Vec2::new(dx as f32, dy as f32), var: var as f32 };
    }
    true
}

/// Beyond this magnitude an f32 coordinate has no fraction: Perlin noise is 0 there.
pub(crate) const LATTICE_PRECISION_LIMIT: f64 = 16_777_216.0;

/// Whether f32 resolves the lattice cell of a noise-space coordinate (`|x|, |y|` below
/// [`LATTICE_PRECISION_LIMIT`]; false for NaN too).
#[inline]
pub(crate) fn within_lattice_precision(p: DVec2) -> bool {
    p.x.abs() < LATTICE_PRECISION_LIMIT && p.y.abs() < LATTICE_PRECISION_LIMIT
}

/// Hash selections and coordinate offsets per output channel.
fn channel_layout(ty: ValueType, fractal: bool) -> ([HashSel; 4], [DVec2; 4], usize) {
    let off = if fractal { DVec2::new(19.0, 193.0) } else { DVec2::new(19.0, 73.0) };
    let z = DVec2::ZERO;
    let b = |k| HashSel::Byte(k);
    match ty.channels() {
        1 => ([HashSel::Full; 4], [z; 4], 1),
        2 if fractal => ([HashSel::Full, HashSel::Full, HashSel::Full, HashSel::Full], [z, off, z, z], 2),
        2 => ([b(0), b(1), b(2), b(2)], [z; 4], 2),
        3 => ([b(0), b(1), b(2), b(2)], [z; 4], 3),
        _ => ([b(0), b(1), b(2), HashSel::Full], [z, z, z, off], 4),
    }
}

/// The input coordinate: mean, per-axis spread, and the Jacobian rows (d coordinate / d uv).
fn coordinate(t: &Filtered) -> (DVec2, DVec2, [Vec2; 2]) {
    let p = DVec2::new(t.ch[0].mean as f64, t.ch[1].mean as f64);
    let s = DVec2::new(t.ch[0].sigma() as f64, t.ch[1].sigma() as f64);
    (p, s, [t.ch[0].grad, t.ch[1].grad])
}

/// Maps a noise-space gradient to a uv gradient.
#[inline]
fn to_uv(m: &Moments, j: &[Vec2; 2]) -> Moments {
    use crate::moments::{add_grad, scale_grad};
    let grad = add_grad(scale_grad(j[0], m.grad.x as f64), scale_grad(j[1], m.grad.y as f64));
    Moments { mean: m.mean, grad, var: m.var }
}

fn noise2d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (amp, pivot, t) = (&ins[0], ins[1].ch[0], &ins[2]);
    let (p, s, j) = coordinate(t);
    let (sels, offs, n) = channel_layout(ty, false);
    let mut oct = [Moments::default(); 4];
    perlin_octave(p, s, &sels[..n], &offs[..n], &mut oct, ctx);
    let mut out = Filtered::zero(ty);
    for k in 0..n {
        let v = mul(to_uv(&oct[k], &j), amp.at(k), ctx.fp);
        out.ch[k] = Moments { mean: v.mean + pivot.mean, grad: v.grad + pivot.grad, var: v.var + pivot.var };
    }
    out
}

/// The most octaves a fractal sums: far more than any document asks for (a lacunarity of 2
/// leaves the f32 range after 128), and a bound on the work a node can cost.
pub const MAX_OCTAVES: u32 = 64;

/// A fractal's `octaves` input as a count: rounded, at least 0, at most [`MAX_OCTAVES`].
#[inline]
pub(crate) fn octave_count(x: f32) -> i32 {
    x.round().clamp(0.0, MAX_OCTAVES as f32) as i32
}

/// Whether a fractal octave of amplitude `a` and frequency `f` is summed. Octaves stop once the
/// amplitude leaves [1e-30, 1e30] (below, nothing an f32 sum can hold; above, beyond where a
/// value saturates) or the frequency leaves the f32 range (where every coordinate is a lattice
/// point and the noise is 0): the fractals' total rule, which also bounds their work.
#[inline]
pub(crate) fn octave_counts(a: f64, f: f64) -> bool {
    (1e-30..=1e30).contains(&a.abs()) && f.abs() <= f32::MAX as f64
}

/// `Σ (a·dimʲ)²` over the `remaining` octaves after one of amplitude `a`: the variance weight
/// of the octaves a fractal drops (each is fully filtered to its mean), stopping once the
/// amplitudes fall below 1e-4.
pub(crate) fn remaining_power(a: f64, dim: f64, remaining: i32) -> f64 {
    let mut rest = 0.0;
    let mut ai = a * dim;
    for _ in 0..remaining.clamp(0, 64) {
        if !(1e-4..=1e30).contains(&ai.abs()) {
            break;
        }
        rest += ai * ai;
        ai *= dim;
    }
    rest
}

/// Sums `octaves` filtered Perlin octaves `diminishⁱ perlin((p + offset) · lacunarityⁱ)` (in
/// noise space); `sels(f)` gives the lattices of the octave at frequency `f`.
#[allow(clippy::too_many_arguments)]
fn fractal_sum(
    p0: DVec2,
    s0: DVec2,
    octaves: i32,
    lac: f64,
    dim: f64,
    sels: impl Fn(f64) -> [HashSel; 4],
    offs: &[DVec2; 4],
    n: usize,
    ctx: &mut Ctx,
) -> [Moments; 4] {
    let mut acc = [(0.0f64, DVec2::ZERO, 0.0f64); 4];
    let (mut a, mut f) = (1.0f64, 1.0f64);
    let mut oct = [Moments::default(); 4];
    for i in 0..octaves {
        // MaterialX offsets the coordinate before the octave loop: (t + offset) · lacunarityⁱ.
        let offs_i: [DVec2; 4] = offs.map(|o| o * f);
        let sel = sels(f);
        let alive = perlin_octave(p0 * f, s0 * f.abs(), &sel[..n], &offs_i[..n], &mut oct, ctx);
        for k in 0..n {
            let o = &oct[k];
            acc[k].0 += a * o.mean as f64;
            acc[k].1 += DVec2::new(o.grad.x as f64, o.grad.y as f64) * (a * f);
            acc[k].2 += a * a * o.var as f64;
        }
        if !alive {
            // Every further octave is finer still: each contributes its mean (0) and its full
            // variance, without being evaluated.
            let rest = remaining_power(a, dim, octaves - i - 1);
            for a in acc.iter_mut().take(n) {
                a.2 += rest * sel[0].variance();
            }
            break;
        }
        a *= dim;
        f *= lac;
        if !octave_counts(a, f) {
            break;
        }
    }
    let mut out = [Moments::default(); 4];
    for k in 0..n {
        let (m, g, v) = acc[k];
        out[k] = Moments {
            mean: crate::moments::sat(m),
            grad: Vec2::new(crate::moments::sat(g.x), crate::moments::sat(g.y)),
            var: crate::moments::sat(v),
        };
    }
    out
}

fn fractal2d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let amp = &ins[0];
    let octaves = octave_count(ins[1].ch[0].mean);
    let lac = ins[2].ch[0].mean as f64;
    let dim = ins[3].ch[0].mean as f64;
    let (p0, s0, j) = coordinate(&ins[4]);
    let (sels, offs, n) = channel_layout(ty, true);
    let sum = fractal_sum(p0, s0, octaves, lac, dim, |_| sels, &offs, n, ctx);
    let mut out = Filtered::zero(ty);
    for k in 0..n {
        out.ch[k] = mul(to_uv(&sum[k], &j), amp.at(k), ctx.fp);
    }
    out
}

/// Unfiltered fractal noise (for tests and the point path).
pub fn fractal_point(p: Vec2, octaves: i32, lacunarity: f32, diminish: f32) -> f32 {
    let (mut r, mut a, mut q) = (0.0f64, 1.0f64, p);
    for _ in 0..octaves.min(MAX_OCTAVES as i32) {
        if !(octave_counts(a, 1.0) && q.is_finite()) {
            break;
        }
        r += a * perlin_point(q, HashSel::Full) as f64;
        a *= diminish as f64;
        q *= lacunarity;
    }
    r as f32
}

/// Unfiltered float Perlin noise at `p` (MaterialX `mx_perlin_noise_float(vec2)`).
pub fn perlin_float(p: Vec2) -> f32 {
    perlin_point(p, HashSel::Full)
}

// ---------------------------------------------------------------------------------------------
// Cell noise.

/// Per-axis spread (cells) up to which cell noise is filtered exactly.
pub const CELL_SIGMA_EXACT: f64 = 0.5;

fn cell_value(ix: i32, iy: i32, k: usize, vector: bool) -> f32 {
    if vector {
        cell_vec3(ix, iy, k as i32)
    } else {
        cell_float(ix, iy)
    }
}

fn cellnoise2d(ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
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

// ---------------------------------------------------------------------------------------------
// Worley noise.

/// Unfiltered MaterialX `mx_worley_noise_*(vec2)` (Euclidean metric): the `n` nearest
/// distances (style 0) or the nearest feature's cell value(s) (style 1).
pub fn worley_point(p: Vec2, jitter: f32, style: i32, n: usize) -> [f32; 3] {
    let (x0, y0) = (ifloor(p.x), ifloor(p.y));
    let local = Vec2::new(p.x - x0 as f32, p.y - y0 as f32);
    let mut d = [1e6f32; 3];
    let mut minpos = Vec2::ZERO;
    for x in -1..=1 {
        for y in -1..=1 {
            let (cx, cy) = (x0.wrapping_add(x), y0.wrapping_add(y));
            let off = Vec2::new(cell_vec3(cx, cy, 0), cell_vec3(cx, cy, 1));
            let off = (off - 0.5) * jitter + 0.5;
            let cell = Vec2::new(x as f32, y as f32) + off - local;
            let dist = cell.dot(cell);
            if dist < d[0] {
                d[2] = d[1];
                d[1] = d[0];
                d[0] = dist;
                minpos = cell;
            } else if dist < d[1] {
                d[2] = d[1];
                d[1] = dist;
            } else if dist < d[2] {
                d[2] = dist;
            }
        }
    }
    if style == 1 {
        let q = minpos + p;
        let (ix, iy) = (ifloor(q.x), ifloor(q.y));
        if n == 1 {
            [cell_float(ix, iy), 0.0, 0.0]
        } else {
            [cell_vec3(ix, iy, 0), cell_vec3(ix, iy, 1), cell_vec3(ix, iy, 2)]
        }
    } else {
        [d[0].sqrt(), d[1].sqrt(), d[2].sqrt()]
    }
}

fn worley_stats(jitter: f32, n: usize) -> PatternStats {
    let (mut s, mut s2) = ([0.0f64; 3], [0.0f64; 3]);
    let res = 40;
    let count = (res * res) as f64;
    for i in 0..res {
        for j in 0..res {
            let p = Vec2::new(3.0 + 6.0 * (i as f32 + 0.5) / res as f32, -7.0 + 6.0 * (j as f32 + 0.5) / res as f32);
            let v = worley_point(p, jitter, 0, n);
            for k in 0..3 {
                s[k] += v[k] as f64;
                s2[k] += (v[k] as f64).powi(2);
            }
        }
    }
    let mut st = PatternStats::default();
    for k in 0..3 {
        st.mean[k] = (s[k] / count) as f32;
        st.var[k] = (s2[k] / count - (s[k] / count).powi(2)).max(0.0) as f32;
    }
    st
}

fn worley2d(stats: &PatternStats, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (p, s, j) = coordinate(&ins[0]);
    let jitter = ins[1].ch[0].mean;
    let style = ins[2].ch[0].mean.round() as i32;
    let n = ty.channels();
    let mut out = Filtered::zero(ty);
    let (gmean, gvar) = if style == 1 { ([0.5; 3], [1.0 / 12.0; 3]) } else { (stats.mean, stats.var) };
    let smax = s.x.max(s.y);
    if smax == 0.0 {
        let v = worley_point(p.as_vec2(), jitter, style, n);
        for k in 0..n {
            out.ch[k] = Moments::constant(v[k]);
        }
        ctx.work.lattice += 9;
        return out;
    }
    let w_global = ((smax - 1.0) / 1.0).clamp(0.0, 1.0);
    if w_global >= 1.0 {
        for k in 0..n {
            out.ch[k] = Moments { mean: gmean[k], grad: Vec2::ZERO, var: gvar[k] };
        }
        return out;
    }
    let (mut e, mut e2, mut ex, mut ey) = ([0.0f64; 3], [0.0f64; 3], [0.0f64; 3], [0.0f64; 3]);
    // 3×3 nodes suffice while the footprint is small against a cell; 5×5 beyond.
    let rule: &[(f64, f64)] = if smax < 0.2 { &gaussian::HERMITE3 } else { &gaussian::HERMITE5 };
    for &(zy, wy) in rule {
        for &(zx, wx) in rule {
            let q = p + DVec2::new(zx * s.x, zy * s.y);
            let v = worley_point(q.as_vec2(), jitter, style, n);
            for k in 0..n {
                let w = wx * wy;
                let vk = v[k] as f64;
                e[k] += w * vk;
                e2[k] += w * vk * vk;
                ex[k] += w * zx * vk;
                ey[k] += w * zy * vk;
            }
        }
    }
    ctx.work.lattice += 9 * (rule.len() * rule.len()) as u64;
    for k in 0..n {
        let var = (e2[k] - e[k] * e[k]).max(0.0);
        let gx = if s.x > 0.0 { ex[k] / s.x } else { 0.0 };
        let gy = if s.y > 0.0 { ey[k] / s.y } else { 0.0 };
        let wl = 1.0 - w_global;
        let m = Moments {
            mean: (wl * e[k] + w_global * gmean[k] as f64) as f32,
            grad: Vec2::new((wl * gx) as f32, (wl * gy) as f32),
            var: (wl * var + w_global * gvar[k] as f64) as f32,
        };
        out.ch[k] = to_uv(&m, &j);
    }
    out
}

/// The angle (degrees) by which `unifiednoise2d` rotates its Perlin and cell lattices, and the
/// z of its `fractal3d` slice, per unit of `jitter − 1`.
const UNIFIED_JITTER_SCALE: f32 = 90000.0;

/// unifiednoise's rotation (degrees) for a `jitter`: `(jitter − 1) · 90000`, reduced modulo 360°
/// where that overflows f32 (the total rule: an infinite angle has no sine).
pub(crate) fn unified_spin(jitter: f32) -> f32 {
    let spin = (jitter - 1.0) * UNIFIED_JITTER_SCALE;
    if spin.is_finite() {
        spin
    } else {
        ((jitter as f64 - 1.0) * UNIFIED_JITTER_SCALE as f64).rem_euclid(360.0) as f32
    }
}

fn unified2d(stats: &PatternStats, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (t, freq, off, jitter) = (&ins[0], &ins[1], &ins[2], ins[3].ch[0].mean);
    let (outmin, outmax) = (ins[4].ch[0], ins[5].ch[0]);
    let clamp = ins[6].ch[0].mean > 0.5;
    let octaves = octave_count(ins[7].ch[0].mean);
    let (lac, dim) = (ins[8].ch[0].mean as f64, ins[9].ch[0].mean as f64);
    let kind = ins[10].ch[0].mean.round() as i32;
    // p = texcoord · freq + offset (exact: affine in the inputs).
    let mut p = Filtered::zero(ValueType::Vector2);
    for k in 0..2 {
        p.ch[k] = add_scaled(mul(t.ch[k], freq.ch[k], ctx.fp), off.ch[k], 1.0, ctx.fp);
    }
    let spin = unified_spin(jitter);
    let raw = match kind {
        0 | 1 => {
            let mut pr = p;
            if spin != 0.0 {
                let (x, y) = super::geometry::rotate(p.ch[0], p.ch[1], spin, ctx);
                pr.ch[0] = x;
                pr.ch[1] = y;
            }
            if kind == 0 {
                let half = Filtered::constant(crate::value::Value::float(0.5));
                noise2d(ValueType::Float, &[half, half, pr], ctx).ch[0]
            } else {
                cellnoise2d(ValueType::Float, &[pr], ctx).ch[0]
            }
        }
        2 => worley2d(stats, ValueType::Float, &[p, ins[3], ins[11]], ctx).ch[0],
        3 => {
            let (p0, s0, j) = coordinate(&p);
            let sels = |f: f64| [HashSel::Slice((spin as f64 * f) as f32); 4];
            let sum = fractal_sum(p0, s0, octaves, lac, dim, sels, &[DVec2::ZERO; 4], 1, ctx);
            to_uv(&sum[0], &j)
        }
        _ => Moments::default(),
    };
    // range(raw, 0, 1 → outmin, outmax), clamped to [outmin, outmax]: the clamp acts on raw.
    let w = if clamp { super::pattern::clamp01(raw) } else { raw };
    let mut out = Filtered::zero(ty);
    out.ch[0] = mix(outmin, outmax, w, ctx.fp);
    out
}

pub(crate) fn eval(op: &NoiseOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    match op {
        NoiseOp::Noise2d => noise2d(ty, ins, ctx),
        NoiseOp::Fractal2d => fractal2d(ty, ins, ctx),
        NoiseOp::Cellnoise2d => cellnoise2d(ty, ins, ctx),
        NoiseOp::Worley2d(st) => worley2d(st, ty, ins, ctx),
        NoiseOp::Unified2d(st) => unified2d(st, ty, ins, ctx),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Room for spreads up to 3.8 lattice units: the references beyond [`PERLIN_SIGMA_EXACT`].
    const WIDE: usize = 32;

    /// The exact convolution at any spread (per channel: value, ∂/∂x, ∂/∂y).
    fn exact_wide(p: DVec2, s: DVec2, sel: HashSel) -> (f64, f64, f64) {
        let mut o = [(0.0, 0.0, 0.0); 4];
        perlin_exact_n::<WIDE, false>(
            p,
            s.max(DVec2::splat(1e-4)),
            PERLIN_TAIL,
            &[sel],
            &mut o,
            &mut crate::eval::Work::default(),
        );
        o[0]
    }

    /// Centres spread over many lattice cells (incommensurate steps).
    fn centres() -> Vec<DVec2> {
        let mut v = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                v.push(DVec2::new(0.37 + i as f64 * 0.6173, 0.11 + j as f64 * 0.5791));
            }
        }
        v
    }

    fn field(s: DVec2, sel: HashSel) -> Vec<f64> {
        centres().iter().map(|&p| exact_wide(p, s, sel).0).collect()
    }

    fn mean_square(v: impl Iterator<Item = f64>) -> f64 {
        let (mut acc, mut n) = (0.0, 0.0);
        for x in v {
            acc += x * x;
            n += 1.0;
        }
        acc / n
    }

    const LATTICES: [HashSel; 2] = [HashSel::Full, HashSel::Slice(0.37)];

    /// The global variance of Perlin noise (`PERLIN_VARIANCE`).
    #[test]
    fn perlin_variance() {
        let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..400 {
            for j in 0..400 {
                let v = perlin_float(Vec2::new(0.013 + i as f32 * 0.0517, 0.029 + j as f32 * 0.0491)) as f64;
                s += v;
                s2 += v * v;
                n += 1.0;
            }
        }
        let var = s2 / n - (s / n).powi(2);
        println!("perlin variance {var:.4}");
        assert!((var - PERLIN_VARIANCE).abs() < 0.005, "variance {var}");
    }

    /// The corner sum is the Gaussian average of the unfiltered noise, up to and beyond
    /// [`PERLIN_SIGMA_EXACT`] (against brute-force quadrature over ±6σ, which sees every
    /// corner), and its derivatives are those of the value.
    #[test]
    fn exact_matches_brute_force() {
        let cases = [
            (DVec2::new(0.3, -1.7), DVec2::new(0.25, 0.25), HashSel::Full),
            (DVec2::new(2.61, 0.45), DVec2::new(0.6, 0.35), HashSel::Full),
            (DVec2::new(-3.2, 5.05), DVec2::new(1.0, 1.0), HashSel::Full),
            (DVec2::new(7.9, -0.2), DVec2::new(1.0, 0.1), HashSel::Byte(1)),
            (DVec2::new(1.37, 2.61), DVec2::new(0.8, 0.5), HashSel::Slice(0.37)),
            (DVec2::new(-4.1, 3.3), DVec2::new(1.6, 1.2), HashSel::Full),
        ];
        for (p, s, sel) in cases {
            let n = 400;
            let mut acc = 0.0;
            let mut wsum = 0.0;
            for i in 0..n {
                let zx = -6.0 + 12.0 * (i as f64 + 0.5) / n as f64;
                let wx = (-0.5 * zx * zx).exp();
                for j in 0..n {
                    let zy = -6.0 + 12.0 * (j as f64 + 0.5) / n as f64;
                    let w = wx * (-0.5 * zy * zy).exp();
                    let q = p + DVec2::new(zx * s.x, zy * s.y);
                    acc += w * perlin_point(q.as_vec2(), sel) as f64;
                    wsum += w;
                }
            }
            let brute = acc / wsum;
            let (v, dx, dy) = exact_wide(p, s, sel);
            let mut o = [(0.0, 0.0, 0.0); 4];
            if s.max_element() <= PERLIN_SIGMA_EXACT {
                perlin_exact(p, s, &[sel], &mut o, &mut crate::eval::Work::default());
                // The filters' tabulated kernel terms against the exact ones.
                assert!((o[0].0 - v).abs() < 5e-6, "table {} vs exact {v}", o[0].0);
            }
            let h = 1e-4;
            let fdx = (exact_wide(p + DVec2::X * h, s, sel).0 - exact_wide(p - DVec2::X * h, s, sel).0) / (2.0 * h);
            let fdy = (exact_wide(p + DVec2::Y * h, s, sel).0 - exact_wide(p - DVec2::Y * h, s, sel).0) / (2.0 * h);
            println!(
                "{p} σ {s} {sel:?}: exact {v:.6} brute {brute:.6}; d/dx {dx:.5} ({fdx:.5}) d/dy {dy:.5} ({fdy:.5})"
            );
            assert!((v - brute).abs() < 2e-5, "exact {v} vs brute force {brute}");
            assert!((dx - fdx).abs() < 1e-6 && (dy - fdy).abs() < 1e-6);
        }
    }

    /// Damped octaves sum their corners over ±`PERLIN_DAMPED_TAIL`·σₑ: against the full tail the
    /// value moves by under 1.5e-3 (1.08e-3 measured), 2 % of its RMS at σₑ.
    #[test]
    fn damped_tail_is_small_beside_the_value() {
        let (mut worst, mut sq, mut n) = (0.0f64, 0.0, 0.0);
        for k in 0..4000 {
            let p = DVec2::new((k as f64 * 0.61803) % 50.0, (k as f64 * 0.7548) % 50.0);
            let s = DVec2::new(
                PERLIN_SIGMA_EXACT,
                if k % 2 == 0 { PERLIN_SIGMA_EXACT } else { 0.2 + (k as f64 * 0.1) % 0.55 },
            );
            let (mut a, mut b) = ([(0.0, 0.0, 0.0); 4], [(0.0, 0.0, 0.0); 4]);
            let w = &mut crate::eval::Work::default();
            perlin_exact_n::<MAX_AXIS, true>(p, s, PERLIN_TAIL, &[HashSel::Full], &mut a, w);
            perlin_exact_n::<MAX_AXIS, true>(p, s, PERLIN_DAMPED_TAIL, &[HashSel::Full], &mut b, w);
            worst = worst.max((a[0].0 - b[0].0).abs());
            sq += a[0].0 * a[0].0;
            n += 1.0;
        }
        let rms = (sq / n).sqrt();
        println!("damped tail: worst {worst:.2e}, value RMS {rms:.3e}");
        assert!(worst < 1.5e-3 && worst < 0.02 * rms, "worst {worst:.2e} against RMS {rms:.3e}");
    }

    /// The corners beyond ±`PERLIN_TAIL`·σ carry under 5e-5 of filtered noise (against a sum
    /// over ±6σ).
    #[test]
    fn tail_is_negligible() {
        let mut worst: f64 = 0.0;
        for &sg in &[0.1, 0.25, 0.5, 0.75, PERLIN_SIGMA_EXACT] {
            for (k, &p) in centres().iter().enumerate().step_by(7) {
                let s = DVec2::new(sg, sg * (0.3 + 0.7 * (k % 5) as f64 / 4.0));
                let mut o = [(0.0, 0.0, 0.0); 4];
                perlin_exact(p, s, &[HashSel::Full], &mut o, &mut crate::eval::Work::default());
                // Reference: every corner within ±6σ, by widening the spread's tail.
                let (mut refv, mut xs, mut ys) =
                    (0.0, [(0, AxisTerms::default()); WIDE], [(0, AxisTerms::default()); WIDE]);
                let wide = |m: f64, s: f64, buf: &mut [(i32, AxisTerms); WIDE]| {
                    axis_terms_exact(m, s, (m - 1.0 - 6.0 * s).floor() as i32, (m + 1.0 + 6.0 * s).ceil() as i32, buf)
                };
                let nx = wide(p.x, s.x, &mut xs);
                let ny = wide(p.y, s.y, &mut ys);
                for &(cy, ty) in &ys[..ny] {
                    for &(cx, tx) in &xs[..nx] {
                        let g = gradient_vector(hash::hash2(cx, cy));
                        refv += g.x * tx.dw * ty.w + g.y * tx.w * ty.dw;
                    }
                }
                worst = worst.max((o[0].0 - refv * GRADIENT_SCALE_2D as f64).abs());
            }
        }
        println!("largest tail left out: {worst:.2e}");
        assert!(worst < 5e-5, "{worst}");
    }

    /// The damping rates: least-squares fits of `exact(σₑ) · Π exp(−κ (σ² − σₑ²))` to the exact
    /// convolution at σ, for isotropic and anisotropic spreads from 1.1 σₑ to 3 σₑ (σₑ =
    /// [`PERLIN_SIGMA_EXACT`]). The constants sit at the fitted minimum, and the damped value
    /// is closer to the exact one than either the undamped value or dropping the octave.
    #[test]
    fn damping_fit() {
        let l = PERLIN_SIGMA_EXACT;
        let mut failures = Vec::new();
        for sel in LATTICES {
            let m0 = mean_square(field(DVec2::ZERO, sel).into_iter());
            let steps = [1.1, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0];
            // Families: (σ, σ), (σ, σₑ), (σ, 0.3 σₑ); each against its clamped evaluation.
            let mut pairs = Vec::new();
            for (lo_y, fam) in [(1.0, 0), (1.0, 1), (0.3, 2)] {
                let base = field(DVec2::new(l, lo_y * l), sel);
                for &t in &steps {
                    let sg = t * l;
                    let s = match fam {
                        0 => DVec2::splat(sg),
                        _ => DVec2::new(sg, lo_y * l),
                    };
                    let axes_beyond = if fam == 0 { 2.0 } else { 1.0 };
                    pairs.push((axes_beyond * (sg * sg - l * l), field(s, sel), base.clone()));
                }
            }
            let err = |kappa: f64| -> f64 {
                pairs
                    .iter()
                    .map(|(e, f, b)| mean_square(f.iter().zip(b).map(|(x, y)| x - (-kappa * e).exp() * y)))
                    .sum::<f64>()
                    / m0
            };
            let (mut best, mut best_err) = (0.0, f64::MAX);
            for i in 1..=120 {
                let k = i as f64 * 0.01;
                let e = err(k);
                if e < best_err {
                    (best, best_err) = (k, e);
                }
            }
            let kappa = sel.kappa();
            let (e_const, e_none, e_drop) = (err(kappa), err(0.0), err(1e6));
            println!(
                "{sel:?}: fitted kappa {best:.2} (rms error {:.4} of the unfiltered rms); constant {kappa}: {:.4}; undamped {:.4}; dropped {:.4}",
                best_err.sqrt(),
                e_const.sqrt(),
                e_none.sqrt(),
                e_drop.sqrt()
            );
            if e_const > best_err * 1.02 || e_const > 0.5 * e_none.min(e_drop) {
                failures.push(format!("{sel:?}: kappa {kappa} is off the fit {best}"));
            }
        }
        assert!(failures.is_empty(), "{failures:?}");
    }

    /// The share of the lattice's variance that the filtered mean keeps (measured from the exact
    /// convolution over a grid of per-axis spreads) against [`HashSel::mean_share`], and the
    /// least-squares fit of [`share_model`]'s parameters (coordinate descent from the constants).
    #[test]
    fn mean_share_fit() {
        let grid = [0.0, 0.1, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0];
        for sel in LATTICES {
            let m0 = mean_square(field(DVec2::ZERO, sel).into_iter());
            let mut pts = Vec::new();
            for (i, &x) in grid.iter().enumerate() {
                for &y in &grid[..=i] {
                    pts.push((DVec2::new(x, y), mean_square(field(DVec2::new(x, y), sel).into_iter()) / m0));
                }
            }
            let err = |q: [f64; 4]| {
                (pts.iter().map(|&(s, r)| (share_model(q, s) - r).powi(2)).sum::<f64>() / pts.len() as f64).sqrt()
            };
            let konst = match sel {
                HashSel::Slice(_) => PERLIN3_SLICE_SHARE,
                _ => PERLIN_SHARE,
            };
            let mut q = konst;
            let mut step = 0.2;
            for _ in 0..400 {
                let mut moved = false;
                for k in 0..4 {
                    for f in [1.0 + step, 1.0 / (1.0 + step)] {
                        let mut t = q;
                        t[k] *= f;
                        if err(t) < err(q) {
                            q = t;
                            moved = true;
                        }
                    }
                }
                if !moved {
                    step *= 0.5;
                }
            }
            let worst = pts.iter().map(|&(s, r)| (sel.mean_share(s) - r).abs()).fold(0.0, f64::max);
            println!(
                "{sel:?}: fitted {q:.3?} (rms {:.4}); constants {konst:?}: rms {:.4}, worst {worst:.4}",
                err(q),
                err(konst)
            );
            for &(s, r) in &pts {
                println!("  σ ({:.2}, {:.2}): share {r:.4}, model {:.4}", s.x, s.y, sel.mean_share(s));
            }
            assert!(err(konst) <= err(q) * 1.05 + 1e-4, "{sel:?}: off the fit");
            assert!(worst < 0.03, "{sel:?}: worst {worst}");
        }
    }
}

#[cfg(test)]
mod slice_tests {
    use super::*;

    /// The 3D slice lattice reproduces unfiltered 3D Perlin noise through the corner kernels,
    /// and prints its variance over the plane at a few slices.
    #[test]
    fn perlin3_slice() {
        for &z in &[0.0f32, 0.3, 0.5, 0.9012] {
            let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0.0f64);
            for i in 0..300 {
                for j in 0..300 {
                    let p = Vec2::new(0.013 + i as f32 * 0.0517, 0.029 + j as f32 * 0.0491);
                    let v = perlin3_float([p.x, p.y, z]) as f64;
                    s += v;
                    s2 += v * v;
                    n += 1.0;
                }
            }
            println!("z {z}: variance {:.4}", s2 / n - (s / n).powi(2));
            // Filtered at a tiny footprint = the point value.
            let p = DVec2::new(1.37, -2.61);
            let mut o = [(0.0, 0.0, 0.0); 4];
            let mut work = crate::eval::Work::default();
            perlin_exact(p, DVec2::splat(1e-4), &[HashSel::Slice(z)], &mut o, &mut work);
            let v = perlin3_float([p.x as f32, p.y as f32, z]) as f64;
            assert!((o[0].0 - v).abs() < 1e-4, "z {z}: {} vs {v}", o[0].0);
        }
    }
}
