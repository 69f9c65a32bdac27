//! A random-graph generator for the totality fuzzer (`tests/verify/random_graphs.rs`): graphs drawn from
//! the whole node library with type-respecting random wiring and random (often extreme)
//! constants, and random footprints from a point to 1e3 uv, rank one or anisotropic up to 1e4.
//!
//! Nothing here knows any node's natural range: the wiring feeds one node's output into any input
//! that accepts its type, as graphs people write do.

use crate::common::Rng;
use glam::{Mat2, Vec2};
use graph::nodes::{self, InType};
use graph::{Graph, GraphBuilder, Source, Value, ValueType};

/// Categories the generator leaves out, with the reason.
pub const EXCLUDED: &[(&str, &str)] = &[
    ("image", "needs a file"),
    ("tiledimage", "needs a file"),
    ("latlongimage", "needs a file"),
    ("triplanarprojection", "needs a file"),
    ("creatematrix", "matrices are folded at load, not evaluated"),
    ("determinant", "matrices are folded at load, not evaluated"),
    ("invertmatrix", "matrices are folded at load, not evaluated"),
    ("transpose", "matrices are folded at load, not evaluated"),
    ("frame", "folded to a constant by the MaterialX reader"),
    ("time", "folded to a constant by the MaterialX reader"),
];

/// Categories drawn with an image file: a small test texture ([`texture`]) as their `file`.
pub const WITH_FILE: &[&str] = &["hextiledimage", "hextilednormalmap"];

/// An 8 × 8 RGBA PNG of varied texels (black ones among them), written once.
pub fn texture() -> std::path::PathBuf {
    static PATH: std::sync::OnceLock<std::path::PathBuf> = std::sync::OnceLock::new();
    PATH.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("graph-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("texture.png");
        let img = image::RgbaImage::from_fn(8, 8, |x, y| {
            let k = (x * 37 + y * 91) % 251;
            let c = if (x + y) % 5 == 0 {
                [0, 0, 0, 255]
            } else {
                [k as u8, (k * 7 % 256) as u8, (255 - k) as u8, (k * 3 % 256) as u8]
            };
            image::Rgba(c)
        });
        img.save(&path).unwrap();
        path
    })
    .clone()
}

/// Categories whose unfiltered function is continuous in every input (for any constants): their
/// filtered mean is compared with brute-force supersampling.
pub const CONTINUOUS: &[&str] = &[
    "add",
    "subtract",
    "multiply",
    "invert",
    "absval",
    "clamp",
    "min",
    "max",
    "sin",
    "cos",
    "mix",
    "dotproduct",
    "magnitude",
    "distance",
    "noise2d",
    "fractal2d",
    "noise3d",
    "fractal3d",
    "worleynoise2d",
    "texcoord",
    "position",
    "normal",
    "tangent",
    "bitangent",
    "constant",
    "place2d",
    "rotate2d",
    "rotate3d",
    "combine2",
    "combine3",
    "combine4",
    "separate2",
    "separate3",
    "separate4",
    "extract",
    "convert",
    "luminance",
    "contrast",
    "saturate",
    "ramplr",
    "ramptb",
    "ramp4",
    "dot",
    "plus",
    "minus",
    "difference",
    "screen",
    "overlay",
    "over",
    "in",
    "mask",
    "matte",
    "out",
    "inside",
    "outside",
    "premult",
    "crossproduct",
    "reflect",
    "trianglewave",
    "geomcolor",
    "blur",
];

/// Every category the generator draws from.
pub fn categories() -> Vec<&'static str> {
    nodes::supported().into_iter().filter(|c| !EXCLUDED.iter().any(|(e, _)| e == c)).collect()
}

const TYPES: [ValueType; 8] = [
    ValueType::Float,
    ValueType::Integer,
    ValueType::Boolean,
    ValueType::Vector2,
    ValueType::Vector3,
    ValueType::Vector4,
    ValueType::Color3,
    ValueType::Color4,
];

/// A random float constant: ordinary values most of the time, extreme ones often.
pub fn constant_float(rng: &mut Rng) -> f32 {
    const EXTREME: [f32; 14] = [0.0, 1e-7, -1e-7, 1e6, -1e6, 1.0, -1.0, 0.5, -0.5, 1e-3, -1e-3, 3.0, -3.0, 100.0];
    match rng.next_u64() % 3 {
        0 => EXTREME[(rng.next_u64() % EXTREME.len() as u64) as usize],
        1 => (rng.uniform() * 4.0 - 2.0) as f32,
        _ => (rng.uniform() * 20.0 - 10.0) as f32,
    }
}

fn constant(rng: &mut Rng, ty: ValueType) -> Value {
    let mut v = [0.0f32; 4];
    let splat = rng.next_u64() % 2 == 0;
    let first = constant_float(rng);
    for (k, x) in v.iter_mut().enumerate().take(ty.channels()) {
        *x = match ty {
            ValueType::Boolean => (rng.next_u64() % 2) as f32,
            ValueType::Integer => {
                [0.0, 1.0, 2.0, 3.0, 5.0, 8.0, 16.0, -1.0, -4.0, 40.0][(rng.next_u64() % 10) as usize]
            }
            _ if splat || k == 0 => first,
            _ => constant_float(rng),
        };
    }
    Value { ty, v }
}

/// A random graph and what it was drawn from.
pub struct RandomGraph {
    /// The graph: one output per node, named after it.
    pub graph: Graph,
    /// Whether every node is in [`CONTINUOUS`].
    #[allow(dead_code)]
    pub continuous: bool,
    /// A readable listing (category, type, inputs) for failure messages.
    pub listing: String,
}

/// The concrete types an input spec may take, given the node's type and earlier inputs' types.
fn input_types(spec: &nodes::InputSpec, node_ty: ValueType, earlier: &[ValueType]) -> Vec<ValueType> {
    TYPES.iter().copied().filter(|t| spec.accepts_with(node_ty, *t, earlier)).collect()
}

/// Draws a graph of `size` nodes (fewer when a drawn node cannot be built: every attempt is
/// bounded). With `continuous_only`, nodes come from [`CONTINUOUS`] alone.
pub fn random_graph(rng: &mut Rng, size: usize, continuous_only: bool) -> RandomGraph {
    let pool: Vec<&'static str> = if continuous_only { CONTINUOUS.to_vec() } else { categories() };
    let mut b = GraphBuilder::new();
    let mut made: Vec<(graph::NodeId, ValueType)> = Vec::new();
    let mut listing = String::new();
    let mut attempts = 0;
    while made.len() < size && attempts < size * 20 {
        attempts += 1;
        let cat = pool[(rng.next_u64() % pool.len() as u64) as usize];
        let Some(def) = nodes::definition(cat) else { continue };
        let tys: Vec<ValueType> = TYPES.iter().copied().filter(|t| (def.types)(*t)).collect();
        if tys.is_empty() {
            continue;
        }
        let ty = tys[(rng.next_u64() % tys.len() as u64) as usize];
        let mut inputs: Vec<(&str, Source)> = Vec::new();
        let mut earlier: Vec<ValueType> = Vec::new();
        for spec in def.inputs {
            let allowed = input_types(spec, ty, &earlier);
            // Wire to an earlier node (or a channel of one), to uv, or a constant; or leave the
            // nodedef default.
            let roll = rng.next_u64() % 10;
            let mut src: Option<(Source, ValueType)> = None;
            if roll < 6 && !made.is_empty() {
                for _ in 0..6 {
                    let (id, t) = made[(rng.next_u64() % made.len() as u64) as usize];
                    if allowed.contains(&t) {
                        src = Some((Source::Node { node: id, channel: None }, t));
                        break;
                    }
                    if t.channels() > 1 && allowed.contains(&ValueType::Float) && t != ValueType::Boolean {
                        let c = (rng.next_u64() % t.channels() as u64) as u8;
                        src = Some((Source::Node { node: id, channel: Some(c) }, ValueType::Float));
                        break;
                    }
                }
            }
            if src.is_none() && roll < 7 && allowed.contains(&ValueType::Vector2) {
                src = Some((Source::Texcoord, ValueType::Vector2));
            }
            if src.is_none() && roll < 9 && !allowed.is_empty() {
                let t = if matches!(spec.ty, InType::Out | InType::SameAs(_)) {
                    allowed[0]
                } else {
                    allowed[(rng.next_u64() % allowed.len() as u64) as usize]
                };
                src = Some((Source::Constant(constant(rng, t)), t));
            }
            match src {
                Some((s, t)) => {
                    inputs.push((spec.name, s));
                    earlier.push(t);
                }
                None => {
                    // The default's type, for the `SameAs` rules of later inputs.
                    let d = spec.default_source_with(ty, &earlier);
                    let t = match &d {
                        Source::Constant(v) => v.ty,
                        Source::Texcoord => ValueType::Vector2,
                        _ => ValueType::Vector3,
                    };
                    earlier.push(t);
                }
            }
        }
        let name = format!("n{}", made.len());
        let params = if WITH_FILE.contains(&cat) {
            vec![nodes::Param::File { name: "file".into(), path: texture(), colorspace: String::new() }]
        } else {
            Vec::new()
        };
        if let Ok(id) = b.add_node(&name, cat, ty, &inputs, params) {
            listing += &format!("{name} = {cat}<{ty}>(");
            for (k, (iname, s)) in inputs.iter().enumerate() {
                let s = match s {
                    Source::Constant(v) => format!("{:?}", v.channels()),
                    Source::Texcoord => "uv".into(),
                    Source::Geometry(g) => format!("{g:?}"),
                    Source::Node { node, channel } => match channel {
                        Some(c) => format!("n{}.{c}", node.0),
                        None => format!("n{}", node.0),
                    },
                };
                listing += &format!("{}{iname}={s}", if k > 0 { ", " } else { "" });
            }
            listing += ")\n";
            made.push((id, ty));
        }
    }
    for (id, ty) in &made {
        let name = format!("out{}", id.0);
        b.add_output(&name, *ty, Source::Node { node: *id, channel: None }).unwrap();
    }
    RandomGraph { graph: b.build(), continuous: continuous_only, listing }
}

/// A random footprint's covariance: σ log-uniform in [1e-7, 1e3] uv (a point one time in ten),
/// aspect up to 1e4 (rank one one time in ten), random orientation. Returns the Cholesky-like
/// factor `L` (Σ = L Lᵀ) and σ, the major axis's standard deviation.
pub fn random_footprint(rng: &mut Rng) -> (Mat2, f32) {
    if rng.next_u64() % 10 == 0 {
        return (Mat2::ZERO, 0.0);
    }
    let sigma = 10f64.powf(-7.0 + 10.0 * rng.uniform()) as f32;
    let aspect = match rng.next_u64() % 10 {
        0 => 0.0,
        1..=3 => 1.0,
        _ => 10f64.powf(-4.0 * rng.uniform()) as f32,
    };
    let r = Mat2::from_angle(rng.uniform() as f32 * std::f32::consts::PI);
    (r * Mat2::from_diagonal(Vec2::new(sigma, aspect * sigma)), sigma)
}

/// A random footprint centre: mostly a few units around the origin, sometimes far out.
pub fn random_centre(rng: &mut Rng) -> Vec2 {
    let scale = if rng.next_u64() % 8 == 0 { 1000.0 } else { 3.0 };
    Vec2::new((rng.uniform() * 2.0 - 1.0) as f32 * scale, (rng.uniform() * 2.0 - 1.0) as f32 * scale)
}
