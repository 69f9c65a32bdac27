//! Image lookups: `image`, `tiledimage`, `latlongimage`, `triplanarprojection`.
//!
//! | node | inputs (default) | unfiltered (MaterialX 1.39) | filtered evaluation |
//! |---|---|---|---|
//! | `image` | `file`, `layer`, `default` (0), `texcoord` (UV0), `uaddressmode` / `vaddressmode` (periodic), `filtertype`, `framerange`, `frameoffset` (0), `frameendaction` | bilinear lookup of the file at `texcoord`, `v = 0` the bottom row of the file; `constant` address mode: `default` outside [0, 1]; `clamp`, `periodic`, `mirror` wrap as GL does (clamp is exact only while the footprint stays within a few texels of the image: coarse levels clamp to their own edge texels); a missing channel reads 0 (alpha 1), a grey file fills r, g, b | up to σ = 1 texel (major axis): the exact Gaussian average of the bilinear reconstruction (separable: each texel's tent integrated in closed form, ±4σ); beyond, a mip pyramid (box levels halving each axis, exact fractional boxes for odd sizes, built at load): the same exact average at levels ⌊lod⌋ and ⌊lod⌋+1, lod = log2 σ (σ = 1–2 texels there), less the 1/4 texel² a level's box and tent already spread, blended linearly in lod; gradient exact (the tents' derivatives); variance `max(gᵀΣg, E[x²] − E[x]²)` from a pyramid of squares; the constant mode's `default` blended by the footprint's mass outside [0, 1] (Φ per axis) |
//! | `tiledimage` | `file`, `default` (0), `texcoord` (UV0), `uvtiling` (1,1), `uvoffset` (0,0), `realworldimagesize` (1,1), `realworldtilesize` (1,1), `filtertype`, `framerange`, `frameoffset` (0), `frameendaction` | `image` (periodic) at `(t·uvtiling − uvoffset) / realworldimagesize · realworldtilesize` | the coordinate exactly (affine), then as `image` |
//! | `latlongimage` (color3) | `file`, `default` (0), `viewdir` (0, 0, 1), `rotation` (0°) | `image` (u periodic, v mirror) at longitude `0.5 − atan2(d.x, d.z)/2π + rotation/360` and latitude `0.5 + asin(d.y)/π` (MaterialX's `NG_latlongimage`) | the coordinate by cubature over `viewdir` and `rotation`, the longitude unwrapped around the mean direction's (a footprint across the seam is not averaged around the circle), then as `image` |
//! | `triplanarprojection` | `filex`, `filey`, `filez`, `default` (0), `position` (P), `normal` (N), `upaxis` (2), `blend` (1), … | three periodic `image`s at `(y, z)`, `(x, z)`, `(x, y)` of `position` (for `upaxis` 2; 1: `(z, y)`, `(x, z)`, `(x, y)`; 0: `(z, y)`, `(z, x)`, `(−y, x)`), weighted by `w = |n|/Σ|n|` of the normalised normal raised to `1/clamp(blend, 0.03, 1)` and renormalised (MaterialX's graph); an axis whose file is empty reads `default` | each lookup at the position's own footprint (exact coordinates), the weights by cubature over the normal and `blend`, their products by Gaussian product moments |
//!
//! Files: PNG (8 or 16 bit) and OpenEXR through the `image` crate. `colorspace="srgb_texture"`
//! (on the input or inherited from an enclosing element) is converted to linear at load, before
//! the pyramid is built, so that filtering averages linear values. Pyramids are shared between
//! nodes that read the same file in the same colour space.

use super::{inp, types, Ctx, Def, InType, NodeDef, Op, Param};
use crate::gaussian::{cdf, mass, poly, poly_expectation};
use crate::graph::Source;
use crate::value::{Filtered, Moments, ValueType};
use glam::{DVec2, Vec2};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock, Weak};

pub(crate) const CATEGORIES: &[&str] = &["image", "tiledimage", "latlongimage", "triplanarprojection"];

/// The three lookups of a `triplanarprojection` (x, y, z), `None` for an empty file name.
pub type Triplanar = [Option<Arc<Texture>>; 3];

/// How a texture coordinate outside [0, 1] is mapped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Address {
    /// The node's `default` value.
    Constant,
    /// The edge texel.
    Clamp,
    /// Repeat.
    Periodic,
    /// Repeat, every other copy mirrored.
    Mirror,
}

impl Address {
    fn parse(s: &str) -> Result<Address, String> {
        Ok(match s {
            "" | "periodic" => Address::Periodic,
            "constant" => Address::Constant,
            "clamp" => Address::Clamp,
            "mirror" => Address::Mirror,
            _ => return Err(format!("unknown address mode `{s}`")),
        })
    }

    /// Maps integer texel `i` of a row of `n` texels into range (`None`: outside, constant).
    #[inline]
    fn texel(self, i: i64, n: i64) -> Option<usize> {
        Some(match self {
            Address::Constant | Address::Clamp => i.clamp(0, n - 1) as usize,
            Address::Periodic => i.rem_euclid(n) as usize,
            Address::Mirror => {
                let k = i.rem_euclid(2 * n);
                (if k < n { k } else { 2 * n - 1 - k }) as usize
            }
        })
    }
}

/// One mip level: RGBA texels, row 0 at `v = 0` (the bottom of the file).
#[derive(Debug)]
struct Level {
    w: usize,
    h: usize,
    px: Vec<[f32; 4]>,
    sq: Vec<[f32; 4]>,
}

/// A decoded image and its mip pyramid.
#[derive(Debug)]
pub struct Pyramid {
    levels: Vec<Level>,
    /// Channels in the file (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA).
    channels: usize,
}

/// A texture as an `image` node reads it: the shared pyramid and the address modes.
#[derive(Debug)]
pub struct Texture {
    pyramid: Arc<Pyramid>,
    u: Address,
    v: Address,
    tiled: bool,
}

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Box weights of the source texels covering target texel `t` when `n` texels shrink to `m`:
/// the exact overlaps of `[t·n/m, (t+1)·n/m)` (mean-preserving for odd sizes too).
fn box_weights(t: usize, n: usize, m: usize) -> Vec<(usize, f32)> {
    let r = n as f64 / m as f64;
    let (lo, hi) = (t as f64 * r, (t + 1) as f64 * r);
    let mut w = Vec::new();
    let mut i = lo.floor() as usize;
    while (i as f64) < hi && i < n {
        let ov = (hi.min(i as f64 + 1.0) - lo.max(i as f64)).max(0.0);
        if ov > 0.0 {
            w.push((i, (ov / r) as f32));
        }
        i += 1;
    }
    w
}

fn downsample(l: &Level) -> Level {
    let (w, h) = ((l.w / 2).max(1), (l.h / 2).max(1));
    let mut px = vec![[0.0f32; 4]; w * h];
    let mut sq = vec![[0.0f32; 4]; w * h];
    let wx: Vec<_> = (0..w).map(|x| box_weights(x, l.w, w)).collect();
    let wy: Vec<_> = (0..h).map(|y| box_weights(y, l.h, h)).collect();
    for y in 0..h {
        for x in 0..w {
            let (mut a, mut b) = ([0.0f32; 4], [0.0f32; 4]);
            for &(sy, ky) in &wy[y] {
                for &(sx, kx) in &wx[x] {
                    let i = sy * l.w + sx;
                    let k = kx * ky;
                    for c in 0..4 {
                        a[c] += k * l.px[i][c];
                        b[c] += k * l.sq[i][c];
                    }
                }
            }
            px[y * w + x] = a;
            sq[y * w + x] = b;
        }
    }
    Level { w, h, px, sq }
}

fn load(path: &Path, srgb: bool) -> Result<Pyramid, String> {
    let img = ::image::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let channels = img.color().channel_count() as usize;
    let rgba = img.to_rgba32f();
    let (w, h) = (rgba.width() as usize, rgba.height() as usize);
    if w == 0 || h == 0 {
        return Err(format!("{}: empty image", path.display()));
    }
    let mut px = vec![[0.0f32; 4]; w * h];
    for (x, y, p) in rgba.enumerate_pixels() {
        let mut c = p.0;
        if srgb {
            for v in c.iter_mut().take(3) {
                *v = srgb_to_linear(*v);
            }
        }
        // Row 0 of the file is the top: store it at the end (v = 1).
        px[(h - 1 - y as usize) * w + x as usize] = c;
    }
    let sq = px.iter().map(|c| c.map(|v| v * v)).collect();
    let mut levels = vec![Level { w, h, px, sq }];
    while levels.last().is_some_and(|l| l.w > 1 || l.h > 1) {
        let next = downsample(levels.last().unwrap());
        levels.push(next);
    }
    Ok(Pyramid { levels, channels })
}

/// Loads (or reuses) the pyramid of `path` in colour space `srgb`.
fn pyramid(path: &Path, srgb: bool) -> Result<Arc<Pyramid>, String> {
    type Cache = Mutex<HashMap<(PathBuf, bool), Weak<Pyramid>>>;
    static CACHE: OnceLock<Cache> = OnceLock::new();
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    let key = (path.to_path_buf(), srgb);
    if let Some(p) = cache.lock().unwrap().get(&key).and_then(|w| w.upgrade()) {
        return Ok(p);
    }
    let p = Arc::new(load(path, srgb)?);
    cache.lock().unwrap().insert(key, Arc::downgrade(&p));
    Ok(p)
}

impl Texture {
    /// The file at `path` (sRGB-decoded if `srgb`), read periodically along u and v: the
    /// lookups of `hextiledimage` (the pyramid is shared with other nodes reading it).
    pub(crate) fn periodic(path: &Path, srgb: bool) -> Result<Texture, String> {
        Ok(Texture { pyramid: pyramid(path, srgb)?, u: Address::Periodic, v: Address::Periodic, tiled: false })
    }

    /// Channels in the file (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA): the argument of
    /// [`channel`].
    pub(crate) fn file_channels(&self) -> usize {
        self.pyramid.channels
    }

    /// Width and height of the file, in texels.
    pub(crate) fn size(&self) -> (usize, usize) {
        (self.pyramid.levels[0].w, self.pyramid.levels[0].h)
    }

    /// Mean and mean square of each RGBA channel over the whole image (its 1 × 1 level: the
    /// box levels preserve both exactly).
    pub(crate) fn global_moments(&self) -> ([f64; 4], [f64; 4]) {
        let top = self.pyramid.levels.last().expect("a pyramid has a level");
        (top.px[0].map(|x| x as f64), top.sq[0].map(|x| x as f64))
    }
}

pub(crate) fn definition(category: &str) -> Option<NodeDef> {
    use Def::*;
    use InType::*;
    let mut types: fn(ValueType) -> bool = types::float_or_vector;
    let (inputs, params): (&'static [_], &'static [&'static str]) = match category {
        "image" => (
            &[inp!("default", Out, Zero), inp!("texcoord", V2, Uv), inp!("frameoffset", Int, Zero)],
            &["file", "layer", "uaddressmode", "vaddressmode", "filtertype", "framerange", "frameendaction"],
        ),
        "latlongimage" => {
            types = types::color3;
            (
                &[
                    inp!("default", Out, Zero),
                    inp!("viewdir", V3, Triple(0.0, 0.0, 1.0)),
                    inp!("rotation", Float, Zero),
                ],
                &["file"],
            )
        }
        "triplanarprojection" => (
            &[
                inp!("default", Out, Zero),
                inp!("position", V3, Geom(crate::graph::GeomProp::Position)),
                inp!("normal", V3, Geom(crate::graph::GeomProp::Normal)),
                inp!("upaxis", Int, Splat(2.0)),
                inp!("blend", Float, One),
                inp!("frameoffset", Int, Zero),
            ],
            &["filex", "filey", "filez", "layerx", "layery", "layerz", "filtertype", "framerange", "frameendaction"],
        ),
        "tiledimage" => (
            &[
                inp!("default", Out, Zero),
                inp!("texcoord", V2, Uv),
                inp!("frameoffset", Int, Zero),
                inp!("uvtiling", V2, Pair(1.0, 1.0)),
                inp!("uvoffset", V2, Zero),
                inp!("realworldimagesize", V2, Pair(1.0, 1.0)),
                inp!("realworldtilesize", V2, Pair(1.0, 1.0)),
            ],
            &["file", "filtertype", "framerange", "frameendaction"],
        ),
        _ => return None,
    };
    let category = CATEGORIES.iter().copied().find(|c| *c == category)?;
    Some(NodeDef { category, inputs, params, types, build })
}

/// The file of parameter `name`, with whether it is sRGB-encoded (`None`: no such parameter).
fn file_param<'p>(params: &'p [Param], name: &str) -> Option<(&'p Path, bool)> {
    params.iter().find_map(|p| match p {
        Param::File { name: n, path, colorspace } if n == name => Some((path.as_path(), colorspace == "srgb_texture")),
        _ => None,
    })
}

fn build(category: &str, _: ValueType, _: &[ValueType], _: &[Source], params: &[Param]) -> Result<Op, String> {
    let texture = |path: &Path, srgb: bool, u: Address, v: Address| -> Result<Arc<Texture>, String> {
        Ok(Arc::new(Texture { pyramid: pyramid(path, srgb)?, u, v, tiled: false }))
    };
    if category == "latlongimage" {
        return match file_param(params, "file") {
            Some((p, srgb)) if !p.as_os_str().is_empty() => {
                Ok(Op::LatLong(texture(p, srgb, Address::Periodic, Address::Mirror)?))
            }
            _ => Ok(Op::Default("its `file` is empty: it gives its `default`".into())),
        };
    }
    if category == "triplanarprojection" {
        let mut axes: Triplanar = [None, None, None];
        for (axis, name) in axes.iter_mut().zip(["filex", "filey", "filez"]) {
            if let Some((p, srgb)) = file_param(params, name).filter(|(p, _)| !p.as_os_str().is_empty()) {
                *axis = Some(texture(p, srgb, Address::Periodic, Address::Periodic)?);
            }
        }
        if axes.iter().all(Option::is_none) {
            return Ok(Op::Default("its files are empty: it gives its `default`".into()));
        }
        return Ok(Op::Triplanar(Arc::new(axes)));
    }
    let mut file = None;
    let (mut u, mut v) = (Address::Periodic, Address::Periodic);
    for p in params {
        match p {
            Param::File { name, path, colorspace } if name == "file" => {
                file = Some((path.clone(), colorspace == "srgb_texture"));
            }
            Param::Str { name, value } if name == "uaddressmode" => u = Address::parse(value)?,
            Param::Str { name, value } if name == "vaddressmode" => v = Address::parse(value)?,
            _ => {}
        }
    }
    let Some((path, srgb)) = file else {
        return Err("no image file".into());
    };
    if path.as_os_str().is_empty() {
        return Ok(Op::Default("its `file` is empty: it gives its `default`".into()));
    }
    let tiled = category == "tiledimage";
    if tiled {
        (u, v) = (Address::Periodic, Address::Periodic);
    }
    Ok(Op::Image(Arc::new(Texture { pyramid: pyramid(&path, srgb)?, u, v, tiled })))
}

/// `(texel, weight, d weight / dm)` along one axis.
type Weights = Vec<(usize, f64, f64)>;

/// Per-axis texel weights of the bilinear (tent) reconstruction averaged over `N(m, s²)`
/// (texel units, centres at `i + ½`): `(texel, weight, d weight / dm)`, the texel already
/// mapped by the address mode. `s = 0` gives the bilinear weights.
fn axis_weights(m: f64, s: f64, n: usize, mode: Address, out: &mut Weights) {
    out.clear();
    let n = n as i64;
    let map = |i: i64| mode.texel(i, n).unwrap_or(0);
    if s < 1e-6 {
        let f = m - 0.5;
        let i0 = f.floor();
        let a = f - i0;
        out.push((map(i0 as i64), 1.0 - a, -1.0));
        out.push((map(i0 as i64 + 1), a, 1.0));
        return;
    }
    let lo = (m - 0.5 - 4.0 * s - 1.0).floor() as i64;
    let hi = (m - 0.5 + 4.0 * s + 1.0).ceil() as i64;
    let mut total = 0.0;
    for i in lo..=hi {
        let c = i as f64 + 0.5;
        let left = poly_expectation(&poly(&[1.0 - c, 1.0]), c - 1.0, c, m, s);
        let right = poly_expectation(&poly(&[1.0 + c, -1.0]), c, c + 1.0, m, s);
        let (z0, z1, z2) = ((c - 1.0 - m) / s, (c - m) / s, (c + 1.0 - m) / s);
        let dw = mass(z0, z1) - mass(z1, z2);
        let w = left + right;
        total += w;
        out.push((map(i), w, dw));
    }
    // The tents sum to 1; renormalise the ±4σ truncation.
    if total > 0.0 {
        for e in out.iter_mut() {
            e.1 /= total;
        }
    }
}

/// The Gaussian average over `N(m, diag(s²))` (uv units) of level `l`'s bilinear
/// reconstruction: value, mean square, and d/du, d/dv, per channel.
fn filtered_level(t: &Texture, l: &Level, m: DVec2, s: DVec2) -> [[f64; 4]; 4] {
    thread_local! {
        static BUF: std::cell::RefCell<(Weights, Weights)> = const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
    }
    BUF.with(|b| {
        let (xs, ys) = &mut *b.borrow_mut();
        axis_weights(m.x * l.w as f64, s.x * l.w as f64, l.w, t.u, xs);
        axis_weights(m.y * l.h as f64, s.y * l.h as f64, l.h, t.v, ys);
        let mut r = [[0.0f64; 4]; 4];
        for &(j, wy, dwy) in ys.iter() {
            for &(i, wx, dwx) in xs.iter() {
                let k = j * l.w + i;
                let (p, q) = (l.px[k], l.sq[k]);
                for c in 0..4 {
                    let v = p[c] as f64;
                    r[0][c] += wx * wy * v;
                    r[1][c] += wx * wy * q[c] as f64;
                    r[2][c] += dwx * wy * v * l.w as f64;
                    r[3][c] += wx * dwy * v * l.h as f64;
                }
            }
        }
        r
    })
}

/// Maps file channels to output channel `k` of an `n`-channel output.
pub(crate) fn channel(p: &[f64; 4], file_channels: usize, k: usize) -> f64 {
    match file_channels {
        1 => {
            if k < 3 {
                p[0]
            } else {
                1.0
            }
        }
        2 => {
            if k < 3 {
                p[0]
            } else {
                p[3]
            }
        }
        _ => p[k],
    }
}

/// The Gaussian average over `N(m, diag(s²))` (image uv, `v = 0` the bottom row) of the
/// file's bilinear reconstruction, per file channel (RGBA): `[value, mean square, ∂/∂u, ∂/∂v]`.
/// Up to 1 texel (major axis) it is taken exactly at level 0. Beyond, at levels L and L + 1
/// around lod = log2(σ), where σ is 1–2 texels, less the spread a level's own box and tent
/// already add (1/4 texel²), blended linearly in lod. `point`: the bilinear lookup.
pub(crate) fn filtered_rgba(t: &Texture, m: DVec2, s: DVec2, point: bool) -> [[f64; 4]; 4] {
    let pyr = &t.pyramid;
    let l0 = &pyr.levels[0];
    let sigma_texels = (s.x * l0.w as f64).max(s.y * l0.h as f64);
    let top = (pyr.levels.len() - 1) as f64;
    let lod = if point || sigma_texels <= 1.0 { 0.0 } else { sigma_texels.log2().min(top) };
    let (la, frac) = (lod.floor() as usize, lod - lod.floor());
    let lb = (la + 1).min(pyr.levels.len() - 1);
    let at = |l: usize| {
        let lv = &pyr.levels[l];
        let sl = if l == 0 {
            s
        } else {
            // Spread left to apply, in level-l texels, mapped back to uv.
            let k = DVec2::new(lv.w as f64, lv.h as f64);
            let st = s * k;
            DVec2::new((st.x * st.x - 0.25).max(0.0).sqrt(), (st.y * st.y - 0.25).max(0.0).sqrt()) / k
        };
        filtered_level(t, lv, m, sl)
    };
    let ra = at(la);
    if frac > 0.0 && lb != la {
        let rb = at(lb);
        std::array::from_fn(|q| std::array::from_fn(|c| ra[q][c] + (rb[q][c] - ra[q][c]) * frac))
    } else {
        ra
    }
}

pub(crate) fn eval(t: &Texture, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    // The lookup coordinate (tiledimage: an affine map of texcoord, exact).
    let (mut scale, mut offset) = (DVec2::ONE, DVec2::ZERO);
    if t.tiled {
        let g = |f: &Filtered| DVec2::new(f.ch[0].mean as f64, f.ch[1].mean as f64);
        let (tiling, off, img, tile) = (g(&ins[3]), g(&ins[4]), g(&ins[5]), g(&ins[6]));
        scale = tiling / img * tile;
        offset = off / img * tile;
    }
    lookup(t, ty, &ins[0], &ins[1], scale, offset, ctx)
}

/// `latlongimage`: the lookup at the direction's longitude and latitude.
pub(crate) fn eval_latlong(t: &Texture, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    use std::f64::consts::{FRAC_1_PI, TAU};
    let d = &ins[1];
    let xs = [d.ch[0], d.ch[1], d.ch[2], ins[2].ch[0]];
    // The longitude is unwrapped around the mean direction's, so that the cubature's points on
    // both sides of the seam stay neighbours (the image is periodic in u).
    let a0 = (d.ch[0].mean as f64).atan2(d.ch[2].mean as f64);
    let lon = move |p: &[f64]| {
        let da = p[0].atan2(p[2]) - a0;
        (a0 + da - TAU * (da / TAU).round()) * -0.5 * FRAC_1_PI + 0.5 + p[3] / 360.0
    };
    let lat = |p: &[f64]| p[1].clamp(-1.0, 1.0).asin() * FRAC_1_PI + 0.5;
    let mut tc = Filtered::zero(ValueType::Vector2);
    tc.ch[0] = crate::moments::nary(&xs, lon);
    tc.ch[1] = crate::moments::nary(&xs, lat);
    lookup(t, ty, &ins[0], &tc, DVec2::ONE, DVec2::ZERO, ctx)
}

/// Weight `i` of `triplanarprojection` from `(normal, blend)`, as MaterialX's graph computes it.
fn triplanar_weight(q: &[f64], i: usize) -> f64 {
    use crate::moments::safe_div;
    let n = glam::DVec3::new(q[0], q[1], q[2]).normalize_or_zero().abs();
    let w = [n.x, n.y, n.z].map(|a| safe_div(a, n.x + n.y + n.z));
    let e = 1.0 / q[3].clamp(0.03, 1.0);
    let p = w.map(|x| super::math::power_point(x, e, false));
    safe_div(p[i], p[0] + p[1] + p[2])
}

/// `triplanarprojection`: three lookups at the position's planar coordinates, blended by the
/// normal.
pub(crate) fn eval_triplanar(axes: &Triplanar, ty: ValueType, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let (default, p, nrm) = (&ins[0], &ins[1], &ins[2]);
    let pair = |a: Moments, b: Moments| Filtered {
        ty: ValueType::Vector2,
        ch: [a, b, Moments::default(), Moments::default()],
    };
    let (x, y, z) = (p.ch[0], p.ch[1], p.ch[2]);
    let up = ins[3].ch[0].mean;
    let coords = if up < 1.0 {
        [pair(z, y), pair(z, x), pair(crate::moments::affine(y, -1.0, 0.0), x)]
    } else if up < 2.0 {
        [pair(z, y), pair(x, z), pair(x, y)]
    } else {
        [pair(y, z), pair(x, z), pair(x, y)]
    };
    let xs = [nrm.ch[0], nrm.ch[1], nrm.ch[2], ins[4].ch[0]];
    let mut out = Filtered::zero(ty);
    for (i, (axis, tc)) in axes.iter().zip(&coords).enumerate() {
        let w = crate::moments::nary(&xs, |q| triplanar_weight(q, i));
        let img = match axis {
            Some(t) => lookup(t, ty, default, tc, DVec2::ONE, DVec2::ZERO, ctx),
            None => *default,
        };
        for k in 0..ty.channels() {
            let term = crate::moments::mul(img.at(k), w, ctx.fp);
            out.ch[k] = crate::moments::add_scaled(out.ch[k], term, 1.0, ctx.fp);
        }
    }
    out
}

/// The filtered lookup of `t` at `tc · scale − offset`, with `default` where the constant
/// address mode leaves the image.
fn lookup(
    t: &Texture,
    ty: ValueType,
    default: &Filtered,
    tc: &Filtered,
    scale: DVec2,
    offset: DVec2,
    ctx: &mut Ctx,
) -> Filtered {
    let n = ty.channels();
    let m = DVec2::new(tc.ch[0].mean as f64, tc.ch[1].mean as f64) * scale - offset;
    let s = DVec2::new(tc.ch[0].sigma() as f64, tc.ch[1].sigma() as f64) * scale.abs();
    let j = [tc.ch[0].grad * scale.x as f32, tc.ch[1].grad * scale.y as f32];
    let pyr = &t.pyramid;
    let [v, sq, dx, dy] = filtered_rgba(t, m, s, ctx.point);
    ctx.work.lattice += 4;
    // Constant address mode: the footprint's mass inside [0, 1] per constant axis.
    let inside = |mode: Address, m: f64, s: f64| -> (f64, f64) {
        if mode != Address::Constant {
            return (1.0, 0.0);
        }
        if s <= 0.0 {
            return (if (0.0..=1.0).contains(&m) { 1.0 } else { 0.0 }, 0.0);
        }
        let (a, b) = (-m / s, (1.0 - m) / s);
        let p = cdf(b) - cdf(a);
        (p, (crate::gaussian::pdf(a) - crate::gaussian::pdf(b)) / s)
    };
    let (pu, dpu) = inside(t.u, m.x, s.x);
    let (pv, dpv) = inside(t.v, m.y, s.y);
    let w_in = pu * pv;
    let mut out = Filtered::zero(ty);
    for k in 0..n {
        let val = channel(&v, pyr.channels, k);
        let gx = channel(&dx, pyr.channels, k);
        let gy = channel(&dy, pyr.channels, k);
        let gl = j[0] * gx as f32 + j[1] * gy as f32;
        let var_lin = (gx * s.x).powi(2) + (gy * s.y).powi(2);
        let var_pyr = channel(&sq, pyr.channels, k) - val * val;
        let img = Moments { mean: val as f32, grad: gl, var: var_lin.max(var_pyr).max(0.0) as f32 };
        out.ch[k] = if w_in >= 1.0 {
            img
        } else {
            let d = default.at(k);
            let wgrad = j[0] * (dpu * pv) as f32 + j[1] * (pu * dpv) as f32;
            let w = Moments { mean: w_in as f32, grad: wgrad, var: (w_in * (1.0 - w_in)) as f32 };
            crate::moments::mix(d, img, w, ctx.fp)
        };
    }
    if ctx.point {
        for c in out.ch.iter_mut() {
            c.grad = Vec2::ZERO;
            c.var = 0.0;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use crate::{Document, EvalScratch, Footprint, LoadOptions};
    use glam::Vec2;

    /// 16-bit PNG and EXR files load, and `v = 0` is the bottom row of the file.
    #[test]
    fn formats_and_orientation() {
        let dir = std::env::temp_dir().join(format!("graph-image-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // File rows (top first): red, green / blue, white.
        let rows = [[[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0]], [[0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]];
        let png = image::ImageBuffer::<image::Rgb<u16>, _>::from_fn(2, 2, |x, y| {
            image::Rgb(rows[y as usize][x as usize].map(|c| (c * 65535.0) as u16))
        });
        png.save(dir.join("t16.png")).unwrap();
        let exr = image::Rgb32FImage::from_fn(2, 2, |x, y| image::Rgb(rows[y as usize][x as usize]));
        exr.save(dir.join("t.exr")).unwrap();
        for file in ["t16.png", "t.exr"] {
            let path = dir.join(file);
            let text = format!(
                r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">
                <image name="i" type="color3"><input name="file" type="filename" value="{}"/></image>
                <output name="out" type="color3" nodename="i"/></nodegraph></materialx>"#,
                path.display()
            );
            let doc = Document::parse(&text, "t.mtlx".as_ref(), &LoadOptions::default()).unwrap();
            let g = doc.graph();
            let out = g.output_id("g/out").unwrap();
            let mut scratch = EvalScratch::new(g);
            let at = |u: f32, v: f32, scratch: &mut EvalScratch| {
                let f = g.eval_output(out, &Footprint::point(Vec2::new(u, v)), scratch);
                [f.ch[0].mean, f.ch[1].mean, f.ch[2].mean]
            };
            let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-3);
            assert!(close(at(0.25, 0.25, &mut scratch), [0.0, 0.0, 1.0]), "{file}: bottom left");
            assert!(close(at(0.75, 0.25, &mut scratch), [1.0, 1.0, 1.0]), "{file}: bottom right");
            assert!(close(at(0.25, 0.75, &mut scratch), [1.0, 0.0, 0.0]), "{file}: top left");
            assert!(close(at(0.75, 0.75, &mut scratch), [0.0, 1.0, 0.0]), "{file}: top right");
            // A huge footprint averages the image.
            let f = g.eval_output(out, &Footprint::isotropic(Vec2::new(0.3, 0.6), 50.0), &mut scratch);
            assert!((f.ch[0].mean - 0.5).abs() < 1e-3 && (f.ch[2].mean - 0.5).abs() < 1e-3);
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
