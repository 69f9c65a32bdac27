//! Procedural texture graphs evaluated *filtered* to the footprint of a path vertex.
//!
//! A [`Graph`] is an immutable DAG of typed MaterialX nodes (float, vector2/3/4, color3/4)
//! with named outputs, usually loaded from a `.mtlx` file by [`Document`] (which also exposes
//! `standard_surface`, `open_pbr_surface` and `gltf_pbr` materials as [`MaterialBinding`]s). [`Graph::eval_output`] evaluates an
//! output at a [`Footprint`] — a uv centre, a 2×2 uv covariance Σ and the surface
//! [`Geometry`] there (position, frame, ∂P/∂u, ∂P/∂v; MaterialX's flat baking quad unless the
//! renderer gives one) — and returns a
//! [`Filtered`] value: per channel the [`Moments`] of the node's unfiltered output over
//! `uv' ~ N(uv, Σ)`: its mean (the filtered value), the gradient of that mean with respect to
//! uv, and its variance (the spread over the footprint). Σ = 0 is unfiltered evaluation and
//! reproduces MaterialX's own results (its hash-based Perlin noise, cell noise, Worley noise).
//!
//! Values carry what downstream nodes need to filter themselves: a node whose input is a
//! transformed coordinate reads its own footprint from the input's per-channel variance (for
//! affine chains exactly `J Σ Jᵀ`); nonlinear nodes integrate their function against the
//! input's Gaussian (closed forms where they exist, Gauss–Hermite or cubature otherwise)
//! instead of applying it to a filtered mean. Per node family:
//!
//! | family (file) | nodes | filtering |
//! |---|---|---|
//! | geometry (`nodes/geometry.rs`) | texcoord, position, normal, tangent, bitangent, geompropvalue, constant, place2d, rotate2d, rotate3d, transformpoint, transformvector, transformnormal, transformmatrix, dot | exact (linear): `position` spreads by the surface Jacobian (`J Σ Jᵀ`); object, model and world space are one in tessera; transformnormal by cubature (it normalises); matrices are uniforms folded at load ([`matrix`]) |
//! | noise (`nodes/noise/`) | noise2d, fractal2d, cellnoise2d, worleynoise2d, unifiednoise2d | Perlin: Gaussian convolution of the separable corner kernels up to σ = 0.75 lattice units (the kernels' 1D Gaussian averages read from a table built from their exact integrals, within 5e-7: `nodes/kernel_table.rs`), Gaussian damping (fitted to the exact convolution) beyond, octaves past the band limit dropped (never evaluated); cell noise: exact cell masses; Worley: 3×3 Gauss–Hermite then the global mean; unifiednoise2d: its type's node (fractal3d as an exactly filtered z-slice of 3D Perlin noise), clamped-ramp moments for the output clamp |
//! | 3D noise (`nodes/noise/`) | noise3d, fractal3d, cellnoise3d, worleynoise3d, unifiednoise3d | as their 2D counterparts over the position input's per-axis spreads (the surface footprint's 3D marginals): Perlin exact up to σ = 0.25 lattice units per axis, damped beyond, octaves past the band limit dropped; cell noise exact cell masses; Worley Gauss–Hermite then the global mean (of the plane, for a footprint flat along a lattice axis) |
//! | patterns (`nodes/pattern.rs`) | checkerboard, ramplr, ramptb, ramp4, ramp, splitlr, splittb, randomfloat, randomcolor | closed forms: square-wave expectations (erf sums / damped Fourier series), clamped-ramp moments, piecewise-polynomial moments (`ramp`), step probabilities Φ |
//! | shapes (`nodes/shape/`) | circle, line, hexagon, grid, crosshatch, tiledcircles, tiledhexagons | coverage probabilities: grid closed form (periodic band masses); convex pieces (disk, capsule, hexagon, strips, clipped to cells) by Gauss–Legendre over the footprint's narrow axis of closed-form Φ chord masses along the other; tiled patterns become their coverage beyond 0.6 cells |
//! | math (`nodes/math.rs`) | add … ifequal, switch (see the file) | exact for linear nodes; closed forms for abs, clamp, min/max, smoothstep, floor/ceil/round/fract/modulo, sign, sin/cos, exp, conditionals (`switch`: the Gaussian mixture of its inputs); Gauss–Hermite / cubature for the rest |
//! | channels (`nodes/channel.rs`) | combine2/3/4, extract, separate2/3/4, convert | exact |
//! | hex tiling (`nodes/hextile.rs`, `nodes/hextile_normal.rs`) | hextiledimage, hextilednormalmap | each of the three blended tiles' lookups as `image` filters them, under the tile's rotation and scale; the blend weights integrated over the footprint at Gauss–Hermite nodes, converging to the image's mean at coarse footprints; normal maps blend the tiles' surface gradients and take `E[normalize(N − G)]` by cubature over the texels' spread of the gradient |
//! | flakes (`nodes/flake.rs`) | flake2d, flake3d (one library node per connected output) | 5 × 5 Gauss–Hermite over the uv footprint of the piecewise-constant flake lookup, moving to a 64-point ensemble of 64 cells once the footprint spans flakes |
//! | images (`nodes/image.rs`) | image, tiledimage | PNG (8/16 bit) / EXR, sRGB decoded at load; up to 1 texel the exact Gaussian average of the bilinear reconstruction (closed-form tent integrals), beyond it the same on a mip pyramid at lod = log2 σ, blended between levels; address modes periodic / clamp / mirror / constant (the default blended by the footprint's mass outside) |
//! | normal maps (`nodes/normal.rs`) | normalmap, heighttonormal | normalmap: cubature (flat tangent frame by default); heighttonormal: the normal of the filtered height's slope (gradients are kept at point footprints for it) |
//! | colour (`nodes/color.rs`) | luminance, saturate, contrast, rgbtohsv, hsvtorgb, hsvadjust | exact when linear; cubature otherwise |
//!
//! Every node is total: for finite inputs it returns finite moments at every footprint. The
//! rules the families share (overflow saturates to ±`f32::MAX`, the moment algebra in
//! [`moments`] redoes in f64 what overflows f32, division by zero is 0, `power` is OSL's `safe_pow`, Perlin noise is
//! 0 where f32 coordinates are whole numbers, fractal octaves stop where their amplitude or
//! frequency overflows) are listed in the README; `tests/verify/random_graphs.rs` fuzzes them. Should a
//! value still go non-finite, the evaluator records the node it started at
//! ([`EvalScratch::take_nonfinite`], [`EvalStats::nonfinite`]).
//!
//! Evaluation ([`eval`]) uses a per-thread [`EvalScratch`] (no allocation per evaluation),
//! visits only the nodes the requested outputs need in topological order, and asks a
//! [`NodeOverride`] first for each of them, so that a tile cache can replace a node by a lookup;
//! [`Graph::eval_node_direct`] evaluates one node filtered (a tile fill's call). The scratch
//! counts evaluations per node and [`Work`] (octaves, lattice visits) for profiling; coarse
//! footprints do less work than fine ones.
//!
//! [`bake`] evaluates one output on a grid of texels over a uv rectangle (point or one-texel
//! filtered, in MaterialX's or Mitsuba's row order): what `tessera bake` writes and what the
//! MaterialX conformance test (`tests/verify/suite.rs`) compares with MaterialX's own bakes.
//!
//! ```
//! use graph::{Document, Footprint, EvalScratch, LoadOptions};
//! use glam::Vec2;
//! let text = r#"<?xml version="1.0"?><materialx version="1.39">
//!   <nodegraph name="g">
//!     <fractal2d name="f" type="float"><input name="octaves" type="integer" value="6"/></fractal2d>
//!     <output name="out" type="float" nodename="f"/>
//!   </nodegraph></materialx>"#;
//! let doc = Document::parse(text, "inline.mtlx".as_ref(), &LoadOptions::default()).unwrap();
//! let g = doc.graph();
//! let out = g.output_id("g/out").unwrap();
//! let mut scratch = EvalScratch::new(g);
//! let sharp = g.eval_output(out, &Footprint::point(Vec2::new(0.3, 0.7)), &mut scratch);
//! let blurred = g.eval_output(out, &Footprint::isotropic(Vec2::new(0.3, 0.7), 10.0), &mut scratch);
//! assert!(blurred.ch[0].mean.abs() < 1e-3 && sharp.ch[0].var == 0.0);
//! ```
#![deny(missing_docs)]
// Channel loops index several parallel per-channel arrays at once.
#![allow(clippy::needless_range_loop)]

pub mod bake;
pub mod error;
pub mod eval;
pub mod gaussian;
pub mod graph;
pub mod matrix;
pub mod moments;
pub mod mtlx;
pub mod nodes;
pub mod text;

/// What the unit tests share.
#[cfg(test)]
pub(crate) mod testing {
    /// Uniform draws in [0, 1) from a xorshift64 stream seeded with `seed` (not 0): reproducible
    /// inputs for randomised tests.
    pub(crate) fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    }
}
pub mod value;

/// The most nodes a graph may have, after node graphs used as node implementations are
/// instantiated: far above any real graph (the demo graphs have tens to hundreds), and a few
/// tens of megabytes at most. Eight levels of node graphs each using the previous ten times made 10⁸
/// nodes (5 GB, more than 30 s) before there was a limit.
pub const MAX_NODES: usize = 1 << 16;

/// How deep node graphs used as node implementations may nest in each other (a node whose
/// definition's graph holds a node whose definition's graph holds …): far beyond the few levels
/// real libraries use. A chain of 20 000 such definitions (a linear number of nodes) took over
/// 24 GB in qualified names before there was a limit.
pub const MAX_INSTANCE_DEPTH: usize = 64;

pub use bake::{BakeError, BakeFilter, BakeSettings, BakeSource, BakedImage, Orientation};
pub use error::{BuildError, LoadError, LoadErrorKind, Location, Unsupported};
pub use eval::{
    clock_pair_ns, robust_mean, BinnedTimings, EvalOrder, EvalScratch, EvalStats, NoOverride, NodeOverride, NonFinite,
    Work, TIMING_PERIOD,
};
pub use graph::{GeomProp, Graph, GraphBuilder, GraphOutput, NodeId, OutputId, Source};
pub use matrix::Matrix;
pub use mtlx::{parse_value, Document, LoadOptions, MaterialBinding, MaterialSource};
pub use nodes::noise::{fractal3_point, perlin3, worley3_point};
pub use nodes::noise::{fractal_point, perlin_float, worley_point};
pub use value::{Filtered, Footprint, Geometry, Moments, Value, ValueType};
