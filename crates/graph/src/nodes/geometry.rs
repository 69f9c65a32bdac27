//! Coordinates, geometry and constants: `texcoord`, `position`, `normal`, `tangent`,
//! `bitangent`, `geompropvalue`, `geomcolor`, `constant`, `place2d`, `rotate2d`, `rotate3d`,
//! `transformpoint`, `transformvector`, `transformnormal`, `transformmatrix`, `dot`.
//!
//! | node | inputs (default) | filtered evaluation |
//! |---|---|---|
//! | `texcoord` | `index` (0) | mean `uv`, gradient the identity, variance `diag Σ` (exact); vector3: third channel 0. tessera's shapes carry one uv set: `index` > 0 reads it too, with a warning |
//! | `position` | `space` (`object`) | mean `P`, per channel gradient `(∂Pᵢ/∂u, ∂Pᵢ/∂v)` and variance `gᵢᵀ Σ gᵢ` (exact to first order: the 3D footprint `J Σ Jᵀ`) |
//! | `normal` | `space` (`object`) | mean `N`, gradients from `∂N/∂u`, `∂N/∂v`, variance as `position` |
//! | `tangent`, `bitangent` | `space` (`object`), `index` (0) | the frame vector at the centre, zero spread (its variation across a footprint is not tracked) |
//! | `geompropvalue` | `geomprop` (string), `default` (0) | uv sets (`UV0`, `uv`, `st`, `texcoord`, …) as `texcoord`, read as another float type the way GL expands a two-component vertex attribute (`(u, v, 0, 1)`, as many channels as the type has: a float is `u`); `P`/`position`/`Pobject`/`Pworld`, `N`/`normal`/…, `tangent`/…, `bitangent`/… (vector3) as those nodes; any other name (or type) gives `default`, with a warning |
//! | `geomcolor` (float, color3, color4) | `index` (0) | 0 (alpha 1: opaque black, GL's default vertex attribute (0, 0, 0, 1), which MaterialX's renderers read for a colour set the mesh lacks), with a warning: tessera's shapes carry no vertex colours |
//! | `constant` | `value` (0) | exact, zero spread |
//! | `place2d` | `texcoord` (UV0), `pivot` (0,0), `scale` (1,1), `rotate` (0°), `offset` (0,0), `operationorder` (0 = SRT) | affine in `texcoord`: exact when the other inputs are uniform, cubature otherwise |
//! | `rotate2d` | `in` (0,0), `amount` (0°) | linear: exact for uniform `amount` |
//! | `rotate3d` | `in` (0,0,0), `amount` (0°), `axis` (0,1,0) | linear: exact for uniform `amount` and `axis`; cubature otherwise |
//! | `transformpoint`, `transformvector` | `in` (0,0,0), `fromspace`, `tospace` | identity (exact) |
//! | `transformnormal` | `in` (0,0,1), `fromspace`, `tospace` | `normalize(in)` (MaterialX normalises), by cubature |
//! | `transformmatrix` | `in` (0), `mat` (identity; a matrix folded at load, see [`crate::matrix`]) | affine `v · M` (vector2 with a matrix33 and vector3 with a matrix44 extended by a homogeneous 1): exact |
//! | `dot` | `in` (0), `note` (a comment, ignored) | pass-through |
//! | `blur` | `in` (0), `size` (0), `filtertype` | pass-through, as MaterialX's GLSL (which blurs image inputs only), with a warning unless `size` is 0: the footprint filtering every node gets is the blur tessera applies |
//!
//! Spaces: tessera transforms meshes and shapes to world space at load and keeps no object
//! transform, so `object`, `model` and `world` are one space here: `position` and `normal`
//! give world-space values whatever `space` says, and the transform nodes between these spaces
//! are the identity (`transformnormal` still normalises, as MaterialX does). Any other space
//! name is an error. Without surface geometry (a footprint built by [`Footprint::new`]) the
//! geometry is MaterialX's flat baking quad ([`crate::value::Geometry::flat_quad`]).
//!
//! `place2d` follows MaterialX's nodegraph: SRT is `((t − pivot) / scale)` rotated by `rotate`
//! degrees (`rotate2d`: `(c x + s y, −s x + c y)`), minus `offset`, plus `pivot`; TRS subtracts
//! `offset` before rotating and divides by `scale` after. `rotate3d` applies the transpose of
//! the right-handed rotation by `amount` degrees about the normalised `axis` (as GLSL reads
//! MaterialX's row-written matrix): like `rotate2d`, a rotation by `−amount`.
//!
//! [`Footprint::new`]: crate::value::Footprint::new

use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::{GeomProp, Source};
use crate::moments::{self, add_scaled, affine};
use crate::value::{Filtered, Moments, ValueType};
use glam::{Vec2, Vec3};

pub(crate) const CATEGORIES: &[&str] = &[
    "texcoord",
    "position",
    "normal",
    "tangent",
    "bitangent",
    "geompropvalue",
    "geomcolor",
    "constant",
    "place2d",
    "rotate2d",
    "rotate3d",
    "transformpoint",
    "transformvector",
    "transformnormal",
    "transformmatrix",
    "dot",
    "blur",
];

/// Geometry operations.
#[derive(Debug)]
pub enum GeometryOp {
    /// `texcoord`, with the warning for a uv set tessera does not have.
    Texcoord(Option<String>),
    /// `position`, `normal`, `tangent`, `bitangent`, and `geompropvalue` naming one of them.
    Prop(GeomProp),
    /// `geompropvalue` of a uv set.
    PropUv,
    /// `geompropvalue` that tessera cannot provide: its `default`, and why.
    PropDefault(String),
    /// A property with no default that tessera's shapes do not carry (`geomcolor`): 0, and why.
    Absent(String),
    /// `rotate3d`
    Rotate3d,
    /// `transformpoint`, `transformvector` (identity between tessera's spaces).
    Identity,
    /// `transformnormal`
    TransformNormal,
    /// `transformmatrix`: `out[k] = Σⱼ in[j] · lin[j][k] + t[k]`.
    TransformMatrix {
        /// The linear part, `[input channel][output channel]`.
        lin: [[f32; 4]; 4],
        /// The translation (the homogeneous row).
        t: [f32; 4],
    },
    /// `constant`
    Constant,
    /// `place2d`
    Place2d,
    /// `rotate2d`
    Rotate2d,
    /// `dot`
    Dot,
    /// `blur`: `in` passed through, with a warning where `size` asks for a blur.
    Blur(Option<String>),
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let v3 = |t: ValueType| t == ValueType::Vector3;
    let (inputs, params, types): (&'static [_], &'static [&'static str], fn(ValueType) -> bool) = match category {
        "texcoord" => (&[inp!("index", Int, Zero)], &[], |t| matches!(t, ValueType::Vector2 | ValueType::Vector3)),
        "position" | "normal" => (&[], &["space"], v3),
        "tangent" | "bitangent" => (&[inp!("index", Int, Zero)], &["space"], v3),
        "geompropvalue" => (&[inp!("default", Out, Zero)], &["geomprop"], types::numeric),
        "geomcolor" => (&[inp!("index", Int, Zero)], &[], |t| {
            matches!(t, ValueType::Float | ValueType::Color3 | ValueType::Color4)
        }),
        "constant" => (&[inp!("value", Out, Zero)], &[], types::numeric),
        "place2d" => (
            &[
                inp!("texcoord", V2, Uv),
                inp!("pivot", V2, Zero),
                inp!("scale", V2, One),
                inp!("rotate", Float, Zero),
                inp!("offset", V2, Zero),
                inp!("operationorder", Int, Zero),
            ],
            &[],
            types::vector2,
        ),
        "rotate2d" => (&[inp!("in", V2, Zero), inp!("amount", Float, Zero)], &[], types::vector2),
        "rotate3d" => {
            (&[inp!("in", V3, Zero), inp!("amount", Float, Zero), inp!("axis", V3, Triple(0.0, 1.0, 0.0))], &[], v3)
        }
        "transformpoint" | "transformvector" => (&[inp!("in", V3, Zero)], &["fromspace", "tospace"], v3),
        "transformnormal" => (&[inp!("in", V3, Triple(0.0, 0.0, 1.0))], &["fromspace", "tospace"], v3),
        "transformmatrix" => (&[inp!("in", Out, Zero)], &["mat"], |t| {
            matches!(t, ValueType::Vector2 | ValueType::Vector3 | ValueType::Vector4)
        }),
        "dot" => (&[inp!("in", Out, Zero)], &["note"], types::numeric),
        "blur" => (&[inp!("in", Out, Zero), inp!("size", Float, Zero)], &["filtertype"], types::float_or_vector),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params, types, build })
}

/// The value of string input `name`, if given.
fn param<'a>(params: &'a [Param], name: &str) -> Option<&'a str> {
    params.iter().find_map(|p| match p {
        Param::Str { name: n, value } if n == name => Some(value.as_str()),
        _ => None,
    })
}

/// Checks a `space` string: tessera's object, model and world spaces are one.
fn check_space(params: &[Param], name: &str) -> Result<(), String> {
    match param(params, name).map(str::trim) {
        None | Some("") | Some("object") | Some("model") | Some("world") => Ok(()),
        Some(other) => Err(format!(
            "{name} `{other}` is not supported: tessera knows `object`, `model` and `world` (one space, as meshes \
             are transformed to world space at load)"
        )),
    }
}

/// The geometric property a `geompropvalue` name reads, if tessera provides it.
enum Named {
    Uv,
    Prop(GeomProp),
}

fn classify_geomprop(name: &str) -> Option<Named> {
    Some(match name.trim().to_ascii_lowercase().as_str() {
        "uv0" | "uv" | "st" | "st0" | "texcoord" | "texcoord0" | "texcoord_0" | "uvmap" => Named::Uv,
        "p" | "position" | "pobject" | "pworld" => Named::Prop(GeomProp::Position),
        "n" | "normal" | "nobject" | "nworld" => Named::Prop(GeomProp::Normal),
        "tangent" | "tobject" | "tworld" => Named::Prop(GeomProp::Tangent),
        "bitangent" | "bobject" | "bworld" => Named::Prop(GeomProp::Bitangent),
        _ => return None,
    })
}

fn build(category: &str, ty: ValueType, _: &[ValueType], srcs: &[Source], params: &[Param]) -> Result<Op, String> {
    let constant_index = |s: &Source| match s {
        Source::Constant(v) => Ok(v.v[0].round() as i32),
        _ => Err("`index` must be a uniform value".to_string()),
    };
    Ok(Op::Geometry(match category {
        "texcoord" => {
            let index = constant_index(&srcs[0])?;
            let warning = (index != 0).then(|| {
                format!("uv set {index} read as uv set 0 (tessera's shapes carry one set of texture coordinates)")
            });
            GeometryOp::Texcoord(warning)
        }
        "position" | "normal" | "tangent" | "bitangent" => {
            check_space(params, "space")?;
            GeometryOp::Prop(match category {
                "position" => GeomProp::Position,
                "normal" => GeomProp::Normal,
                "tangent" => GeomProp::Tangent,
                _ => GeomProp::Bitangent,
            })
        }
        "geompropvalue" => {
            let name = param(params, "geomprop").unwrap_or("");
            match classify_geomprop(name) {
                Some(Named::Uv) if ty != ValueType::Integer && ty != ValueType::Boolean => GeometryOp::PropUv,
                Some(Named::Prop(p)) if ty == ValueType::Vector3 => GeometryOp::Prop(p),
                Some(_) => GeometryOp::PropDefault(format!(
                    "geomprop `{name}` cannot be read as a {ty}; the node gives its `default`"
                )),
                None => GeometryOp::PropDefault(format!(
                    "geomprop `{name}` is not provided by tessera (it knows uv sets, position, normal, tangent and \
                     bitangent); the node gives its `default`"
                )),
            }
        }
        "geomcolor" => {
            let index = constant_index(&srcs[0])?;
            GeometryOp::Absent(format!(
                "vertex colour set {index} is not carried by tessera's shapes; `geomcolor` gives 0 (alpha 1)"
            ))
        }
        "transformmatrix" => {
            let dim = ty.channels();
            let mat = params
                .iter()
                .find_map(|p| match p {
                    Param::Matrix { name, value } if name == "mat" => Some(*value),
                    _ => None,
                })
                .unwrap_or_else(|| crate::matrix::Matrix::identity(dim.max(3)));
            let Some((lin, t)) = mat.affine_for(dim) else {
                return Err(format!(
                    "`mat` is a matrix{n}{n}, which cannot transform a {ty} (vector2 takes a matrix33, vector3 \
                     either, vector4 a matrix44)",
                    n = mat.n
                ));
            };
            GeometryOp::TransformMatrix { lin, t }
        }
        "constant" => GeometryOp::Constant,
        "blur" => GeometryOp::Blur(match &srcs[1] {
            Source::Constant(v) if v.v[0] == 0.0 => None,
            _ => Some(
                "`blur` passes `in` through unblurred, as MaterialX's GLSL does for procedural inputs (tessera \
                 filters every node to its footprint already)"
                    .to_string(),
            ),
        }),
        "place2d" => GeometryOp::Place2d,
        "rotate2d" => GeometryOp::Rotate2d,
        "rotate3d" => GeometryOp::Rotate3d,
        "transformpoint" | "transformvector" | "transformnormal" => {
            check_space(params, "fromspace")?;
            check_space(params, "tospace")?;
            if category == "transformnormal" {
                GeometryOp::TransformNormal
            } else {
                GeometryOp::Identity
            }
        }
        _ => GeometryOp::Dot,
    }))
}

/// Whether the operation reads geometry beyond uv.
pub(crate) fn reads_geometry(op: &GeometryOp) -> bool {
    matches!(op, GeometryOp::Prop(_) | GeometryOp::PropDefault(_))
}

/// The operation's load-time warning, if any.
pub(crate) fn warning(op: &GeometryOp) -> Option<String> {
    match op {
        GeometryOp::Texcoord(w) => w.clone(),
        GeometryOp::PropDefault(w) | GeometryOp::Absent(w) => Some(w.clone()),
        GeometryOp::Blur(w) => w.clone(),
        _ => None,
    }
}

/// A vector3 whose channels are linear in uv with the given value and uv derivatives.
fn linear3(value: Vec3, du: Vec3, dv: Vec3, ctx: &Ctx) -> Filtered {
    let mut f = Filtered::zero(ValueType::Vector3);
    for k in 0..3 {
        let g = Vec2::new(du[k], dv[k]);
        f.ch[k] = Moments { mean: value[k], grad: g, var: ctx.fp.quad(g, g).max(0.0) };
    }
    f
}

/// The filtered geometric property at the footprint.
pub(crate) fn geomprop(prop: GeomProp, ctx: &Ctx) -> Filtered {
    let g = &ctx.fp.geom;
    match prop {
        GeomProp::Position => linear3(g.p, g.dpdu, g.dpdv, ctx),
        GeomProp::Normal => linear3(g.n, g.dndu, g.dndv, ctx),
        GeomProp::Tangent => linear3(g.t, Vec3::ZERO, Vec3::ZERO, ctx),
        GeomProp::Bitangent => linear3(g.b, Vec3::ZERO, Vec3::ZERO, ctx),
    }
}

/// The filtered texture coordinate itself.
pub(crate) fn texcoord(ctx: &Ctx) -> Filtered {
    let fp = ctx.fp;
    let mut f = Filtered::zero(ValueType::Vector2);
    f.ch[0] = Moments { mean: fp.uv.x, grad: Vec2::X, var: fp.cov.x_axis.x.max(0.0) };
    f.ch[1] = Moments { mean: fp.uv.y, grad: Vec2::Y, var: fp.cov.y_axis.y.max(0.0) };
    f
}

/// Rotates `(x, y)` by `deg` degrees the way MaterialX's `rotate2d` does.
pub(crate) fn rotate(x: Moments, y: Moments, deg: f32, ctx: &Ctx) -> (Moments, Moments) {
    let (s, c) = deg.to_radians().sin_cos();
    let rx = add_scaled(affine(x, c, 0.0), y, s, ctx.fp);
    let ry = add_scaled(affine(y, c, 0.0), x, -s, ctx.fp);
    (rx, ry)
}

fn uniform(ins: &[Filtered], idx: &[usize]) -> bool {
    idx.iter().all(|&i| ins[i].is_uniform())
}

pub(crate) fn eval(op: &GeometryOp, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    match op {
        GeometryOp::Texcoord(_) => {
            let mut f = texcoord(ctx);
            f.ty = ty;
            f
        }
        GeometryOp::PropUv => {
            // A two-component property read as another type, as GL expands a vertex attribute:
            // (u, v, 0, 1), as many channels as the type has.
            let uv = texcoord(ctx);
            let mut f = Filtered::zero(ty);
            f.ch[0] = uv.ch[0];
            if ty.channels() > 1 {
                f.ch[1] = uv.ch[1];
            }
            if ty.channels() == 4 {
                f.ch[3] = crate::value::Moments::constant(1.0);
            }
            f
        }
        GeometryOp::Prop(p) => geomprop(*p, ctx),
        GeometryOp::PropDefault(_) => ins[0],
        GeometryOp::Absent(_) => {
            // A vertex attribute a mesh does not carry reads as GL's default (0, 0, 0, 1):
            // an absent colour set is opaque black, as in MaterialX's renderers.
            let mut v = Filtered::zero(ty);
            if ty.channels() == 4 {
                v.ch[3] = crate::value::Moments::constant(1.0);
            }
            v
        }
        GeometryOp::Identity | GeometryOp::Blur(_) => ins[0],
        GeometryOp::TransformNormal => super::math::eval(&super::math::MathOp::Normalize, ty, ins, ctx),
        GeometryOp::Rotate3d => rotate3d(ins, ctx),
        GeometryOp::TransformMatrix { lin, t } => {
            let v = &ins[0];
            let n = ty.channels();
            let mut out = Filtered::zero(ty);
            for k in 0..n {
                let mut acc = Moments::constant(t[k]);
                for j in 0..n {
                    acc = add_scaled(acc, v.ch[j], lin[j][k], ctx.fp);
                }
                out.ch[k] = acc;
            }
            out
        }
        GeometryOp::Constant | GeometryOp::Dot => ins[0],
        GeometryOp::Rotate2d => {
            let mut out = Filtered::zero(ValueType::Vector2);
            if ins[1].is_uniform() {
                let (x, y) = rotate(ins[0].ch[0], ins[0].ch[1], ins[1].ch[0].mean, ctx);
                out.ch[0] = x;
                out.ch[1] = y;
            } else {
                for k in 0..2 {
                    out.ch[k] = moments::nary(&[ins[0].ch[0], ins[0].ch[1], ins[1].ch[0]], |p| {
                        let (s, c) = p[2].to_radians().sin_cos();
                        if k == 0 {
                            c * p[0] + s * p[1]
                        } else {
                            -s * p[0] + c * p[1]
                        }
                    });
                }
            }
            out
        }
        GeometryOp::Place2d => place2d(ins, ctx),
    }
}

fn place2d(ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let t = &ins[0];
    let mut out = Filtered::zero(ValueType::Vector2);
    if uniform(ins, &[1, 2, 3, 4, 5]) {
        let pivot = Vec2::new(ins[1].ch[0].mean, ins[1].ch[1].mean);
        let scale = Vec2::new(ins[2].ch[0].mean, ins[2].ch[1].mean);
        let deg = ins[3].ch[0].mean;
        let offset = Vec2::new(ins[4].ch[0].mean, ins[4].ch[1].mean);
        let trs = ins[5].ch[0].mean >= 1.0;
        let (x, y) = (affine(t.ch[0], 1.0, -pivot.x), affine(t.ch[1], 1.0, -pivot.y));
        let (x, y) = if !trs {
            let (x, y) =
                rotate(affine(x, moments::recip(scale.x), 0.0), affine(y, moments::recip(scale.y), 0.0), deg, ctx);
            (affine(x, 1.0, -offset.x), affine(y, 1.0, -offset.y))
        } else {
            let (x, y) = rotate(affine(x, 1.0, -offset.x), affine(y, 1.0, -offset.y), deg, ctx);
            (affine(x, moments::recip(scale.x), 0.0), affine(y, moments::recip(scale.y), 0.0))
        };
        out.ch[0] = affine(x, 1.0, pivot.x);
        out.ch[1] = affine(y, 1.0, pivot.y);
        return out;
    }
    let xs = [
        t.ch[0],
        t.ch[1],
        ins[1].ch[0],
        ins[1].ch[1],
        ins[2].ch[0],
        ins[2].ch[1],
        ins[3].ch[0],
        ins[4].ch[0],
        ins[4].ch[1],
        ins[5].ch[0],
    ];
    for k in 0..2 {
        out.ch[k] = moments::nary(&xs, |p| place2d_point(p)[k]);
    }
    out
}

/// MaterialX `rotate3d`'s matrix: the transpose of the right-handed rotation by `deg` degrees
/// about `axis` (normalised; a zero axis leaves vectors unchanged). Row-major: `out = M · in`.
pub(crate) fn rotate3d_matrix(axis: [f64; 3], deg: f64) -> [[f64; 3]; 3] {
    let len = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    if !(len > 0.0 && len.is_finite()) {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let (x, y, z) = (axis[0] / len, axis[1] / len, axis[2] / len);
    let (s, c) = deg.to_radians().sin_cos();
    let oc = 1.0 - c;
    // Rodrigues' R, transposed.
    [
        [oc * x * x + c, oc * x * y + z * s, oc * z * x - y * s],
        [oc * x * y - z * s, oc * y * y + c, oc * y * z + x * s],
        [oc * z * x + y * s, oc * y * z - x * s, oc * z * z + c],
    ]
}

fn rotate3d(ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let v = &ins[0];
    let mut out = Filtered::zero(ValueType::Vector3);
    if ins[1].is_uniform() && ins[2].is_uniform() {
        let a = &ins[2];
        let m =
            rotate3d_matrix([a.ch[0].mean as f64, a.ch[1].mean as f64, a.ch[2].mean as f64], ins[1].ch[0].mean as f64);
        for (k, row) in m.iter().enumerate() {
            let acc = affine(v.ch[0], row[0] as f32, 0.0);
            let acc = add_scaled(acc, v.ch[1], row[1] as f32, ctx.fp);
            out.ch[k] = add_scaled(acc, v.ch[2], row[2] as f32, ctx.fp);
        }
        return out;
    }
    let xs = [v.ch[0], v.ch[1], v.ch[2], ins[1].ch[0], ins[2].ch[0], ins[2].ch[1], ins[2].ch[2]];
    for k in 0..3 {
        out.ch[k] = moments::nary(&xs, |p| {
            let m = rotate3d_matrix([p[4], p[5], p[6]], p[3]);
            m[k][0] * p[0] + m[k][1] * p[1] + m[k][2] * p[2]
        });
    }
    out
}

/// Unfiltered `place2d` from `[tx, ty, px, py, sx, sy, deg, ox, oy, order]`.
fn place2d_point(p: &[f64]) -> [f64; 2] {
    let (x, y) = (p[0] - p[2], p[1] - p[3]);
    let (s, c) = p[6].to_radians().sin_cos();
    let rot = |x: f64, y: f64| (c * x + s * y, -s * x + c * y);
    let (x, y) = if p[9] < 1.0 {
        let (x, y) = rot(moments::safe_div(x, p[4]), moments::safe_div(y, p[5]));
        (x - p[7], y - p[8])
    } else {
        let (x, y) = rot(x - p[7], y - p[8]);
        (moments::safe_div(x, p[4]), moments::safe_div(y, p[5]))
    };
    [x + p[2], y + p[3]]
}
