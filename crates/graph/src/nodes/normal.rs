//! Normal maps: `normalmap`, `heighttonormal`, `bump`.
//!
//! | node | inputs (default) | unfiltered (MaterialX 1.39) | filtered evaluation |
//! |---|---|---|---|
//! | `normalmap` (vector3) | `in` (0.5, 0.5, 1), `scale` (1; float or vector2), `normal` (0,0,1), `tangent` (1,0,0), `bitangent` (0,1,0) | `v = 2·in − 1` (`(0,0,1)` for `in = 0`), `normalize(T·v.x·scale.x + B·v.y·scale.y + N·v.z)` | per output channel, spherical cubature over the varying input channels ([`moments::nary`](crate::moments::nary)) |
//! | `heighttonormal` (vector3) | `in` (0), `scale` (1), `texcoord` (UV0) | `normalize(−k ∂h/∂tₓ, −k ∂h/∂t_y, 1)·½ + ½`, `k = scale/16`: what MaterialX's screen-space construction (`cross` of the screen tangents `(∂t/∂s, k ∂h/∂s)`) reduces to, independent of the pixel size; `(0,0,1)` where `texcoord` is degenerate | the normal of the filtered height: `∂h/∂t` from the gradients of the filtered `in` and `texcoord` means (`∂h/∂t = J⁻ᵀ ∂h/∂uv`); its spread over the footprint is not modelled (variance 0). Evaluation keeps gradients for point footprints when this node is involved |
//! | `bump` (vector3) | `height` (0), `scale` (1), `normal`, `tangent`, `bitangent` (the shading frame) | MaterialX's `NG_bump`: `normalmap` of `heighttonormal(height)` (scale 1, texcoord UV0) by `scale` in the given frame | as the two nodes: the normal of the filtered height, then cubature; gradients kept at point footprints |
//!
//! `space` (an input MaterialX 1.39 removed): `tangent` (or absent) is the tangent-space map
//! above; `object`, as MaterialX's upgrade of older documents rewrites it, is
//! `normalize(2·in − 1)` (filtered by cubature), the frame inputs unused. Any other value is an
//! error.
//!
//! The frame defaults to the flat tangent frame (MaterialX's are the current world-space
//! normal, tangent and bitangent, which the renderer does not pass to graphs yet).

use super::{inp, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::{GeomProp, Source};
use crate::moments;
use crate::value::{Filtered, Moments, ValueType};
use glam::Vec3;

pub(crate) const CATEGORIES: &[&str] = &["normalmap", "heighttonormal", "bump"];

/// Normal-map operations.
#[derive(Debug)]
pub enum NormalOp {
    /// `normalmap`
    NormalMap,
    /// `normalmap` with `space` = `object`: `normalize(2·in − 1)`.
    ObjectSpace,
    /// `heighttonormal`
    HeightToNormal,
    /// `bump`
    Bump,
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let inputs: &'static [_] = match category {
        "normalmap" => &[
            inp!("in", V3, Triple(0.5, 0.5, 1.0)),
            inp!("scale", Any, One),
            inp!("normal", V3, Triple(0.0, 0.0, 1.0)),
            inp!("tangent", V3, Triple(1.0, 0.0, 0.0)),
            inp!("bitangent", V3, Triple(0.0, 1.0, 0.0)),
        ],
        "heighttonormal" => &[inp!("in", Float, Zero), inp!("scale", Float, One), inp!("texcoord", V2, Uv)],
        "bump" => &[
            inp!("height", Float, Zero),
            inp!("scale", Float, One),
            inp!("normal", V3, Geom(GeomProp::Normal)),
            inp!("tangent", V3, Geom(GeomProp::Tangent)),
            inp!("bitangent", V3, Geom(GeomProp::Bitangent)),
        ],
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params: &["space"], types: |t| t == ValueType::Vector3, build })
}

fn build(category: &str, _: ValueType, types: &[ValueType], _: &[Source], params: &[Param]) -> Result<Op, String> {
    if category == "heighttonormal" {
        return Ok(Op::Normal(NormalOp::HeightToNormal));
    }
    if category == "bump" {
        return Ok(Op::Normal(NormalOp::Bump));
    }
    let space = params.iter().find_map(|p| match p {
        Param::Str { name, value } if name == "space" => Some(value.trim()),
        _ => None,
    });
    match space {
        None | Some("") | Some("tangent") => {}
        Some("object") => return Ok(Op::Normal(NormalOp::ObjectSpace)),
        Some(other) => return Err(format!("`space` must be `tangent` or `object`, not `{other}`")),
    }
    if !matches!(types[1], ValueType::Float | ValueType::Vector2) {
        return Err(format!("`scale` must be float or vector2, not {}", types[1]));
    }
    Ok(Op::Normal(NormalOp::NormalMap))
}

/// Unfiltered `normalmap` from `[in(3), scale(2), N(3), T(3), B(3)]`.
pub fn normalmap_point(p: &[f64]) -> [f64; 3] {
    let v = Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32);
    let v = if v == Vec3::ZERO { Vec3::Z } else { v * 2.0 - 1.0 };
    let f = |k: usize| Vec3::new(p[k] as f32, p[k + 1] as f32, p[k + 2] as f32);
    let (n, t, b) = (f(5), f(8), f(11));
    let r = (t * v.x * p[3] as f32 + b * v.y * p[4] as f32 + n * v.z).normalize_or_zero();
    [r.x as f64, r.y as f64, r.z as f64]
}

/// Unfiltered object-space `normalmap`: `normalize(2·in − 1)` (zero where that is zero).
pub fn object_space_point(p: &[f64]) -> [f64; 3] {
    let v = glam::DVec3::new(2.0 * p[0] - 1.0, 2.0 * p[1] - 1.0, 2.0 * p[2] - 1.0).normalize_or_zero();
    [v.x, v.y, v.z]
}

/// Unfiltered `heighttonormal` from the height's gradient `dh` with respect to the texture
/// coordinate and `k = scale/16`.
pub fn heighttonormal_point(dh: [f64; 2], k: f64) -> [f64; 3] {
    let n = glam::DVec3::new(-k * dh[0], -k * dh[1], 1.0).normalize();
    [n.x * 0.5 + 0.5, n.y * 0.5 + 0.5, n.z * 0.5 + 0.5]
}

pub(crate) fn eval(op: &NormalOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    if let NormalOp::Bump = op {
        let one = Filtered::constant(crate::value::Value::float(1.0));
        let tc = super::geometry::texcoord(ctx);
        let h = eval(&NormalOp::HeightToNormal, ValueType::Vector3, &[ins[0], one, tc], ctx);
        return eval(&NormalOp::NormalMap, ty, &[h, ins[1], ins[2], ins[3], ins[4]], ctx);
    }
    if let NormalOp::HeightToNormal = op {
        let gh = ins[0].ch[0].grad.as_dvec2();
        let t = &ins[2];
        let j = glam::DMat2::from_cols(t.ch[0].grad.as_dvec2(), t.ch[1].grad.as_dvec2());
        // Columns of j are ∂tₓ/∂uv and ∂t_y/∂uv: ∂h/∂uv = j · ∂h/∂t.
        let det = j.determinant();
        let r = if det.abs() < 1e-12 {
            [0.5, 0.5, 1.0]
        } else {
            let dh = j.inverse() * gh;
            heighttonormal_point([dh.x, dh.y], ins[1].ch[0].mean as f64 / 16.0)
        };
        let mut out = Filtered::zero(ty);
        for k in 0..3 {
            out.ch[k] = Moments::constant(r[k] as f32);
        }
        return out;
    }
    if let NormalOp::ObjectSpace = op {
        let xs = [ins[0].ch[0], ins[0].ch[1], ins[0].ch[2]];
        let mut out = Filtered::zero(ty);
        for k in 0..3 {
            out.ch[k] = moments::nary(&xs, |p| object_space_point(p)[k]);
        }
        return out;
    }
    let mut xs = [Moments::default(); 14];
    xs[..3].copy_from_slice(&ins[0].ch[..3]);
    xs[3] = ins[1].at(0);
    xs[4] = ins[1].at(1);
    for (f, input) in ins[2..5].iter().enumerate() {
        for k in 0..3 {
            xs[5 + 3 * f + k] = input.ch[k];
        }
    }
    let mut out = Filtered::zero(ty);
    for k in 0..3 {
        out.ch[k] = moments::nary(&xs, |p| normalmap_point(p)[k]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::normalmap_point;

    #[test]
    fn normalmap_frame() {
        let frame = [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let at = |v: [f64; 3], s: [f64; 2]| {
            let p: Vec<f64> = v.iter().chain(&s).chain(&frame).copied().collect();
            normalmap_point(&p)
        };
        let close = |a: [f64; 3], b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5);
        assert!(close(at([0.5, 0.5, 1.0], [1.0, 1.0]), [0.0, 0.0, 1.0]));
        assert!(close(at([1.0, 0.5, 0.5], [1.0, 1.0]), [1.0, 0.0, 0.0]));
        assert!(close(at([0.0, 0.0, 0.0], [1.0, 1.0]), [0.0, 0.0, 1.0]));
        let r = at([1.0, 0.5, 1.0], [0.5, 1.0]);
        let k = 1.0 / (1.25f64).sqrt();
        assert!(close(r, [0.5 * k, 0.0, k]), "{r:?}");
    }
}

#[cfg(test)]
mod height_tests {
    use crate::{Document, EvalScratch, Footprint, LoadOptions};
    use glam::Vec2;

    /// A height ramp `h = 0.8 u` read through `t = 2 uv`: `∂h/∂tₓ = 0.4`, at a point footprint.
    #[test]
    fn heighttonormal_of_a_ramp() {
        let text = r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">
          <texcoord name="t" type="vector2"/>
          <multiply name="s" type="vector2"><input name="in1" type="vector2" nodename="t"/><input name="in2" type="float" value="2"/></multiply>
          <extract name="u" type="float"><input name="in" type="vector2" nodename="t"/></extract>
          <multiply name="h" type="float"><input name="in1" type="float" nodename="u"/><input name="in2" type="float" value="0.8"/></multiply>
          <heighttonormal name="n" type="vector3"><input name="in" type="float" nodename="h"/><input name="scale" type="float" value="16"/><input name="texcoord" type="vector2" nodename="s"/></heighttonormal>
          <output name="out" type="vector3" nodename="n"/></nodegraph></materialx>"#;
        let doc = Document::parse(text, "t.mtlx".as_ref(), &LoadOptions::default()).unwrap();
        let g = doc.graph();
        let out = g.output_id("g/out").unwrap();
        let mut scratch = EvalScratch::new(g);
        let v = g.eval_output(out, &Footprint::point(Vec2::new(0.3, 0.6)), &mut scratch);
        let l = (1.0f32 + 0.16).sqrt();
        let want = [-0.4 / l * 0.5 + 0.5, 0.5, 1.0 / l * 0.5 + 0.5];
        for k in 0..3 {
            assert!((v.ch[k].mean - want[k]).abs() < 1e-4, "channel {k}: {} vs {}", v.ch[k].mean, want[k]);
        }
    }
}
