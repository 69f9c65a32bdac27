//! Flakes: `flake2d`, `flake3d` (MaterialX 1.39's `ND_flake2d`, `ND_flake3d`), nodes of four
//! outputs of mixed types.
//!
//! | input | type | default |
//! |---|---|---|
//! | `size` | float | 0.01 |
//! | `roughness` | float | 0.1 |
//! | `coverage` | float | 0.5 |
//! | `texcoord` (`flake2d`) | vector2 | UV0 |
//! | `position` (`flake3d`) | vector3 | the shading point's position |
//! | `normal`, `tangent`, `bitangent` | vector3 | the shading frame |
//!
//! | output | type | no flake |
//! |---|---|---|
//! | `id` | integer | 0 |
//! | `rand` | float | 0 |
//! | `presence` | float | 0 |
//! | `flakenormal` | vector3 | `normal` |
//!
//! tessera's graph values have one type each, so a document's `flake2d` node becomes one library
//! node per output it connects (`nodename` + `output`), each with the same inputs and its
//! output named by the [`Param`] `output` (absent: the output of the node's type, `rand` for
//! float). Each evaluates the flake lookup of its point on its own; they agree wherever they are
//! evaluated at the same footprint.
//!
//! **Unfiltered** (MaterialX's GLSL `mx_flake`, `flake2d` being `flake3d` at `(u, v, 0)`). With
//! `P = position / size` and the cell `⌊P⌋`, each of the 3 × 3 × 3 cells `q` around it holds a
//! flake when `cell(q) ≤ p(coverage)` (MaterialX's fitted rational density-to-probability curve
//! of the coverage clamped to [0, 1]); the flake is a cube of half-width `1.5/√3` about the
//! cell's centre, rotated by Arvo's random rotation of `cellvec3(q)`, and considered only where
//! `|P − q − ½|² < 3 · (1.5/√3)²`. Of the flakes containing `P`, the one of highest priority
//! `cell(q, 3)` wins (later cells on ties). Its `cellvec3(q, 2) = (ξ₀, ξ₁, r)` give
//! `rand = r`, `id = ⌊r (2²⁴ − 1)⌋`, `presence` = the priority, and the normal
//! `normalize(T cos φ sin θ + B sin φ sin θ + N cos θ)`, `φ = 2π ξ₀`,
//! `tan θ = roughness² √(ξ₁/(1 − ξ₁))` (a GGX sample). The classification is computed in `f32`,
//! as the shader does, so that bakes agree texel for texel.
//!
//! **Filtered.** The outputs are constant over each flake and jump at its edges. Over the
//! footprint carried by the coordinate (its gradients map the uv footprint to `P`), the node
//! returns the mean and variance of the point values at the 5 × 5 Gauss–Hermite nodes of the uv
//! footprint (at the centre alone for a point); the gradient is 0 (piecewise constant). Once the
//! footprint spans flakes (σ of `P` from ½ to 2 cells, a smoothstep in `log σ`), the result moves
//! to the ensemble: the mean and variance over a fixed 8 × 8 stratified set of points covering
//! 64 cells about the centre, so that coarse footprints see the flakes' coverage, not a few
//! cells' values.
//!
//! **Totality.** `size` of magnitude below 1e-30 is taken as ±1e-30; cells beyond ±2³⁰ wrap in
//! `i32` as MaterialX's `int` does (saturating casts); `tan θ` of `ξ₁ = 1` or of a huge
//! roughness gives `sin θ = 1`; a zero normal sum gives 0.

use super::{hash, hextile, inp, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::{GeomProp, Source};
use crate::value::{Filtered, Moments, ValueType};
use glam::{DMat2, DVec2, Vec2, Vec3};

pub(crate) const CATEGORIES: &[&str] = &["flake2d", "flake3d"];

/// Which output of a flake node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlakeOutput {
    /// `id` (integer).
    Id,
    /// `rand` (float).
    Rand,
    /// `presence` (float).
    Presence,
    /// `flakenormal` (vector3).
    Normal,
}

/// A flake node: its dimension and output.
#[derive(Debug)]
pub struct FlakeOp {
    three_d: bool,
    output: FlakeOutput,
}

/// The outputs of a flake node, in the nodedef's order.
pub const OUTPUTS: [&str; 4] = ["id", "rand", "presence", "flakenormal"];

/// The type of output `name` of a flake node.
pub fn output_type(name: &str) -> Option<ValueType> {
    Some(match name {
        "id" => ValueType::Integer,
        "rand" | "presence" => ValueType::Float,
        "flakenormal" => ValueType::Vector3,
        _ => return None,
    })
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let inputs: &'static [_] = match category {
        "flake2d" => &[
            inp!("size", Float, Splat(0.01)),
            inp!("roughness", Float, Splat(0.1)),
            inp!("coverage", Float, Half),
            inp!("texcoord", V2, Uv),
            inp!("normal", V3, Geom(GeomProp::Normal)),
            inp!("tangent", V3, Geom(GeomProp::Tangent)),
            inp!("bitangent", V3, Geom(GeomProp::Bitangent)),
        ],
        "flake3d" => &[
            inp!("size", Float, Splat(0.01)),
            inp!("roughness", Float, Splat(0.1)),
            inp!("coverage", Float, Half),
            inp!("position", V3, Geom(GeomProp::Position)),
            inp!("normal", V3, Geom(GeomProp::Normal)),
            inp!("tangent", V3, Geom(GeomProp::Tangent)),
            inp!("bitangent", V3, Geom(GeomProp::Bitangent)),
        ],
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef {
        category,
        inputs,
        params: &["output"],
        types: |t| matches!(t, ValueType::Integer | ValueType::Float | ValueType::Vector3),
        build,
    })
}

fn build(category: &str, ty: ValueType, _: &[ValueType], _: &[Source], params: &[Param]) -> Result<Op, String> {
    let named = params.iter().find_map(|p| match p {
        Param::Str { name, value } if name == "output" => Some(value.trim()),
        _ => None,
    });
    let output = match named {
        Some("id") => FlakeOutput::Id,
        Some("rand") => FlakeOutput::Rand,
        Some("presence") => FlakeOutput::Presence,
        Some("flakenormal") => FlakeOutput::Normal,
        Some(o) => {
            return Err(format!("`{category}` has no output `{o}`; its outputs: id, rand, presence, flakenormal"))
        }
        None => match ty {
            ValueType::Integer => FlakeOutput::Id,
            ValueType::Vector3 => FlakeOutput::Normal,
            _ => FlakeOutput::Rand,
        },
    };
    let want = match output {
        FlakeOutput::Id => ValueType::Integer,
        FlakeOutput::Rand | FlakeOutput::Presence => ValueType::Float,
        FlakeOutput::Normal => ValueType::Vector3,
    };
    if want != ty {
        return Err(format!("`{category}`'s output `{output:?}` is a {want}, not a {ty}"));
    }
    Ok(Op::Flake(FlakeOp { three_d: category == "flake3d", output }))
}

/// MaterialX's fitted curve from coverage density to the probability that a cell holds a flake.
fn density_to_probability(x: f32) -> f32 {
    let (a, b, c, d, e, f) = (-26.197_718, 26.396_639, 85.538_57, -102.350_69, -101.426_35, 118.450_82);
    let xx = x * x;
    (a * xx + b * x) / (c * xx * x + d * xx + e * x + f)
}

/// Arvo's random rotation of `i` (three values in [0, 1)) applied to `p`, as MaterialX's
/// `mx_rotate_flake` (GLSL's column-major `mat3` written out).
fn rotate_flake(p: Vec3, i: Vec3) -> Vec3 {
    let theta = std::f32::consts::PI * 2.0 * i.x;
    let phi = std::f32::consts::PI * 2.0 * i.y;
    let z = i.z * 2.0;
    let r = z.sqrt();
    let (vx, vy, vz) = (phi.sin() * r, phi.cos() * r, (2.0 - z).max(0.0).sqrt());
    let (st, ct) = theta.sin_cos();
    let sx = vx * ct - vy * st;
    let sy = vx * st + vy * ct;
    let c0 = Vec3::new(vx * sx - ct, vx * sy - st, vx * vz);
    let c1 = Vec3::new(vy * sx + st, vy * sy - ct, vy * vz);
    let c2 = Vec3::new(vz * sx, vz * sy, 1.0 - z);
    c0 * p.x + c1 * p.y + c2 * p.z
}

/// The flake at a point: (id, rand, presence, normal), or `None` where there is none.
pub fn flake_at(
    size: f32,
    roughness: f32,
    coverage: f32,
    pos: Vec3,
    frame: [Vec3; 3],
) -> Option<(i32, f32, f32, Vec3)> {
    let probability = density_to_probability(coverage.clamp(0.0, 1.0));
    let diameter = 1.5 / 3.0f32.sqrt();
    let size = if size.abs() < 1e-30 { 1e-30f32.copysign(size) } else { size };
    let p = pos / size;
    let base = p.floor();
    let (mut priority, mut cell) = (0.0f32, [0i32; 3]);
    for i in -1..2 {
        for j in -1..2 {
            for k in -1..2 {
                let q = base + Vec3::new(i as f32, j as f32, k as f32);
                let pp = p - q - Vec3::splat(0.5);
                if pp.dot(pp) >= diameter * diameter * 3.0 {
                    continue;
                }
                let c = [q.x as i32, q.y as i32, q.z as i32];
                if hash::cell3_float(c[0], c[1], c[2]) > probability {
                    continue;
                }
                let pr = hash::cell4_float(c[0], c[1], c[2], 3);
                if pr < priority {
                    continue;
                }
                let rot = Vec3::from_array([0, 1, 2].map(|ch| hash::cell3_vec3(c[0], c[1], c[2], ch)));
                let r = rotate_flake(pp, rot);
                if r.x.abs() <= diameter && r.y.abs() <= diameter && r.z.abs() <= diameter {
                    priority = pr;
                    cell = c;
                }
            }
        }
    }
    if priority <= 0.0 {
        return None;
    }
    let [xi0, xi1, rand] = [0, 1, 2].map(|k| hash::cell4_vec3(cell[0], cell[1], cell[2], 2, k));
    let id = (rand * 16_777_215.0) as i32;
    let phi = std::f32::consts::PI * 2.0 * xi0;
    let tan = roughness * roughness * xi1.sqrt() / (1.0 - xi1).sqrt();
    let sec2 = 1.0 + tan * tan;
    let sin = if sec2.is_finite() { tan / sec2.sqrt() } else { 1.0 };
    let sin = if sin.is_finite() { sin.clamp(-1.0, 1.0) } else { 1.0 };
    let cos = (1.0 - sin * sin).max(0.0).sqrt();
    let [n, t, b] = frame;
    let normal = (t * (phi.cos() * sin) + b * (phi.sin() * sin) + n * cos).normalize_or_zero();
    Some((id, rand, priority, normal))
}

/// The output's channels at a point.
fn point(op: &FlakeOp, size: f32, rough: f32, cover: f32, pos: Vec3, frame: [Vec3; 3]) -> [f32; 3] {
    let f = flake_at(size, rough, cover, pos, frame);
    match (op.output, f) {
        (FlakeOutput::Id, f) => [f.map_or(0.0, |f| f.0 as f32), 0.0, 0.0],
        (FlakeOutput::Rand, f) => [f.map_or(0.0, |f| f.1), 0.0, 0.0],
        (FlakeOutput::Presence, f) => [f.map_or(0.0, |f| f.2), 0.0, 0.0],
        (FlakeOutput::Normal, Some(f)) => f.3.to_array(),
        (FlakeOutput::Normal, None) => frame[0].to_array(),
    }
}

/// Footprint size (σ of `P` in cells) from which the result starts moving to the ensemble.
pub const NEAR: f64 = 0.5;
/// Footprint size from which the result is the ensemble's.
pub const FAR: f64 = 2.0;

pub(crate) fn eval(op: &FlakeOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let f = |i: usize| ins[i].ch[0].mean;
    let v3 = |i: usize| Vec3::new(ins[i].ch[0].mean, ins[i].ch[1].mean, ins[i].ch[2].mean);
    let (size, rough, cover) = (f(0), f(1), f(2));
    let frame = [v3(4), v3(5), v3(6)];
    let coord = &ins[3];
    let dims = if op.three_d { 3 } else { 2 };
    let centre = Vec3::new(coord.ch[0].mean, coord.ch[1].mean, if op.three_d { coord.ch[2].mean } else { 0.0 });
    let n = ty.channels();
    let mut out = Filtered::zero(ty);
    let at = |pos: Vec3| point(op, size, rough, cover, pos, frame);
    if ctx.point {
        let v = at(centre);
        for k in 0..n {
            out.ch[k] = Moments::constant(v[k]);
        }
        return out;
    }
    // The coordinate's map from uv offsets (its gradients), and its spread in cells.
    let grads: Vec<DVec2> = (0..dims).map(|k| coord.ch[k].grad.as_dvec2()).collect();
    let cov = ctx.fp.cov.as_dmat2();
    let cells = (0..dims).map(|k| grads[k].dot(cov * grads[k]).max(0.0)).fold(0.0f64, f64::max).sqrt()
        / (size.abs().max(1e-30) as f64);
    let far = smooth_in_log(cells, NEAR, FAR);
    let (mut m, mut m2) = ([0.0f64; 3], [0.0f64; 3]);
    let add = |v: [f32; 3], w: f64, m: &mut [f64; 3], m2: &mut [f64; 3]| {
        for k in 0..n {
            m[k] += w * v[k] as f64;
            m2[k] += w * (v[k] as f64) * (v[k] as f64);
        }
    };
    if far < 1.0 {
        let l: DMat2 = hextile::factor(&cov);
        for (z1, a1) in crate::gaussian::HERMITE5 {
            for (z2, a2) in crate::gaussian::HERMITE5 {
                let d = l * DVec2::new(z1, z2);
                let mut pos = centre;
                for k in 0..dims {
                    pos[k] += grads[k].dot(d) as f32;
                }
                add(at(pos), a1 * a2 * (1.0 - far), &mut m, &mut m2);
            }
        }
        ctx.work.lattice += 25;
    }
    if far > 0.0 {
        // The ensemble: 8 × 8 stratified points over 8 × 8 cells about the centre (in the plane
        // of the first two coordinates; a 3D coordinate keeps its third).
        let s = size.abs().max(1e-30);
        for i in 0..8 {
            for j in 0..8 {
                let jitter = |a: i32, b: i32| ((a * 7 + b * 3) % 8) as f32 / 8.0 + 1.0 / 16.0;
                let off = Vec3::new(i as f32 + jitter(i, j), j as f32 + jitter(j, i), 0.0) - Vec3::new(4.0, 4.0, 0.0);
                add(at(centre + off * s), far / 64.0, &mut m, &mut m2);
            }
        }
        ctx.work.lattice += 64;
    }
    for k in 0..n {
        out.ch[k] = Moments { mean: m[k] as f32, grad: Vec2::ZERO, var: (m2[k] - m[k] * m[k]).max(0.0) as f32 };
    }
    out
}

/// 0 below `a`, 1 above `b`, a smoothstep in `log x` between.
fn smooth_in_log(x: f64, a: f64, b: f64) -> f64 {
    if x <= a {
        return 0.0;
    }
    if x >= b {
        return 1.0;
    }
    let t = (x / a).ln() / (b / a).ln();
    t * t * (3.0 - 2.0 * t)
}
