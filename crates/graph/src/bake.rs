//! Baking: a graph output evaluated on a grid of texels over a uv rectangle. This is the core of
//! `tessera bake` and of the MaterialX conformance runner (`tests/verify/suite.rs`), which therefore
//! check the same code.
//!
//! # Grid and orientation
//!
//! A bake of `W × H` texels covers the uv rectangle `[u0, u1] × [v0, v1]`. Texel `(i, j)` —
//! column `i` counted from the left, row `j` counted from the top of the stored image — has its
//! centre at `u = u0 + (i + ½)/W · (u1 − u0)` and
//!
//! - [`Orientation::MaterialX`]: `v = v1 − (j + ½)/H · (v1 − v0)`: row 0 (the top row) is
//!   `v = v1`, the bottom row is `v = v0`. This is how MaterialX's TextureBaker writes images
//!   (OpenGL's convention, v pointing up), and how the reference bakes of the conformance suite
//!   are stored.
//! - [`Orientation::Mitsuba`]: `v = v0 + (j + ½)/H · (v1 − v0)`: row 0 (the top row) is
//!   `v = v0`, the bottom row is `v = v1`. This is Mitsuba's bitmap convention (uv (0, 0) at the
//!   top-left of the file), so a bake over [0, 1]² loaded by a Mitsuba `bitmap` texture shows the
//!   same values at a surface's uv as the graph does when the renderer evaluates it there.
//!
//! # Filtering
//!
//! [`BakeFilter::Point`] evaluates unfiltered at texel centres (what MaterialX's baker computes
//! for procedural nodes). [`BakeFilter::Texel`] evaluates filtered over the footprint of one
//! texel: a Gaussian centred on the texel with standard deviation half a texel along each axis
//! (`Δu/2`, `Δv/2`). Its mip level — log2 of its 2σ width in texels — is 0, which is the level
//! OpenGL picks for a pixel covering one texel, so texel-filtered bakes of image lookups
//! reproduce what a GPU baker samples.
//!
//! Texels are evaluated in parallel (rayon, one [`EvalScratch`] per worker); every texel is a
//! pure function of its position, so the result does not depend on the thread count.

use crate::eval::EvalScratch;
use crate::graph::{Graph, OutputId};
use crate::mtlx::{Document, MaterialSource};
use crate::value::{Footprint, Value, ValueType};
use glam::{Mat2, Vec2};
use rayon::prelude::*;
use std::fmt;
use std::str::FromStr;

/// Which image row is `v = v1` (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Orientation {
    /// Row 0 (top) is `v = v1`: MaterialX's TextureBaker, OpenGL.
    #[default]
    MaterialX,
    /// Row 0 (top) is `v = v0`: Mitsuba's bitmap convention.
    Mitsuba,
}

impl FromStr for Orientation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "materialx" => Ok(Orientation::MaterialX),
            "mitsuba" => Ok(Orientation::Mitsuba),
            _ => Err(format!("unknown orientation '{s}' (expected mitsuba or materialx)")),
        }
    }
}

/// How each texel is evaluated (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BakeFilter {
    /// Unfiltered, at the texel centre.
    #[default]
    Point,
    /// Filtered over a Gaussian of half a texel's standard deviation per axis.
    Texel,
}

impl FromStr for BakeFilter {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "point" => Ok(BakeFilter::Point),
            "texel" => Ok(BakeFilter::Texel),
            _ => Err(format!("unknown filter '{s}' (expected point or texel)")),
        }
    }
}

/// The grid of a bake.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BakeSettings {
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// uv at the left (u) and at the `v0` edge.
    pub uv_min: Vec2,
    /// uv at the right (u) and at the `v1` edge.
    pub uv_max: Vec2,
    /// Point or texel filtering.
    pub filter: BakeFilter,
    /// Which row is `v1`.
    pub orientation: Orientation,
}

/// The largest bake, in texels (2^28, as for rendered images).
pub const MAX_TEXELS: u64 = 1 << 28;

impl BakeSettings {
    /// A `width × height` point-sampled bake of [0, 1]² in MaterialX orientation.
    pub fn new(width: u32, height: u32) -> BakeSettings {
        BakeSettings {
            width,
            height,
            uv_min: Vec2::ZERO,
            uv_max: Vec2::ONE,
            filter: BakeFilter::Point,
            orientation: Orientation::MaterialX,
        }
    }

    /// Checks the resolution and the uv rectangle.
    pub fn validate(&self) -> Result<(), BakeError> {
        let bad = |m: String| Err(BakeError::Settings(m));
        if self.width == 0 || self.height == 0 {
            return bad(format!("resolution {}x{} has no texels", self.width, self.height));
        }
        if self.width as u64 * self.height as u64 > MAX_TEXELS {
            return bad(format!("resolution {}x{} exceeds {MAX_TEXELS} texels", self.width, self.height));
        }
        if !(self.uv_min.is_finite() && self.uv_max.is_finite()) {
            return bad("the uv rectangle must be finite".into());
        }
        if self.uv_min.x == self.uv_max.x || self.uv_min.y == self.uv_max.y {
            return bad(format!(
                "the uv rectangle ({}, {}) to ({}, {}) is empty",
                self.uv_min.x, self.uv_min.y, self.uv_max.x, self.uv_max.y
            ));
        }
        Ok(())
    }

    /// The uv at the centre of texel `(i, j)` (column `i`, row `j` from the top).
    pub fn texel_uv(&self, i: u32, j: u32) -> Vec2 {
        let d = self.uv_max - self.uv_min;
        let fu = (i as f32 + 0.5) / self.width as f32;
        let fv = (j as f32 + 0.5) / self.height as f32;
        let v = match self.orientation {
            Orientation::MaterialX => self.uv_max.y - fv * d.y,
            Orientation::Mitsuba => self.uv_min.y + fv * d.y,
        };
        Vec2::new(self.uv_min.x + fu * d.x, v)
    }

    /// The footprint texel `(i, j)` is evaluated at.
    pub fn footprint(&self, i: u32, j: u32) -> Footprint {
        let uv = self.texel_uv(i, j);
        match self.filter {
            BakeFilter::Point => Footprint::point(uv),
            BakeFilter::Texel => {
                let half = (self.uv_max - self.uv_min).abs() / Vec2::new(self.width as f32, self.height as f32) * 0.5;
                Footprint::new(uv, Mat2::from_diagonal(half * half))
            }
        }
    }
}

/// What a bake evaluates: a graph output, or a uniform value (a material input set to a
/// constant).
#[derive(Clone, Debug, PartialEq)]
pub enum BakeSource {
    /// A graph output.
    Output(OutputId),
    /// A uniform value.
    Constant(Value),
}

/// A baked image: `width × height` texels of `ty.channels()` floats, row-major, row 0 at the
/// top (see [`Orientation`] for which v that is).
#[derive(Clone, Debug, PartialEq)]
pub struct BakedImage {
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// The value type (its channel count is the number of floats per texel).
    pub ty: ValueType,
    /// Texel values.
    pub data: Vec<f32>,
}

impl BakedImage {
    /// Channels per texel.
    pub fn channels(&self) -> usize {
        self.ty.channels()
    }

    /// The channels of texel `(i, j)`.
    pub fn texel(&self, i: u32, j: u32) -> &[f32] {
        let n = self.channels();
        let k = (j as usize * self.width as usize + i as usize) * n;
        &self.data[k..k + n]
    }

    /// MaterialX's channel names for the type: `Y` for scalars, `R,G` for vector2, `R,G,B` for
    /// three channels, `R,G,B,A` for four.
    pub fn channel_names(&self) -> &'static [&'static str] {
        channel_names(self.ty)
    }
}

/// MaterialX's (and the conformance suite's) EXR channel names for a type.
pub fn channel_names(ty: ValueType) -> &'static [&'static str] {
    match ty.channels() {
        1 => &["Y"],
        2 => &["R", "G"],
        3 => &["R", "G", "B"],
        _ => &["R", "G", "B", "A"],
    }
}

/// A bake that cannot be made.
#[derive(Clone, Debug, PartialEq)]
pub enum BakeError {
    /// The element is neither an output nor a material input; lists what is available.
    UnknownElement {
        /// The name asked for.
        element: String,
        /// Every bakeable element of the document.
        available: Vec<String>,
    },
    /// The element exists but cannot be evaluated (it depends on unsupported nodes, or is not
    /// connected).
    Unavailable {
        /// The name asked for.
        element: String,
        /// Why.
        reason: String,
    },
    /// Invalid resolution or uv rectangle.
    Settings(String),
    /// A texel's value is not finite (nothing is written): where, and the node where the
    /// evaluation first went non-finite.
    NonFinite {
        /// Column from the left.
        i: u32,
        /// Row from the top of the image.
        j: u32,
        /// The texel's centre.
        uv: Vec2,
        /// The origin (see [`crate::eval::NonFinite::describe`]), or why none was found.
        origin: String,
        /// How many texels are not finite.
        count: usize,
    },
}

impl fmt::Display for BakeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BakeError::UnknownElement { element, available } => {
                write!(f, "no element `{element}` to bake; ")?;
                if available.is_empty() {
                    write!(f, "the document has no bakeable outputs")
                } else {
                    write!(f, "available: {}", available.join(", "))
                }
            }
            BakeError::Unavailable { element, reason } => write!(f, "cannot bake `{element}`: {reason}"),
            BakeError::Settings(m) => f.write_str(m),
            BakeError::NonFinite { i, j, uv, origin, count } => write!(
                f,
                "{count} texel(s) are not finite (nothing written); the first, texel ({i}, {j}) at uv ({}, {}): {origin}",
                uv.x, uv.y
            ),
        }
    }
}

impl std::error::Error for BakeError {}

/// Every element of `doc` that [`resolve`] accepts: graph outputs (`nodegraph/output`, or
/// `output` at the top level), then material inputs (`material/shader/input`) connected to
/// graphs or set to values.
pub fn bakeable_elements(doc: &Document) -> Vec<String> {
    let mut v: Vec<String> =
        doc.graph().outputs().iter().map(|o| o.name.clone()).filter(|n| !doc.is_shader_input_output(n)).collect();
    v.extend(doc.shader_input_paths());
    v
}

/// Resolves an element name to what to bake and its type. Accepts graph output names and
/// material inputs as `material/shader/input` (the conformance manifest's form), `material/input`
/// or `shader/input`.
pub fn resolve(doc: &Document, element: &str) -> Result<(BakeSource, ValueType), BakeError> {
    let g = doc.graph();
    if let Some(id) = g.output_id(element) {
        return Ok((BakeSource::Output(id), g.output(id).ty));
    }
    if let Some((_, reason)) = doc.skipped().iter().find(|(n, _)| n == element) {
        return Err(BakeError::Unavailable { element: element.to_string(), reason: reason.clone() });
    }
    let parts: Vec<&str> = element.split('/').collect();
    let found = match parts.as_slice() {
        [m, s, i] => doc.shader_input(m, Some(s), i),
        [m, i] => doc.shader_input(m, None, i),
        _ => None,
    };
    match found {
        Some(Ok((MaterialSource::Output(id), _))) => Ok((BakeSource::Output(id), g.output(id).ty)),
        Some(Ok((MaterialSource::Constant(v), _))) => Ok((BakeSource::Constant(v), v.ty)),
        Some(Ok((MaterialSource::Geometric, ty))) => Err(BakeError::Unavailable {
            element: element.to_string(),
            reason: format!("the input ({ty}) is neither connected nor set"),
        }),
        Some(Err(reason)) => Err(BakeError::Unavailable { element: element.to_string(), reason }),
        None => Err(BakeError::UnknownElement { element: element.to_string(), available: bakeable_elements(doc) }),
    }
}

/// Bakes `source` of `graph` with `settings`; `ty` is the type to write (its channel count).
pub fn bake(
    graph: &Graph,
    source: &BakeSource,
    ty: ValueType,
    settings: &BakeSettings,
) -> Result<BakedImage, BakeError> {
    settings.validate()?;
    let (w, h) = (settings.width, settings.height);
    let n = ty.channels();
    let mut data = vec![0.0f32; w as usize * h as usize * n];
    match source {
        BakeSource::Constant(v) => {
            for px in data.chunks_exact_mut(n) {
                for (k, x) in px.iter_mut().enumerate() {
                    *x = v.v.get(k).copied().unwrap_or(0.0);
                }
            }
        }
        BakeSource::Output(out) => {
            data.par_chunks_mut(w as usize * n).enumerate().for_each_init(
                || EvalScratch::new(graph),
                |scratch, (j, row)| {
                    for (i, px) in row.chunks_exact_mut(n).enumerate() {
                        let f = graph.eval_output(*out, &settings.footprint(i as u32, j as u32), scratch);
                        for (k, x) in px.iter_mut().enumerate() {
                            *x = f.ch[k].mean;
                        }
                    }
                },
            );
        }
    }
    if let Some(first) = data.iter().position(|x| !x.is_finite()) {
        // Never a NaN texel: say where, and which node made it (evaluated again to find out).
        let count = data.chunks_exact(n).filter(|px| px.iter().any(|x| !x.is_finite())).count();
        let texel = (first / n) as u32;
        let (i, j) = (texel % w, texel / w);
        let fp = settings.footprint(i, j);
        let origin = match source {
            BakeSource::Output(out) => {
                let mut scratch = EvalScratch::new(graph);
                graph.eval_output(*out, &fp, &mut scratch);
                match scratch.take_nonfinite() {
                    Some(at) => at.describe(graph),
                    None => "no node gave a non-finite value when evaluated again".into(),
                }
            }
            BakeSource::Constant(_) => "the element is a constant that is not finite".into(),
        };
        return Err(BakeError::NonFinite { i, j, uv: fp.uv, origin, count });
    }
    Ok(BakedImage { width: w, height: h, ty, data })
}

/// Resolves `element` in `doc` and bakes it.
pub fn bake_element(doc: &Document, element: &str, settings: &BakeSettings) -> Result<BakedImage, BakeError> {
    let (source, ty) = resolve(doc, element)?;
    bake(doc.graph(), &source, ty, settings)
}
