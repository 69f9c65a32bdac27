//! The node library: one file per node family, each with a table of its inputs.
//!
//! [`definition`] maps a MaterialX category to its [`NodeDef`]: the inputs in order with their
//! types and nodedef defaults (hard-coded from the MaterialX 1.39 Standard Nodes spec), the
//! output types it accepts, and how to build its [`Op`]. `eval` dispatches a filtered
//! evaluation to the family.

pub(crate) mod channel;
pub(crate) mod color;
pub(crate) mod composite;
pub(crate) mod flake;
pub(crate) mod geometry;
pub(crate) mod hash;
pub(crate) mod hextile;
pub(crate) mod hextile_normal;
pub(crate) mod image;
pub(crate) mod kernel_table;
pub(crate) mod math;
pub(crate) mod noise;
pub(crate) mod normal;
pub(crate) mod pattern;
pub(crate) mod shape;
pub(crate) mod vector;

#[doc(hidden)]
pub use math::set_unguarded_power;

use crate::eval::Work;
use crate::graph::{GeomProp, Source};
use crate::value::{Filtered, Footprint, Value, ValueType};
use std::path::PathBuf;
use std::sync::Arc;

/// The most inputs a node definition has (`ramp`: 24).
pub(crate) const MAX_INPUTS: usize = 24;

/// A uniform string-like input of a node (file names, address modes, ...).
#[derive(Clone, Debug, PartialEq)]
pub enum Param {
    /// An image file, resolved to a path, with its declared colour space.
    File {
        /// Input name.
        name: String,
        /// Resolved path.
        path: PathBuf,
        /// `colorspace` attribute (e.g. `srgb_texture`), empty if none.
        colorspace: String,
    },
    /// Any other string input.
    Str {
        /// Input name.
        name: String,
        /// Its value.
        value: String,
    },
    /// A `matrix33` / `matrix44` input, folded to its value at load (matrices are uniforms in
    /// tessera: see [`crate::matrix`]).
    Matrix {
        /// Input name.
        name: String,
        /// Its value.
        value: crate::matrix::Matrix,
    },
}

/// The type rule of one input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InType {
    /// Same type as the node's output.
    Out,
    /// Same as the output or, for a colour output, the vector of as many channels (MaterialX
    /// defines noise amplitudes of colour noise as vectors: `ND_noise3d_color3` takes a
    /// `vector3`), or a float broadcast to every channel.
    OutOrFloat,
    /// `float`.
    Float,
    /// `integer`.
    Int,
    /// `boolean`.
    Bool,
    /// `float`, `integer` or `boolean`.
    Scalar,
    /// `vector2`.
    V2,
    /// `vector3`.
    V3,
    /// `color3`.
    C3,
    /// Any numeric type.
    Any,
    /// The type of input number `k`.
    SameAs(usize),
}

/// A nodedef default.
#[derive(Clone, Copy, Debug)]
pub enum Def {
    /// All channels 0.
    Zero,
    /// All channels 1.
    One,
    /// All channels 0.5.
    Half,
    /// All channels this value.
    Splat(f32),
    /// A vector2.
    Pair(f32, f32),
    /// A three-channel value.
    Triple(f32, f32, f32),
    /// A four-channel value.
    Quad(f32, f32, f32, f32),
    /// The geometric texture coordinate `UV0`.
    Uv,
    /// A geometric property (`Pobject`, `Nobject`, ...).
    Geom(GeomProp),
}

/// One input of a node definition.
#[derive(Clone, Copy, Debug)]
pub struct InputSpec {
    /// Input name.
    pub name: &'static str,
    /// Type rule.
    pub ty: InType,
    /// Default when omitted.
    pub default: Def,
}

/// An [`InputSpec`] literal (a macro so that tables of them are promoted to statics).
macro_rules! inp {
    ($name:expr, $ty:expr, $default:expr) => {
        $crate::nodes::InputSpec { name: $name, ty: $ty, default: $default }
    };
}
pub(crate) use inp;

/// The vector type with as many channels as colour type `ty` (none for other types).
fn vector_like(ty: ValueType) -> Option<ValueType> {
    match ty {
        ValueType::Color3 => Some(ValueType::Vector3),
        ValueType::Color4 => Some(ValueType::Vector4),
        _ => None,
    }
}

impl InputSpec {
    fn concrete_type(&self, node_ty: ValueType, earlier: &[ValueType]) -> ValueType {
        match self.ty {
            InType::Out | InType::OutOrFloat => node_ty,
            InType::Float | InType::Scalar | InType::Any => ValueType::Float,
            InType::Int => ValueType::Integer,
            InType::Bool => ValueType::Boolean,
            InType::V2 => ValueType::Vector2,
            InType::V3 => ValueType::Vector3,
            InType::C3 => ValueType::Color3,
            InType::SameAs(k) => earlier.get(k).copied().unwrap_or(ValueType::Float),
        }
    }

    /// The source an omitted input takes.
    pub fn default_source_with(&self, node_ty: ValueType, earlier: &[ValueType]) -> Source {
        let ty = self.concrete_type(node_ty, earlier);
        let v = match self.default {
            Def::Zero => Value::splat(ty, 0.0),
            Def::One => Value::splat(ty, 1.0),
            Def::Half => Value::splat(ty, 0.5),
            Def::Splat(x) => Value::splat(ty, x),
            Def::Pair(a, b) => Value::new(ValueType::Vector2, &[a, b]),
            Def::Triple(a, b, c) => Value::new(ty, &[a, b, c]),
            // A four-channel default serves a three-channel variant too (`colorcorrect`'s `in`
            // is (1, 1, 1) for color3 and (1, 1, 1, 0) for color4).
            Def::Quad(a, b, c, d) => Value::new(ty, &[a, b, c, d][..ty.channels().min(4)]),
            Def::Uv => return Source::Texcoord,
            Def::Geom(g) => return Source::Geometry(g),
        };
        Source::Constant(v)
    }

    /// The source an omitted input takes (for inputs that do not depend on other inputs).
    pub fn default_source(&self, node_ty: ValueType) -> Source {
        self.default_source_with(node_ty, &[])
    }

    /// Whether a value of type `found` may connect here.
    pub fn accepts_with(&self, node_ty: ValueType, found: ValueType, earlier: &[ValueType]) -> bool {
        use ValueType::*;
        match self.ty {
            InType::Out => found == node_ty,
            InType::OutOrFloat => found == node_ty || found == Float || Some(found) == vector_like(node_ty),
            InType::Float => found == Float,
            InType::Int => found == Integer,
            InType::Bool => found == Boolean,
            InType::Scalar => found.is_scalar(),
            InType::V2 => found == Vector2,
            InType::V3 => found == Vector3,
            InType::C3 => found == Color3,
            InType::Any => true,
            InType::SameAs(k) => earlier.get(k).is_none_or(|t| *t == found),
        }
    }

    /// Whether a value of type `found` may connect here (ignoring `SameAs` rules).
    pub fn accepts(&self, node_ty: ValueType, found: ValueType) -> bool {
        self.accepts_with(node_ty, found, &[])
    }

    /// Human-readable expected type.
    pub fn expected(&self, node_ty: ValueType) -> String {
        match self.ty {
            InType::Out => node_ty.name().to_string(),
            InType::OutOrFloat => match vector_like(node_ty) {
                Some(v) => format!("{v}, {node_ty} or float"),
                None => format!("{node_ty} or float"),
            },
            InType::Scalar => "float, integer or boolean".into(),
            InType::Any => "any".into(),
            InType::SameAs(_) => "the type of the first input".into(),
            _ => self.concrete_type(node_ty, &[]).name().to_string(),
        }
    }
}

/// Builds a node's [`Op`] from its output type, input types, input sources and parameters.
pub type BuildFn = fn(&str, ValueType, &[ValueType], &[Source], &[Param]) -> Result<Op, String>;

/// A node definition.
pub struct NodeDef {
    /// MaterialX category.
    pub category: &'static str,
    /// Inputs in evaluation order.
    pub inputs: &'static [InputSpec],
    /// String-valued inputs, kept as [`Param`]s.
    pub params: &'static [&'static str],
    /// Output types accepted.
    pub types: fn(ValueType) -> bool,
    /// Builds the operation.
    pub build: BuildFn,
}

/// The operation of a node, grouped by family.
#[derive(Debug)]
pub enum Op {
    /// `texcoord`, `position`, `normal`, `tangent`, `bitangent`, `geompropvalue`, `constant`,
    /// `place2d`, `rotate2d`, `rotate3d`, `transform*`, `dot`.
    Geometry(geometry::GeometryOp),
    /// `noise2d`, `fractal2d`, `cellnoise2d`, `worleynoise2d`, `unifiednoise2d`.
    Noise(noise::NoiseOp),
    /// `noise3d`, `fractal3d`, `cellnoise3d`, `worleynoise3d`, `unifiednoise3d`.
    Noise3d(noise::Noise3dOp),
    /// Shapes, ramps, splits, random values.
    Pattern(pattern::PatternOp),
    /// `circle`, `line`, `hexagon`, `grid`, `crosshatch`, `tiledcircles`, `tiledhexagons`.
    Shape(shape::ShapeOp),
    /// Math nodes.
    Math(math::MathOp),
    /// Channel nodes.
    Channel(channel::ChannelOp),
    /// Colour adjustment nodes.
    Color(color::ColorOp),
    /// Compositing: blends, the Porter–Duff alpha operators, masks, premultiplication.
    Composite(composite::CompositeOp),
    /// `crossproduct`, `reflect`, `refract`.
    Vector(vector::VectorOp),
    /// `normalmap`, `heighttonormal`.
    Normal(normal::NormalOp),
    /// `image`, `tiledimage`.
    Image(Arc<image::Texture>),
    /// `latlongimage`.
    LatLong(Arc<image::Texture>),
    /// `triplanarprojection`.
    Triplanar(Arc<image::Triplanar>),
    /// `flake2d`, `flake3d` (one node per output).
    Flake(flake::FlakeOp),
    /// `hextiledimage`, `hextilednormalmap`.
    HexTile(Arc<hextile::HexTile>),
    /// A node that evaluates its `default` input (its first), as MaterialX's image nodes do
    /// when their `file` is empty; the text says why, as a load warning.
    Default(String),
}

/// Per-evaluation context handed to nodes.
pub(crate) struct Ctx<'a> {
    pub fp: &'a Footprint,
    /// True when the footprint is a point (Σ = 0): gradients are not needed.
    pub point: bool,
    pub work: &'a mut Work,
}

/// Evaluates one node filtered, from its (already filtered) inputs, into `out`. At points
/// (unfiltered evaluation) the result carries no uv gradient, whatever the node family computed
/// on the way.
///
/// The value is written in place: returned and then stored, it went through temporaries that
/// each copy read back across their fresh stores (a store-forwarding stall per node).
#[inline]
pub(crate) fn eval_into(op: &Op, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx, out: &mut Filtered) {
    // Math nodes write their channels into `out` themselves; the other families return a value.
    match op {
        Op::Math(m) => math::eval_into(m, ty, ins, ctx, out),
        Op::Geometry(g) => *out = geometry::eval(g, ty, ins, ctx),
        Op::Noise(n) => *out = noise::eval(n, ty, ins, ctx),
        Op::Noise3d(n) => *out = noise::eval3d(n, ty, ins, ctx),
        Op::Pattern(p) => *out = pattern::eval(p, ty, ins, ctx),
        Op::Shape(s) => *out = shape::eval(s, ty, ins, ctx),
        Op::Channel(c) => *out = channel::eval(c, ty, ins, ctx),
        Op::Color(c) => *out = color::eval(c, ty, ins, ctx),
        Op::Composite(c) => *out = composite::eval(c, ty, ins, ctx),
        Op::Vector(v) => *out = vector::eval(v, ty, ins, ctx),
        Op::Image(t) => *out = image::eval(t, ty, ins, ctx),
        Op::LatLong(t) => *out = image::eval_latlong(t, ty, ins, ctx),
        Op::Triplanar(t) => *out = image::eval_triplanar(t, ty, ins, ctx),
        Op::HexTile(h) => *out = hextile::eval(h, ty, ins, ctx),
        Op::Flake(f) => *out = flake::eval(f, ty, ins, ctx),
        Op::Normal(n) => *out = normal::eval(n, ty, ins, ctx),
        Op::Default(_) => *out = ins[0],
    }
    if ctx.point {
        point_gradients(out);
    }
}

/// Clears `out`'s gradients: at a point footprint a node reports none.
#[inline]
pub(crate) fn point_gradients(out: &mut Filtered) {
    for c in out.ch.iter_mut() {
        c.grad = glam::Vec2::ZERO;
    }
}

/// [`eval_into`], returning the value.
pub(crate) fn eval(op: &Op, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let mut out = Filtered::zero(ty);
    eval_into(op, ty, ins, ctx, &mut out);
    out
}

/// The overflow rule every node shares: a mean or gradient beyond the largest finite `f32`
/// saturates to ±`f32::MAX`, a variance to `f32::MAX`. Finite inputs thus never become infinite
/// on the way through a graph (`exp(100)`, `x / 1e-40`, a product of two huge values), while a
/// NaN stays NaN so that the evaluator can report the node that made it. The evaluator applies
/// it to every node's value that is not finite (one check per node).
#[inline]
pub(crate) fn saturate(v: &mut Filtered) {
    const M: f32 = f32::MAX;
    for c in v.ch.iter_mut() {
        c.mean = c.mean.clamp(-M, M);
        c.grad = glam::Vec2::new(c.grad.x.clamp(-M, M), c.grad.y.clamp(-M, M));
        c.var = c.var.clamp(0.0, M);
    }
}

/// Whether the operation itself reads the shading point's geometry beyond uv (position, normal,
/// tangent, bitangent).
pub(crate) fn reads_geometry(op: &Op) -> bool {
    match op {
        Op::Geometry(g) => geometry::reads_geometry(g),
        _ => false,
    }
}

/// A warning about a node that loads but cannot do what it asks.
pub(crate) fn warning(op: &Op) -> Option<String> {
    match op {
        Op::Geometry(g) => geometry::warning(g),
        Op::Default(why) => Some(why.clone()),
        _ => None,
    }
}

/// Every category this library supports.
pub fn supported() -> Vec<&'static str> {
    let mut v: Vec<&'static str> = Vec::new();
    for f in [
        geometry::CATEGORIES,
        noise::CATEGORIES,
        noise::CATEGORIES_3D,
        pattern::CATEGORIES,
        shape::CATEGORIES,
        math::CATEGORIES,
        channel::CATEGORIES,
        color::CATEGORIES,
        composite::CATEGORIES,
        vector::CATEGORIES,
        image::CATEGORIES,
        hextile::CATEGORIES,
        normal::CATEGORIES,
        flake::CATEGORIES,
    ] {
        v.extend_from_slice(f);
    }
    v.extend_from_slice(crate::matrix::FOLDED);
    v.extend_from_slice(FOLDED_AT_LOAD);
    v.sort_unstable();
    v
}

/// Nodes of the application rather than the surface, which the MaterialX reader folds to
/// constants at load: `frame` (the frame rendered, [`crate::mtlx::LoadOptions::frame`]) and
/// `time` (`frame / fps`).
pub const FOLDED_AT_LOAD: &[&str] = &["frame", "time"];

/// Supported categories as one comma-separated line.
pub fn supported_list() -> String {
    supported().join(", ")
}

/// The definition of a category.
pub fn definition(category: &str) -> Option<NodeDef> {
    geometry::definition(category)
        .or_else(|| noise::definition(category))
        .or_else(|| noise::definition3d(category))
        .or_else(|| pattern::definition(category))
        .or_else(|| shape::definition(category))
        .or_else(|| math::definition(category))
        .or_else(|| channel::definition(category))
        .or_else(|| color::definition(category))
        .or_else(|| composite::definition(category))
        .or_else(|| vector::definition(category))
        .or_else(|| image::definition(category))
        .or_else(|| hextile::definition(category))
        .or_else(|| normal::definition(category))
        .or_else(|| flake::definition(category))
}

/// Input names of a category (empty if unknown).
pub fn input_names(category: &str) -> Vec<&'static str> {
    definition(category).map(|d| d.inputs.iter().map(|i| i.name).collect()).unwrap_or_default()
}

/// Output-type predicates used by definitions.
pub(crate) mod types {
    use crate::value::ValueType::{self, *};
    pub fn numeric(_: ValueType) -> bool {
        true
    }
    pub fn float(t: ValueType) -> bool {
        t == Float
    }
    pub fn vector2(t: ValueType) -> bool {
        t == Vector2
    }
    pub fn color3(t: ValueType) -> bool {
        t == Color3
    }
    pub fn multichannel(t: ValueType) -> bool {
        t.channels() > 1
    }
    pub fn float_or_vector(t: ValueType) -> bool {
        matches!(t, Float | Vector2 | Vector3 | Vector4 | Color3 | Color4)
    }
    pub fn color(t: ValueType) -> bool {
        matches!(t, Color3 | Color4)
    }
    pub fn boolean(t: ValueType) -> bool {
        t == Boolean
    }
}

#[cfg(test)]
mod tests {
    /// The evaluator's fixed input array holds every definition's inputs.
    #[test]
    fn every_definition_fits_the_input_array() {
        let folded = |c: &&str| crate::matrix::FOLDED.contains(c) || super::FOLDED_AT_LOAD.contains(c);
        for c in super::supported().into_iter().filter(|c| !folded(c)) {
            let d = super::definition(c).unwrap();
            assert!(d.inputs.len() <= super::MAX_INPUTS, "{c}: {} inputs", d.inputs.len());
        }
    }
}
