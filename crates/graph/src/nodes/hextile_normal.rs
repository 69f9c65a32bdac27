//! Hex-tiled normal maps: `hextilednormalmap` (MaterialX 1.39's `ND_hextilednormalmap_vector3`),
//! the tiling of [`super::hextile`] applied to a tangent-space normal map.
//!
//! | input | type | default |
//! |---|---|---|
//! | `file` | filename | — (empty: the node gives its `default`, as `hextiledimage` does) |
//! | `default` | vector3 | 0.5, 0.5, 1 |
//! | `texcoord`, `tiling`, `rotation`, `rotationrange`, `scale`, `scalerange`, `offset`, `offsetrange`, `falloff` | as `hextiledimage` | as `hextiledimage` |
//! | `strength` | float | 1 |
//! | `flip_g` | boolean | false |
//! | `normal`, `tangent`, `bitangent` | vector3 | the shading frame (`Nworld`, `Tworld`, `Bworld`) |
//!
//! The output is a unit vector3 in the frame's space (not an encoded colour), as MaterialX's.
//!
//! **Unfiltered** (MaterialX's GLSL `mx_hextilednormalmap_vector3`). The coordinate, the
//! triangle's three tiles, their lookups and their blend weights are those of `hextiledimage`
//! (v flipped before the tiling, see [`super::hextile`]) with the luminance factor 1 (the node has
//! no `falloffcontrast`): `w ∝ b⁷`, normalised, then Schlick's gain when `falloff ≠ 0.5`. Tile
//! `k`'s encoded normal `c_k` (its green channel `1 − g` when `flip_g`) decodes to
//! `m = 2 c_k − 1`; its frame is the input frame rotated about `N` by the tile's random angle
//! `θ_k` (`T_k = R_N(θ_k) T · strength`, `B_k` likewise, Rodrigues' formula as MaterialX's
//! `mx_axis_rotation_matrix`), its normal `N_k = normalize(T_k m.x + B_k m.y + N m.z)`. The three
//! blend as surface gradients (Mikkelsen 2020): `g_k = (d N − N_k)/max(1e-8, |d|)`,
//! `d = N·N_k`, and the result is `normalize(N − Σ w_k g_k)` (0 where that is 0, where MaterialX's
//! `normalize` is undefined).
//!
//! **Filtered.** As `hextiledimage`, the blend is linear in what the tiles contribute, here their
//! surface gradients, so the same two parts apply:
//! - *Lookups.* Each of the centre triangle's three tiles takes `image`'s filtered lookup of the
//!   encoded map over the tile's map of the footprint (as MaterialX's `textureGrad` filters the
//!   encoded map before decoding it), decoded to its gradient `g_k`.
//! - *Weights.* The weight masses `E[w_k]` over the footprint come from the blend weights at the
//!   5 × 5 Gauss–Hermite nodes (`hextiledimage`'s rule, with luminance factor 1). Tiles other than
//!   the three take a surrogate gradient: the three's mean where the tiles' maps agree, else the
//!   gradient of the image's mean colour averaged over the rotation range (a 16-point midpoint
//!   rule over `θ`), mixed by the tiles' coherence. Beyond a tile (`ρ` from `NEAR` to `FAR`) the
//!   blend moves to the surrogate as `hextiledimage`'s does, and from `FAR` on, with unrelated or
//!   blurred tiles, the node is the normal of that averaged gradient without any lookup.
//! - The result is `normalize(N − E[Σ w_k g_k])`. *Gradient*: forward-mode through the weight
//!   masses and the lookups (each `g_k`'s derivative by central differences along its lookup's
//!   gradient), then through the normalisation; the frame inputs' own variation enters through
//!   `N` alone. *Variance*: the lookups' spreads mapped through the decode's Jacobian and combined
//!   as fully correlated (as `hextiledimage` combines them), plus the linear part `gᵀΣg`.
//!
//! **Totality.** The decode, the rotation and the blend are finite for finite inputs: the
//! gradient's divisor is at least 1e-8, and every normalisation of a zero vector is 0.

use super::hextile::{self, Coord, Dual, HexTile, Params};
use super::image;
use super::{inp, Ctx, Def, InType, NodeDef};
use crate::graph::GeomProp;
use crate::value::{Filtered, Moments, ValueType};
use glam::{DMat2, DVec2, DVec3, Vec2};

pub(super) fn definition() -> NodeDef {
    use Def::*;
    use InType::*;
    let inputs: &'static [_] = &[
        inp!("default", V3, Triple(0.5, 0.5, 1.0)),
        inp!("texcoord", V2, Uv),
        inp!("tiling", V2, Pair(1.0, 1.0)),
        inp!("rotation", Float, One),
        inp!("rotationrange", V2, Pair(0.0, 360.0)),
        inp!("scale", Float, One),
        inp!("scalerange", V2, Pair(0.5, 2.0)),
        inp!("offset", Float, One),
        inp!("offsetrange", V2, Pair(0.0, 1.0)),
        inp!("falloff", Float, Half),
        inp!("strength", Float, One),
        inp!("flip_g", Bool, Zero),
        inp!("normal", V3, Geom(GeomProp::Normal)),
        inp!("tangent", V3, Geom(GeomProp::Tangent)),
        inp!("bitangent", V3, Geom(GeomProp::Bitangent)),
    ];
    NodeDef {
        category: "hextilednormalmap",
        inputs,
        params: &["file"],
        types: |t| t == ValueType::Vector3,
        build: hextile::build,
    }
}

/// MaterialX's `M_FLOAT_EPS`, the least divisor of a surface gradient.
const EPS: f64 = 1e-8;
/// Nodes of the midpoint rule over the rotation range.
const ANGLES: usize = 16;
/// Colour step of the central differences through the decode.
const STEP: f64 = 1e-4;

/// The frame and settings a tile's encoded normal is decoded with.
struct Frame {
    n: DVec3,
    t: DVec3,
    b: DVec3,
    strength: f64,
    flip_g: bool,
}

/// `v` rotated about `a` by `r`: `cos r v + sin r (a × v) + (1 − cos r)(a·v) a`, the matrix
/// MaterialX's `mx_axis_rotation_matrix(a, −r)` applies (for any `a`, unit or not).
fn rotate(a: DVec3, r: f64, v: DVec3) -> DVec3 {
    let (s, c) = r.sin_cos();
    v * c + a.cross(v) * s + a * (a.dot(v) * (1.0 - c))
}

impl Frame {
    fn read(ins: &[Filtered]) -> Frame {
        let v3 = |f: &Filtered| DVec3::new(f.ch[0].mean as f64, f.ch[1].mean as f64, f.ch[2].mean as f64);
        Frame {
            n: v3(&ins[12]),
            t: v3(&ins[13]),
            b: v3(&ins[14]),
            strength: ins[10].ch[0].mean as f64,
            flip_g: ins[11].ch[0].mean != 0.0,
        }
    }

    /// The surface gradient of a tile whose encoded normal is `rgb`, rotated by `theta`.
    fn gradient(&self, rgb: DVec3, theta: f64) -> DVec3 {
        let g = if self.flip_g { 1.0 - rgb.y } else { rgb.y };
        let m = DVec3::new(rgb.x, g, rgb.z) * 2.0 - DVec3::ONE;
        let tk = rotate(self.n, theta, self.t) * self.strength;
        let bk = rotate(self.n, theta, self.b) * self.strength;
        let nk = (tk * m.x + bk * m.y + self.n * m.z).normalize_or_zero();
        let d = self.n.dot(nk);
        (self.n * d - nk) / d.abs().max(EPS)
    }
}

/// The Jacobian of `f` in the colour, by central differences: column `i` is `∂f/∂rgbᵢ`.
fn jacobian(f: impl Fn(DVec3) -> DVec3, rgb: DVec3) -> [DVec3; 3] {
    [DVec3::X, DVec3::Y, DVec3::Z].map(|e| (f(rgb + e * STEP) - f(rgb - e * STEP)) / (2.0 * STEP))
}

/// One tile's decoded lookup: its gradient, the gradient's derivatives in `c`, and the
/// texels' spread of the gradient in the tangent plane.
struct Tile {
    g: DVec3,
    dg: [DVec3; 2],
    spread: DMat2,
}

pub(super) fn eval(h: &HexTile, ins: &[Filtered], ctx: &mut Ctx) -> Filtered {
    let mut p = Params::read(ins);
    // No luminance weighting: MaterialX blends normal tiles with luminance factor 1.
    p.contrast = 0.0;
    p.luma = [0.0; 3];
    let frame = Frame::read(ins);
    let tc = &ins[1];
    let Coord { c, cov, lambda, rho, alpha, kappa } = Coord::of(&p, tc, ctx);
    let fc = h.tex.file_channels();
    let (gm, gsq) = h.tex.global_moments();
    let mean_rgb = DVec3::from_array([0, 1, 2].map(|k| image::channel(&gm, fc, k)));
    let global_var = DVec3::from_array([0, 1, 2].map(|k| {
        let m = image::channel(&gm, fc, k);
        (image::channel(&gsq, fc, k) - m * m).max(0.0)
    }));
    let plane = Plane::of(frame.n);

    if alpha >= 1.0 && (kappa < 1e-4 || lambda >= (hextile::BLURRED * p.max_scale()).powi(2)) {
        // Much larger than a tile: the normal of the image's texels under random rotations.
        ctx.work.lattice += 1;
        let (g_mean, spread) = far_field(&frame, &p, &plane, mean_rgb, global_var);
        let (m, m2) = plane.expect(frame.n, g_mean, &spread);
        return output(m, [Vec2::ZERO; 3], (m2 - m * m).to_array());
    }

    let tri = hextile::triangle(c);
    let size = h.tex.size();
    let mut tiles: Vec<Tile> = Vec::with_capacity(3);
    for id in tri.ids {
        let ctr = hextile::centre(id);
        let (l, o) = p.tile_map(id);
        let theta = p.tile_angle(id);
        let at = hextile::flip(l * (c - ctr) + ctr + o);
        let ck = l * cov * l.transpose();
        let sigma = DVec2::new(ck.x_axis.x.max(0.0).sqrt(), ck.y_axis.y.max(0.0).sqrt());
        let [v, sq, du, dv] = image::filtered_rgba(&h.tex, at, sigma, ctx.point);
        ctx.work.lattice += 4;
        let rgb = DVec3::from_array([0, 1, 2].map(|k| image::channel(&v, fc, k)));
        // ∂rgb/∂c per axis of c: Lᵀ F ∂/∂(lookup uv).
        let grads =
            [0, 1, 2].map(|k| l.transpose() * DVec2::new(image::channel(&du, fc, k), -image::channel(&dv, fc, k)));
        let dir = [0, 1].map(|a| DVec3::new(grads[0][a], grads[1][a], grads[2][a]));
        let f = |x: DVec3| frame.gradient(x, theta);
        let jac = jacobian(f, rgb);
        let dg = dir.map(|d| jac[0] * d.x + jac[1] * d.y + jac[2] * d.z);
        // The texels' own spread within the lookup, which the filtered (smooth) lookup does
        // not carry, as the footprint grows past a texel (`hextiledimage`'s rule).
        let coverage = (sigma.x * size.0 as f64).max(sigma.y * size.1 as f64).powi(2).min(1.0);
        let var = DVec3::from_array([0, 1, 2].map(|k| {
            let lin = hextile::quad(&cov, grads[k]);
            (image::channel(&sq, fc, k) - rgb[k] * rgb[k] - lin).max(0.0) * coverage
        }));
        tiles.push(Tile { g: f(rgb), dg, spread: plane.project(&jac, var) });
    }

    // The surrogate of the other tiles: the three's mean where their maps agree, else the
    // image's texels under random rotations.
    let avg_g = (tiles[0].g + tiles[1].g + tiles[2].g) / 3.0;
    let avg_dg = [0, 1].map(|a| (tiles[0].dg[a] + tiles[1].dg[a] + tiles[2].dg[a]) * (kappa / 3.0));
    let far = (!ctx.point).then(|| far_field(&frame, &p, &plane, mean_rgb, global_var));
    let (g_sur, sur_spread) = match far {
        Some((g_mean, spread)) => {
            let tiles_spread = (tiles[0].spread + tiles[1].spread + tiles[2].spread) * (1.0 / 3.0);
            (avg_g * kappa + g_mean * (1.0 - kappa), tiles_spread * kappa + spread * (1.0 - kappa))
        }
        None => (avg_g, DMat2::ZERO),
    };

    // E[normalize(N − G)] over the footprint: at its nodes, G is the blend of the tiles'
    // gradients, each linear over the footprint, with the texels' spread about it.
    let (mut w, mut wfar) = ([Dual::constant(0.0); 3], Dual::constant(0.0));
    let (mut m, mut m2) = (DVec3::ZERO, DVec3::ZERO);
    hextile::for_footprint_nodes(c, &cov, rho, |x, wt| {
        let at = hextile::triangle(x);
        let dx = x - c;
        let ones = [Dual::constant(1.0); 3];
        let (mut g, mut s) = (DVec3::ZERO, DMat2::ZERO);
        for (v, wv) in hextile::blend(&p, at.bary, ones).into_iter().enumerate() {
            match tri.ids.iter().position(|t| *t == at.ids[v]) {
                Some(k) => {
                    w[k] = w[k] + wv * wt;
                    let t = &tiles[k];
                    g += (t.g + t.dg[0] * dx.x + t.dg[1] * dx.y) * wv.v;
                    s += t.spread * (wv.v * wv.v);
                }
                None => {
                    wfar = wfar + wv * wt;
                    g += (g_sur + avg_dg[0] * dx.x + avg_dg[1] * dx.y) * wv.v;
                    s += sur_spread * (wv.v * wv.v);
                }
            }
        }
        let (e, e2) = plane.expect(frame.n, g, &s);
        m += e * wt;
        m2 += e2 * wt;
    });
    // Beyond a tile: towards the surrogate alone.
    if alpha > 0.0 {
        let (e, e2) = plane.expect(frame.n, g_sur, &sur_spread);
        m += (e - m) * alpha;
        m2 += (e2 - m2) * alpha;
    }

    // The gradient: forward-mode through the blend's weight masses and the lookups, then
    // through normalize(N − G) at the blended gradient; back to uv through c = (u tₓ, 1 − v t_y).
    let mut gsum = g_sur * wfar.v;
    let mut dsum = [0, 1].map(|a| g_sur * wfar.d[a] + avg_dg[a] * wfar.v);
    for (wk, t) in w.iter().zip(&tiles) {
        gsum += t.g * wk.v;
        for a in 0..2 {
            dsum[a] += t.g * wk.d[a] + t.dg[a] * wk.v;
        }
    }
    let blend_g = gsum + (g_sur - gsum) * alpha;
    let blend_d = [0, 1].map(|a| dsum[a] * (1.0 - alpha) + avg_dg[a] * alpha);
    let (n, len) = normal_of(frame.n, blend_g);
    let t = p.tiling;
    let dn_dc = blend_d.map(|dg| if len > 0.0 { -(dg - n * n.dot(dg)) / len } else { DVec3::ZERO });
    let nin = &ins[12];
    let dn_in = |a: usize| DVec3::new(nin.ch[0].grad[a] as f64, nin.ch[1].grad[a] as f64, nin.ch[2].grad[a] as f64);
    let through = |d: DVec3| if len > 0.0 { (d - n * n.dot(d)) / len } else { DVec3::ZERO };
    let (du_in, dv_in) = (through(dn_in(0)), through(dn_in(1)));
    let grads = [0, 1, 2].map(|k| {
        let from_c = tc.ch[0].grad * (dn_dc[0][k] * t.x) as f32 - tc.ch[1].grad * (dn_dc[1][k] * t.y) as f32;
        from_c + Vec2::new(du_in[k] as f32, dv_in[k] as f32)
    });
    if ctx.point {
        return output(n, grads, [0.0; 3]);
    }
    let var = [0, 1, 2].map(|k| (m2[k] - m[k] * m[k]).max(hextile::quad(&cov, DVec2::new(dn_dc[0][k], dn_dc[1][k]))));
    output(m, grads, var)
}

/// The far field: the gradient of the image's mean colour averaged over the rotation range, and
/// the spread (in the tangent plane) of the gradients of the image's texels under random
/// rotations about it: over the midpoint rule's angles, the angles' own scatter plus each
/// angle's decode Jacobian applied to the image's per-channel variances.
fn far_field(frame: &Frame, p: &Params, plane: &Plane, rgb: DVec3, var: DVec3) -> (DVec3, DMat2) {
    let rr = p.rotation_range * (std::f64::consts::PI / 180.0);
    let (a, b) = (rr.x, rr.x + (rr.y - rr.x) * p.rotation);
    let mut gs = [DVec3::ZERO; ANGLES];
    let mut spread = DMat2::ZERO;
    for (k, g) in gs.iter_mut().enumerate() {
        let theta = a + (b - a) * (k as f64 + 0.5) / ANGLES as f64;
        *g = frame.gradient(rgb, theta);
        spread += plane.project(&jacobian(|x| frame.gradient(x, theta), rgb), var);
    }
    let mean = gs.iter().copied().sum::<DVec3>() / ANGLES as f64;
    for g in gs {
        let d = plane.coords(g - mean);
        spread += DMat2::from_cols(d * d.x, d * d.y);
    }
    (mean, spread * (1.0 / ANGLES as f64))
}

/// The tangent plane of the input normal: two orthonormal vectors perpendicular to it, in which
/// the spreads of surface gradients are kept (a surface gradient is perpendicular to a unit `N`).
struct Plane {
    u: DVec3,
    v: DVec3,
}

impl Plane {
    fn of(n: DVec3) -> Plane {
        let nh = n.try_normalize().unwrap_or(DVec3::Z);
        let (u, v) = nh.any_orthonormal_pair();
        Plane { u, v }
    }

    fn coords(&self, x: DVec3) -> DVec2 {
        DVec2::new(self.u.dot(x), self.v.dot(x))
    }

    /// `J diag(var) Jᵀ` in the plane, `J` given by its columns.
    fn project(&self, jac: &[DVec3; 3], var: DVec3) -> DMat2 {
        let mut s = DMat2::ZERO;
        for (col, v) in jac.iter().zip(var.to_array()) {
            let d = self.coords(*col);
            s += DMat2::from_cols(d * (d.x * v), d * (d.y * v));
        }
        s
    }

    /// `E[normalize(N − G)]` and its per-channel second moment for `G` normal about `g` with
    /// covariance `s` in the plane (3 × 3 Gauss–Hermite).
    fn expect(&self, n: DVec3, g: DVec3, s: &DMat2) -> (DVec3, DVec3) {
        if s.x_axis.x + s.y_axis.y <= 1e-18 {
            let (e, _) = normal_of(n, g);
            return (e, e * e);
        }
        let l = hextile::factor(s);
        let (mut m, mut m2) = (DVec3::ZERO, DVec3::ZERO);
        for (z1, a1) in crate::gaussian::HERMITE3 {
            for (z2, a2) in crate::gaussian::HERMITE3 {
                let d = l * DVec2::new(z1, z2);
                let (e, _) = normal_of(n, g + self.u * d.x + self.v * d.y);
                m += e * (a1 * a2);
                m2 += e * e * (a1 * a2);
            }
        }
        (m, m2)
    }
}

/// `normalize(N − G)` and `|N − G|` (0 and 0 where it is 0).
fn normal_of(n: DVec3, g: DVec3) -> (DVec3, f64) {
    let v = n - g;
    let len = v.length();
    if len > 0.0 && len.is_finite() {
        (v / len, len)
    } else {
        (DVec3::ZERO, 0.0)
    }
}

fn output(n: DVec3, grads: [Vec2; 3], var: [f64; 3]) -> Filtered {
    let mut out = Filtered::zero(ValueType::Vector3);
    for k in 0..3 {
        out.ch[k] = Moments { mean: n[k] as f32, grad: grads[k], var: var[k].max(0.0) as f32 };
    }
    out
}
