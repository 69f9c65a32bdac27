//! Hex-tiled image lookups: `hextiledimage` (MaterialX 1.39, after Mikkelsen, "Practical
//! Real-Time Hex-Tiling", JCGT 11(2), 2022); `hextilednormalmap`, the same tiling of a normal
//! map, is in [`super::hextile_normal`].
//!
//! | input | type | default |
//! |---|---|---|
//! | `file` | filename | — (a missing file is a load error, as for `image`) |
//! | `default` | same as the output | 0 (read only when the file cannot be resolved: never in tessera) |
//! | `texcoord` | vector2 | UV0 |
//! | `tiling` | vector2 | 1, 1 |
//! | `rotation` | float | 1 |
//! | `rotationrange` | vector2 (degrees) | 0, 360 |
//! | `scale` | float | 1 |
//! | `scalerange` | vector2 | 0.5, 2 |
//! | `offset` | float | 1 |
//! | `offsetrange` | vector2 | 0, 1 |
//! | `falloff` | float | 0.5 |
//! | `falloffcontrast` | float | 0.5 |
//! | `lumacoeffs` | color3 | 0.2722287, 0.6740818, 0.0536895 (ACEScg) |
//!
//! Output types `color3` and `color4` (the only nodedefs MaterialX has). Defaults are those of
//! MaterialX's `stdlib_defs.mtlx` (the prose of the Standard Nodes document gives 0 for
//! `rotation` and `offset`; the nodedefs, which implementations read, give 1).
//!
//! **Unfiltered** (MaterialX's `mx_hextiledimage` / `mx_hextile_coord`). With
//! `c = F(texcoord · tiling)`, `F(x, y) = (x, 1 − y)` (MaterialX's `mx_transform_uv` with
//! `fileTextureVerticalFlip`, which its renderers and its TextureBaker set: the tiles, their
//! random maps and the blend live in the v-flipped coordinate, and each lookup point is flipped
//! back to the image's own v), and `st = 2√3 c` skewed onto the triangle grid, `k = (st.x − st.y/√3, 2 st.y/√3)`:
//! the cell is `⌊k⌋`, its fractional part `(x, y)`, `z = 1 − x − y`; the triangle is the upper
//! one when `z ≤ 0`. Its three vertices (`⌊k⌋ + (1,1), (1,0), (0,1)` for the upper triangle,
//! `⌊k⌋ + (0,0), (0,1), (1,0)` for the lower) carry the barycentric weights, and each vertex is
//! the centre of a hex tile at `ctr = (i + j/2, (√3/2) j) / (2√3)`. Each tile draws
//! `r = hash(i + 0.12345, j + 0.12345)` (MaterialX's two-output "hash without sine", evaluated in
//! `f32` as the shader does) and looks the image up (periodic, bilinear) at
//! `F(R(θ)(c − ctr)/σ + ctr + o)`, with `θ = mix(rotationrange)(r.x · rotation)` (degrees),
//! `σ = mix(1, mix(scalerange)(r.y), scale)`, `o = mix(offsetrange)(r · offset)` per axis. The
//! blend weights are `w ∝ (1 + falloffcontrast (luma(colour) − 1)) · b⁷`, normalised, then, when
//! `falloff ≠ 0.5`, passed through Schlick's gain with parameter `falloff` (clamped to
//! [0.001, 0.999]) and normalised again. RGB is `Σ w c`; the alpha of `color4` is `Σ aw a`, the
//! three alphas blended with the weights of luminance factor 1 (`b⁷` normalised, then the gain),
//! as MaterialX 1.39.5's GLSL and OSL blend it. Where the weights
//! sum to 0 (black texels with `falloffcontrast = 1`, where MaterialX divides by 0) the
//! luminance factor is dropped; a tile scale of 0 is taken as ±1e-6.
//!
//! Colour spaces are handled as for `image`: `srgb_texture` files are decoded at load, so the
//! blend (like all filtering) works on linear values; other spaces convert the node's output.
//!
//! **Filtered.** The footprint of `texcoord` (its per-channel spreads and the covariance of its
//! two channels) maps to the coordinate `c` exactly (`F T Σ T F`, `T = diag(tiling)`, the flip
//! negating the covariance of the two channels); its size is
//! `ρ = σ_max(c)/e` in triangle edges `e = 1/(2√3)` (a hex tile spans about 1.15 e).
//!
//! - *Lookups.* The centre triangle's three tiles each take `image`'s filtered lookup, centred on
//!   the tile's map of the centre, with the footprint mapped by the tile's linear map
//!   `L = R(θ)/σ`: `L Σ Lᵀ` exactly, whose marginal spreads the (axis-separable) lookup
//!   integrates over — exact for isotropic footprints, whose rotation stays isotropic; the
//!   correlation of an anisotropic footprint's rotated axes is dropped, as `image` drops it for
//!   sheared texture coordinates. The luminance factors use the filtered colours (as
//!   MaterialX's `textureGrad` lookups do).
//! - *Weights.* The result is `Σ_k E[w_k(x) c_k(x)]` over `x ~ N(c, Σ)`, with each lookup taken
//!   linear over the footprint (`c_k(x) = c̄_k + ∇c̄_k · (x − c)`): the weight masses `E[w_k]`
//!   and first moments `E[w_k (x − c)]` come from the blend weights (never the image) at the
//!   5 × 5 Gauss–Hermite nodes of the footprint (at its centre alone while `ρ` <
//!   [`CENTRE_ONLY`]). Tiles other than the three (met at nodes across the triangle's edges)
//!   take a surrogate lookup: the three's plain mean where the tiles' maps agree, the image's
//!   mean where they are unrelated, mixed by their coherence (see `Params::coherence`: 1 when
//!   all ranges have zero width, so that `hextiledimage` is then exactly `tiledimage` at every
//!   footprint). Alpha (`color4`) is filtered as the colour, with the weight masses of its own
//!   weights `aw`.
//! - *Beyond a tile.* From `ρ = `[`NEAR`] to [`FAR`] the result moves to the surrogate by a
//!   smoothstep in `log ρ` (the 25-node rule no longer resolves the tiles); from `FAR` on, when
//!   the tiles are unrelated (or every lookup is blurred past 1.5 image periods), the node
//!   returns the image's mean and global variance without any lookup: coarse footprints cost
//!   less than fine ones. The mean, not the luminance-weighted blend's mean, is the limit: the
//!   two differ by the weighting's bias (a few 1e-3 for the test texture).
//! - *Gradients* are forward-mode derivatives through the weights, the luminance factors, the
//!   gain and the lookups (the first-moment term's own derivative is left out). *Variance*: the
//!   lookups' spreads combined as fully correlated (`(Σ |W| σ)²`, exact when the tiles' maps
//!   coincide, an upper bound on independent lookups) plus the weights' linear variation, at
//!   least `gᵀΣg`, the weights' part at most a quarter of the squared range of the tiles' values
//!   (a convex combination's variance: the linearised weights' derivatives grow without bound
//!   where the luminance factors' sum nears 0); a lookup's spread is its linear part plus, as the footprint grows past a
//!   texel, the texels' own spread.
//!
//! No allocation per evaluation: everything lives on the stack (the lookups reuse `image`'s
//! per-thread buffers).

use super::image::{self, Texture};
use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::graph::Source;
use crate::value::{Filtered, Moments, ValueType};
use glam::{DMat2, DVec2, Vec2};
use std::ops::{Add, Div, Mul, Sub};
use std::sync::Arc;

pub(crate) const CATEGORIES: &[&str] = &["hextiledimage", "hextilednormalmap"];

/// Footprint size (σ of the coordinate over the triangle edge) up to which the blend weights at
/// the centre are used unchanged.
pub const NEAR: f64 = 0.7;
/// Footprint size from which the node returns the image's mean.
pub const FAR: f64 = 3.0;

/// Lookup spread (σ, image uv) from which a filtered lookup is the image's mean: the periodic
/// image's first harmonic is damped by `exp(−2π²σ²)` < 1e-19 there.
pub(super) const BLURRED: f64 = 1.5;
/// `2√3`: the scale from the coordinate to the triangle grid (whose edge is 1 there).
const GRID: f64 = 3.464_101_615_137_754_6;
/// MaterialX's skew constants (`tan 30°`, `2 tan 30°`).
const TAN30: f64 = 0.577_350_27;
const TAN30X2: f64 = 1.154_700_54;

/// A `hextiledimage` or `hextilednormalmap` node: the periodic texture it reads.
#[derive(Debug)]
pub struct HexTile {
    pub(super) tex: Texture,
    /// `hextilednormalmap` (see [`super::hextile_normal`]).
    normal_map: bool,
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    if category == "hextilednormalmap" {
        return Some(super::hextile_normal::definition());
    }
    if category != "hextiledimage" {
        return None;
    }
    let inputs: &'static [_] = &[
        inp!("default", Out, Zero),
        inp!("texcoord", V2, Uv),
        inp!("tiling", V2, Pair(1.0, 1.0)),
        inp!("rotation", Float, One),
        inp!("rotationrange", V2, Pair(0.0, 360.0)),
        inp!("scale", Float, One),
        inp!("scalerange", V2, Pair(0.5, 2.0)),
        inp!("offset", Float, One),
        inp!("offsetrange", V2, Pair(0.0, 1.0)),
        inp!("falloff", Float, Half),
        inp!("falloffcontrast", Float, Half),
        inp!("lumacoeffs", C3, Triple(0.272_228_7, 0.674_081_8, 0.053_689_5)),
    ];
    Some(NodeDef { category: CATEGORIES[0], inputs, params: &["file"], types: types::color, build })
}

pub(super) fn build(
    category: &str,
    _: ValueType,
    _: &[ValueType],
    _: &[Source],
    params: &[Param],
) -> Result<Op, String> {
    let file = params.iter().find_map(|p| match p {
        Param::File { name, path, colorspace } if name == "file" => Some((path, colorspace == "srgb_texture")),
        _ => None,
    });
    let Some((path, srgb)) = file else {
        return Err("no image file".into());
    };
    if path.as_os_str().is_empty() {
        return Ok(Op::Default("its `file` is empty: it gives its `default`".into()));
    }
    let normal_map = category == "hextilednormalmap";
    Ok(Op::HexTile(Arc::new(HexTile { tex: Texture::periodic(path, srgb)?, normal_map })))
}

/// A value and its gradient with respect to the coordinate `c` (forward-mode derivative).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Dual {
    pub(super) v: f64,
    pub(super) d: DVec2,
}

impl Dual {
    pub(super) const fn new(v: f64, d: DVec2) -> Dual {
        Dual { v, d }
    }
    pub(super) const fn constant(v: f64) -> Dual {
        Dual { v, d: DVec2::ZERO }
    }
    fn pow7(self) -> Dual {
        let v6 = self.v.powi(6);
        Dual { v: v6 * self.v, d: self.d * (7.0 * v6) }
    }
}

impl Add for Dual {
    type Output = Dual;
    fn add(self, o: Dual) -> Dual {
        Dual { v: self.v + o.v, d: self.d + o.d }
    }
}

impl Sub for Dual {
    type Output = Dual;
    fn sub(self, o: Dual) -> Dual {
        Dual { v: self.v - o.v, d: self.d - o.d }
    }
}

impl Mul for Dual {
    type Output = Dual;
    fn mul(self, o: Dual) -> Dual {
        Dual { v: self.v * o.v, d: self.d * o.v + o.d * self.v }
    }
}

impl Mul<f64> for Dual {
    type Output = Dual;
    fn mul(self, k: f64) -> Dual {
        Dual { v: self.v * k, d: self.d * k }
    }
}

impl Div for Dual {
    type Output = Dual;
    fn div(self, o: Dual) -> Dual {
        Dual { v: self.v / o.v, d: (self.d * o.v - o.d * self.v) / (o.v * o.v) }
    }
}

/// MaterialX's per-tile hash of a grid vertex (a Dave Hoskins "hash without sine" variant),
/// in `f32` as the shader evaluates it: two values in [0, 1).
pub(crate) fn tile_hash(i: i32, j: i32) -> [f64; 2] {
    let fract = |x: f32| x - x.floor();
    let (px, py) = (i as f32 + 0.12345, j as f32 + 0.12345);
    let (mut x, mut y, mut z) = (fract(px * 0.1031), fract(py * 0.1030), fract(px * 0.0973));
    let d = x * (y + 33.33) + y * (z + 33.33) + z * (x + 33.33);
    x += d;
    y += d;
    z += d;
    [fract((x + y) * z) as f64, fract((x + z) * y) as f64]
}

/// Schlick's gain `x ↦ x/(a + 1)` below ½, `(a − x)/(a − 1)` above, `a = (1/r − 2)(1 − 2x)`,
/// with `r` clamped to [0.001, 0.999].
fn gain(x: Dual, r: f64) -> Dual {
    let r = r.clamp(0.001, 0.999);
    let a = (Dual::constant(1.0) - x * 2.0) * (1.0 / r - 2.0);
    if x.v < 0.5 {
        x / (a + Dual::constant(1.0))
    } else {
        (a - x) / (a - Dual::constant(1.0))
    }
}

/// The three tiles whose blend covers a coordinate: grid vertices and barycentric weights
/// (with their gradients).
pub(super) struct Triangle {
    pub(super) ids: [[i32; 2]; 3],
    pub(super) bary: [Dual; 3],
}

pub(super) fn triangle(c: DVec2) -> Triangle {
    let st = c * GRID;
    let k = DVec2::new(st.x - TAN30 * st.y, TAN30X2 * st.y);
    let base = k.floor();
    let (x, y) = (k.x - base.x, k.y - base.y);
    let z = 1.0 - x - y;
    // Gradients of the fractional parts with respect to c.
    let dx = DVec2::new(GRID, -GRID * TAN30);
    let dy = DVec2::new(0.0, GRID * TAN30X2);
    let (b0, b1) = (base.x as i32, base.y as i32);
    if z <= 0.0 {
        // Upper triangle: vertices (1,1), (1,0), (0,1).
        Triangle {
            ids: [[b0 + 1, b1 + 1], [b0 + 1, b1], [b0, b1 + 1]],
            bary: [Dual::new(-z, dx + dy), Dual::new(1.0 - y, -dy), Dual::new(1.0 - x, -dx)],
        }
    } else {
        // Lower triangle: vertices (0,0), (0,1), (1,0).
        Triangle {
            ids: [[b0, b1], [b0, b1 + 1], [b0 + 1, b1]],
            bary: [Dual::new(z, -dx - dy), Dual::new(y, dy), Dual::new(x, dx)],
        }
    }
}

/// A hex tile's centre in the coordinate `c`.
pub(super) fn centre(id: [i32; 2]) -> DVec2 {
    let (i, j) = (id[0] as f64 / GRID, id[1] as f64 / GRID);
    DVec2::new(i + 0.5 * j, j / TAN30X2)
}

/// The smoothstep in `log ρ` from [`NEAR`] (0) to [`FAR`] (1): the weight of the image's mean.
pub fn mean_weight(rho: f64) -> f64 {
    if rho <= NEAR {
        return 0.0;
    }
    if rho >= FAR {
        return 1.0;
    }
    let t = (rho / NEAR).ln() / (FAR / NEAR).ln();
    t * t * (3.0 - 2.0 * t)
}

/// Scalar inputs read by their filtered means.
pub(super) struct Params {
    pub(super) tiling: DVec2,
    pub(super) rotation: f64,
    pub(super) rotation_range: DVec2,
    pub(super) scale: f64,
    pub(super) scale_range: DVec2,
    pub(super) offset: f64,
    pub(super) offset_range: DVec2,
    pub(super) falloff: f64,
    pub(super) contrast: f64,
    pub(super) luma: [f64; 3],
}

impl Params {
    pub(super) fn read(ins: &[Filtered]) -> Params {
        let f = |i: usize| ins[i].ch[0].mean as f64;
        let v = |i: usize| DVec2::new(ins[i].ch[0].mean as f64, ins[i].ch[1].mean as f64);
        Params {
            tiling: v(2),
            rotation: f(3),
            rotation_range: v(4),
            scale: f(5),
            scale_range: v(6),
            offset: f(7),
            offset_range: v(8),
            falloff: f(9),
            contrast: f(10),
            luma: [0, 1, 2].map(|k| ins[11].ch[k].mean as f64),
        }
    }

    /// Tile `id`'s random rotation `θ` (radians): `mix(rotationrange)(r.x · rotation)`.
    pub(super) fn tile_angle(&self, id: [i32; 2]) -> f64 {
        let r = tile_hash(id[0], id[1]);
        let rr = self.rotation_range * (std::f64::consts::PI / 180.0);
        rr.x + (rr.y - rr.x) * (r[0] * self.rotation)
    }

    /// Tile `id`'s linear map `R(θ)/σ` and its translation: the lookup is `L (c − ctr) + ctr + o`.
    pub(super) fn tile_map(&self, id: [i32; 2]) -> (DMat2, DVec2) {
        let r = tile_hash(id[0], id[1]);
        let theta = self.tile_angle(id);
        let sr = self.scale_range;
        let s = 1.0 + (sr.x + (sr.y - sr.x) * r[1] - 1.0) * self.scale;
        let s = if s.abs() < 1e-6 { 1e-6f64.copysign(s) } else { s };
        let or = self.offset_range;
        let o = DVec2::new(or.x + (or.y - or.x) * r[0] * self.offset, or.x + (or.y - or.x) * r[1] * self.offset);
        let (sn, cs) = theta.sin_cos();
        // Columns of R(θ)/σ: R(θ) d = (cos θ dx − sin θ dy, sin θ dx + cos θ dy).
        let l = DMat2::from_cols(DVec2::new(cs, sn), DVec2::new(-sn, cs)) * (1.0 / s);
        (l, o)
    }
}

impl Params {
    /// How alike two random tiles' lookups of one point are, in [0, 1], for a coordinate spread
    /// `lambda` (largest eigenvalue of its covariance): `exp(−Δ²/(4 σ²))`, the correlation of a
    /// white image blurred to the lookups' spread `σ² = λ E[1/s²]` at the mean square distance
    /// `Δ²` between two tiles' lookup points: `2 |d|² (E[1/s²] − |E[e^{iθ}]|² E[1/s]²)` for the
    /// random rotation and scale about a centre `|d|² = λ + e²/3` away, plus `w²/3` for the
    /// offsets of range width `w`. 1 when every range has zero width (the tiles are one image:
    /// `tiledimage`), 0 when the tiles' scales straddle 0.
    /// The largest tile scale magnitude.
    pub(super) fn max_scale(&self) -> f64 {
        let s = |r: f64| (1.0 + (r - 1.0) * self.scale).abs();
        s(self.scale_range.x).max(s(self.scale_range.y))
    }

    pub(super) fn coherence(&self, lambda: f64) -> f64 {
        let (sa, sb) = (1.0 + (self.scale_range.x - 1.0) * self.scale, 1.0 + (self.scale_range.y - 1.0) * self.scale);
        if sa * sb <= 0.0 {
            return 0.0;
        }
        let (e1, e2) = if (sb - sa).abs() < 1e-9 * sa.abs() {
            (1.0 / sa, 1.0 / (sa * sa))
        } else {
            ((sb / sa).ln() / (sb - sa), 1.0 / (sa * sb))
        };
        let rr = self.rotation_range * (std::f64::consts::PI / 180.0);
        let (ta, tb) = (rr.x, rr.x + (rr.y - rr.x) * self.rotation);
        let (ec, es) = if (tb - ta).abs() < 1e-9 {
            (ta.cos(), ta.sin())
        } else {
            ((tb.sin() - ta.sin()) / (tb - ta), (ta.cos() - tb.cos()) / (tb - ta))
        };
        let wo = (self.offset_range.y - self.offset_range.x) * self.offset;
        let d2 = lambda + 1.0 / (3.0 * GRID * GRID);
        let spread = (2.0 * d2 * (e2 - (ec * ec + es * es) * e1 * e1)).max(0.0) + wo * wo / 3.0;
        if spread <= 1e-18 {
            return 1.0;
        }
        (-spread / (4.0 * lambda * e2).max(1e-300)).exp()
    }
}

/// One tile's filtered lookup, per output channel: value (with its gradient in `c`) and spread.
#[derive(Clone, Copy, Default)]
struct Sample {
    val: [f64; 4],
    grad: [DVec2; 4],
    var: [f64; 4],
}

/// The flip of v, `F(x, y) = (x, 1 − y)`: MaterialX's `mx_transform_uv` with
/// `fileTextureVerticalFlip`, applied before the hex tiling, and again (as the image's own
/// orientation) to every lookup.
pub(super) fn flip(x: DVec2) -> DVec2 {
    DVec2::new(x.x, 1.0 - x.y)
}

/// The hex-tiling coordinate of a node and its footprint.
pub(super) struct Coord {
    /// `c = F(texcoord · tiling)`.
    pub(super) c: DVec2,
    /// Its covariance (`T Σ T` flipped: the covariance of the two channels changes sign).
    pub(super) cov: DMat2,
    /// The largest eigenvalue of `cov`.
    pub(super) lambda: f64,
    /// The footprint's size in triangle edges (0 at points).
    pub(super) rho: f64,
    /// The weight of the far-field surrogate ([`mean_weight`] of `rho`).
    pub(super) alpha: f64,
    /// How alike random tiles' lookups are ([`Params::coherence`]; 0 at points).
    pub(super) kappa: f64,
}

impl Coord {
    pub(super) fn of(p: &Params, tc: &Filtered, ctx: &Ctx) -> Coord {
        let t = p.tiling;
        let c = flip(DVec2::new(tc.ch[0].mean as f64, tc.ch[1].mean as f64) * t);
        // The coordinate's covariance: texcoord's (its channels' spreads and their covariance)
        // scaled by the tiling, the covariance negated by the flip.
        let cuv = if ctx.point { 0.0 } else { -crate::moments::cov(&tc.ch[0], &tc.ch[1], ctx.fp) as f64 };
        let cov = DMat2::from_cols(
            DVec2::new(tc.ch[0].var.max(0.0) as f64 * t.x * t.x, cuv * t.x * t.y),
            DVec2::new(cuv * t.x * t.y, tc.ch[1].var.max(0.0) as f64 * t.y * t.y),
        );
        let (a, b, d) = (cov.x_axis.x, cov.x_axis.y, cov.y_axis.y);
        let lambda = (0.5 * (a + d) + (0.25 * (a - d) * (a - d) + b * b).sqrt()).max(0.0);
        let rho = if ctx.point { 0.0 } else { lambda.sqrt() * GRID };
        let alpha = mean_weight(rho);
        let kappa = if rho > 0.0 { p.coherence(lambda) } else { 0.0 };
        Coord { c, cov, lambda, rho, alpha, kappa }
    }
}

/// `gᵀ C g`.
pub(super) fn quad(c: &DMat2, g: DVec2) -> f64 {
    g.dot(*c * g)
}

pub(crate) fn eval(h: &HexTile, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    if h.normal_map {
        return super::hextile_normal::eval(h, ins, ctx);
    }
    let n = ty.channels();
    let p = Params::read(ins);
    let tc = &ins[1];
    let t = p.tiling;
    let Coord { c, cov, lambda, rho, alpha, kappa } = Coord::of(&p, tc, ctx);
    let fc = h.tex.file_channels();
    let (gm, gsq) = h.tex.global_moments();
    // The image's mean and global variance per output channel.
    let global = |k: usize| {
        let m = image::channel(&gm, fc, k);
        (m, (image::channel(&gsq, fc, k) - m * m).max(0.0))
    };

    let mut out = Filtered::zero(ty);
    if alpha >= 1.0 && (kappa < 1e-4 || lambda >= (BLURRED * p.max_scale()).powi(2)) {
        // Much larger than a tile, and the tiles' lookups unrelated or each blurred to the
        // image's mean: the image's mean.
        ctx.work.lattice += 1;
        for k in 0..n {
            let (m, v) = global(k);
            out.ch[k] = Moments { mean: m as f32, grad: Vec2::ZERO, var: v as f32 };
        }
        return out;
    }

    // The three tiles' lookups.
    let tri = triangle(c);
    let size = h.tex.size();
    let mut samples = [Sample::default(); 3];
    for (s, id) in samples.iter_mut().zip(tri.ids) {
        let ctr = centre(id);
        let (l, o) = p.tile_map(id);
        let at = flip(l * (c - ctr) + ctr + o);
        let ck = l * cov * l.transpose();
        let sigma = DVec2::new(ck.x_axis.x.max(0.0).sqrt(), ck.y_axis.y.max(0.0).sqrt());
        let [v, sq, du, dv] = image::filtered_rgba(&h.tex, at, sigma, ctx.point);
        let coverage = (sigma.x * size.0 as f64).max(sigma.y * size.1 as f64).powi(2).min(1.0);
        ctx.work.lattice += 4;
        for k in 0..n {
            let val = image::channel(&v, fc, k);
            // ∂/∂c = Lᵀ F ∂/∂(lookup uv), F the flip of v.
            let g = l.transpose() * DVec2::new(image::channel(&du, fc, k), -image::channel(&dv, fc, k));
            s.val[k] = val;
            s.grad[k] = g;
            // Spread over the footprint: the linear part, and, as the footprint grows past a
            // texel, the texels' own spread (the mean square's excess), which a sub-texel
            // footprint of the smooth bilinear reconstruction does not see.
            let lin = quad(&cov, g);
            let texels = (image::channel(&sq, fc, k) - val * val - lin).max(0.0);
            s.var[k] = if ctx.point { 0.0 } else { lin + texels * coverage };
        }
    }
    // Luminance factors: the three tiles', and that of the other tiles (their surrogate).
    let luma_factor = |val: &[f64; 4], grad: &[DVec2; 4]| {
        let mut lum = Dual::constant(0.0);
        for i in 0..3 {
            lum = lum + Dual::new(val[i], grad[i]) * p.luma[i];
        }
        Dual::constant(1.0) + (lum - Dual::constant(1.0)) * p.contrast
    };
    let cw = samples.each_ref().map(|s| luma_factor(&s.val, &s.grad));
    let (mut sur_val, mut sur_grad) = ([0.0; 4], [DVec2::ZERO; 4]);
    for k in 0..n {
        let (gmean, _) = global(k);
        let avg: f64 = samples.iter().map(|s| s.val[k]).sum::<f64>() / 3.0;
        sur_val[k] = gmean + (avg - gmean) * kappa;
        sur_grad[k] = samples.iter().map(|s| s.grad[k]).sum::<DVec2>() * (kappa / 3.0);
    }
    let cw_far = luma_factor(&sur_val, &sur_grad);
    let mut m = Masses::default();
    // Alpha blends with luminance factor 1 (its own weights, `aw`).
    let mut ma = Masses::default();
    for_footprint_nodes(c, &cov, rho, |x, wt| {
        let at = triangle(x);
        let slot = at.ids.map(|id| tri.ids.iter().position(|t| *t == id));
        // The lookups vary over the footprint by their gradients: their luminance factors
        // at the node, and (below) the first moments of each tile's weight.
        let dx = x - c;
        let factors = [0, 1, 2].map(|v| {
            let f = slot[v].map_or(cw_far, |k| cw[k]);
            Dual::new(f.v + f.d.dot(dx), f.d)
        });
        for (v, wv) in blend(&p, at.bary, factors).into_iter().enumerate() {
            match slot[v] {
                Some(k) => {
                    m.w[k] = m.w[k] + wv * wt;
                    m.wx[k] += dx * (wv.v * wt);
                }
                None => {
                    m.far = m.far + wv * wt;
                    m.wx_far += dx * (wv.v * wt);
                }
            }
        }
        if n == 4 {
            for (v, wv) in blend(&p, at.bary, [Dual::constant(1.0); 3]).into_iter().enumerate() {
                match slot[v] {
                    Some(k) => {
                        ma.w[k] = ma.w[k] + wv * wt;
                        ma.wx[k] += dx * (wv.v * wt);
                    }
                    None => {
                        ma.far = ma.far + wv * wt;
                        ma.wx_far += dx * (wv.v * wt);
                    }
                }
            }
        }
    });

    for k in 0..n {
        let avg_sd: f64 = samples.iter().map(|s| s.var[k].sqrt()).sum::<f64>() / 3.0;
        // The tiles beyond the centre's three: like the three as far as the tiles' maps agree,
        // else the image's mean.
        let sur = Dual::new(sur_val[k], sur_grad[k]);
        let (val, grad, var);
        {
            // Colour by the luminance-weighted blend, alpha by its own (MaterialX 1.39.5's `aw`).
            let m = if k < 3 { &m } else { &ma };
            let gvar = global(k).1;
            let sur_var = kappa * avg_sd * avg_sd + (1.0 - kappa) * gvar;
            // The three tiles' and the others' weight masses over the footprint.
            // E[w c] with c linear over the footprint: W c̄ + E[w (x − c)]·∇c̄.
            let (mut vc, mut gc) = (m.far.v * sur.v + m.wx_far.dot(sur.d), m.far.d * sur.v + sur.d * m.far.v);
            let (mut lin, mut sd) = (m.far.d * sur.v, m.far.v.abs() * sur_var.sqrt());
            for ((wk, wx), s) in m.w.iter().zip(&m.wx).zip(&samples) {
                vc += wk.v * s.val[k] + wx.dot(s.grad[k]);
                gc += wk.d * s.val[k] + s.grad[k] * wk.v;
                lin += wk.d * s.val[k];
                sd += wk.v.abs() * s.var[k].sqrt();
            }
            // The blend is a convex combination of the tiles' values: its variation through
            // the weights alone stays within a quarter of their range squared (the linearised
            // weights' derivatives grow without bound where the luminance factors' sum nears 0).
            let (lo, hi) = samples.iter().fold((sur.v, sur.v), |(a, b), s| (a.min(s.val[k]), b.max(s.val[k])));
            let weights_var = 0.25 * (hi - lo) * (hi - lo);
            let bound = (sd + weights_var.sqrt()).powi(2);
            let var_c = (sd * sd + quad(&cov, lin).min(weights_var)).max(quad(&cov, gc).min(bound));
            val = vc + (sur.v - vc) * alpha;
            grad = gc * (1.0 - alpha) + sur.d * alpha;
            var = var_c + (sur_var - var_c) * alpha;
        }
        // Back to uv: c = (u tₓ, 1 − v t_y).
        let g_uv = tc.ch[0].grad * (grad.x * t.x) as f32 - tc.ch[1].grad * (grad.y * t.y) as f32;
        out.ch[k] = Moments { mean: val as f32, grad: g_uv, var: if ctx.point { 0.0 } else { var.max(0.0) as f32 } };
    }
    out
}

/// MaterialX's blend weights of three tiles with barycentric weights `bary` and luminance
/// factors `cw`: `cw b⁷` normalised, then the gain, normalised (with their gradients). Where
/// `cw b⁷` sums to 0 the luminance factors are dropped.
pub(super) fn blend(p: &Params, bary: [Dual; 3], cw: [Dual; 3]) -> [Dual; 3] {
    let mut w = [0, 1, 2].map(|k| cw[k] * bary[k].pow7());
    if !normalise(&mut w) {
        w = bary.map(Dual::pow7);
        normalise(&mut w);
    }
    if p.falloff != 0.5 {
        let mut gained = w.map(|x| gain(x, p.falloff));
        if normalise(&mut gained) {
            w = gained;
        }
    }
    w
}

/// Footprint size `ρ` below which the blend weights at the centre are used.
const CENTRE_ONLY: f64 = 5e-3;

/// What the blend gives each tile over the footprint: the weight masses of the centre
/// triangle's three tiles and of all others, and their first moments.
#[derive(Default)]
struct Masses {
    w: [Dual; 3],
    far: Dual,
    /// First moments `E[w (x − c)]`.
    wx: [DVec2; 3],
    wx_far: DVec2,
}

/// Calls `f(x, weight)` for the nodes of a cubature over the footprint `N(c, cov)`: 5 × 5
/// Gauss–Hermite along a factor of `cov`, or the centre alone while the footprint is small
/// against a tile (`ρ` below [`CENTRE_ONLY`]). The blend weights are evaluated there, never the
/// image.
pub(super) fn for_footprint_nodes(c: DVec2, cov: &DMat2, rho: f64, mut f: impl FnMut(DVec2, f64)) {
    if rho < CENTRE_ONLY {
        return f(c, 1.0);
    }
    let l = factor(cov);
    for (z1, a1) in crate::gaussian::HERMITE5 {
        for (z2, a2) in crate::gaussian::HERMITE5 {
            f(c + l * DVec2::new(z1, z2), a1 * a2);
        }
    }
}

/// A factor `L` of a covariance, `L Lᵀ = C` (Cholesky; degenerate covariances allowed).
pub(super) fn factor(c: &DMat2) -> DMat2 {
    let (a, b, d) = (c.x_axis.x.max(0.0), c.x_axis.y, c.y_axis.y.max(0.0));
    if a <= 1e-300 {
        return DMat2::from_cols(DVec2::ZERO, DVec2::new(0.0, d.sqrt()));
    }
    let l11 = a.sqrt();
    let l21 = b / l11;
    DMat2::from_cols(DVec2::new(l11, l21), DVec2::new(0.0, (d - l21 * l21).max(0.0).sqrt()))
}

/// Divides the weights by their sum; false (and unchanged) when the sum is not a usable
/// divisor.
fn normalise(w: &mut [Dual; 3]) -> bool {
    let s = w[0] + w[1] + w[2];
    if s.v.abs() <= 1e-30 || !s.v.is_finite() {
        return false;
    }
    *w = w.map(|x| x / s);
    true
}
