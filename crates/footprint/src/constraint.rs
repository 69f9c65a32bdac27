//! The half-vector constraint and its derivatives `A_i`, `B_i`, `C_i`, plus the roughness model
//! that gives `var(Δh_i)`.

use glam::{DMat2, DVec2, DVec3};

use crate::vertex::{LocalGeometry, Scatter, Vertex};
use crate::{MAX_ALPHA, MIN_COSINE, MIN_DISTANCE, MIN_ETA_OFFSET, MIN_HALF_VECTOR_NORM};

/// The blocks of row `i` of the constraint derivative matrix (eq. 1 of the supplemental):
/// `A_i = ∂h_i/∂x_{i−1}`, `B_i = ∂h_i/∂x_i`, `C_i = ∂h_i/∂x_{i+1}`, each 2×2.
///
/// `h_i` is the half vector at `x_i` in slope space of `x_i`'s shading frame,
/// `(h·t / h·n, h·b / h·n)`; each `x_j` is an offset in `x_j`'s own tangent plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstraintDerivatives {
    /// `A_i = ∂h_i/∂x_{i−1}`.
    pub a: DMat2,
    /// `B_i = ∂h_i/∂x_i` (includes the rotation of `x_i`'s frame as it moves).
    pub b: DMat2,
    /// `C_i = ∂h_i/∂x_{i+1}`.
    pub c: DMat2,
}

impl ConstraintDerivatives {
    /// Whether all entries are finite.
    pub fn is_finite(&self) -> bool {
        self.a.is_finite() && self.b.is_finite() && self.c.is_finite()
    }
}

/// The relative IOR actually used for a refraction: non-finite or non-positive values become 1,
/// values are clamped to `[1e-3, 1e3]`, and kept at least [`MIN_ETA_OFFSET`] away from 1 (an
/// index-matched interface has no half vector; nearby, the constraint degenerates gracefully to
/// straight propagation because roughness then barely deflects the path).
pub fn effective_eta(eta: f64) -> f64 {
    let e = if eta.is_finite() && eta > 0.0 { eta.clamp(1e-3, 1e3) } else { 1.0 };
    if (e - 1.0).abs() < MIN_ETA_OFFSET {
        if e < 1.0 {
            1.0 - MIN_ETA_OFFSET
        } else {
            1.0 + MIN_ETA_OFFSET
        }
    } else {
        e
    }
}

/// Coefficients `(c_i, c_o)` with `h ∝ c_i ω_i + c_o ω_o`. The overall sign of `h` does not
/// matter in slope space, so refraction uses `ω_i + eta ω_o`.
fn coefficients(scatter: Scatter) -> (f64, f64) {
    match scatter {
        Scatter::Reflection => (1.0, 1.0),
        Scatter::Refraction { eta } => (1.0, effective_eta(eta)),
    }
}

/// [`unit_and_length`] as the unit vector and the reciprocal of the (clamped) length: one
/// division where the vector and its derivatives would take four.
#[inline]
fn unit_and_inverse_length(d: DVec3) -> (DVec3, f64) {
    let l = d.length();
    if l > MIN_DISTANCE && l.is_finite() {
        let inv = 1.0 / l;
        (d * inv, inv)
    } else {
        let (u, l) = unit_and_length(d);
        (u, 1.0 / l)
    }
}

fn unit_and_length(d: DVec3) -> (DVec3, f64) {
    let l = d.length();
    if l > MIN_DISTANCE && l.is_finite() {
        (d / l, l)
    } else if l > 0.0 && l.is_finite() {
        (d / l, MIN_DISTANCE)
    } else {
        (DVec3::Z, MIN_DISTANCE)
    }
}

/// `h·n` kept away from zero: `|h·n| ≥ max(MIN_COSINE |h|, MIN_HALF_VECTOR_NORM)`, sign kept.
/// Decided on squares first: most half vectors are far from grazing, and the clamp then needs
/// no square root.
#[inline]
fn clamped_hn(h: DVec3, n: DVec3) -> f64 {
    let hn = h.dot(n);
    let hn2 = hn * hn;
    if hn2 >= 4.0 * (MIN_COSINE * MIN_COSINE) * h.length_squared() && hn.abs() >= 2.0 * MIN_HALF_VECTOR_NORM {
        // Twice the floors (the factors cover the squares' rounding): the test below holds.
        return hn;
    }
    let floor = (MIN_COSINE * h.length()).max(MIN_HALF_VECTOR_NORM);
    if hn.abs() >= floor {
        hn
    } else {
        floor.copysign(hn)
    }
}

/// The half vector at `cur` in slope space of `cur`'s shading frame, for a path through
/// `prev_p → cur → next_p`. Uses the same clamps as [`constraint_derivatives`].
pub fn half_vector_slope(prev_p: DVec3, cur: &Vertex, next_p: DVec3, scatter: Scatter) -> DVec2 {
    let (wi, _) = unit_and_length(prev_p - cur.p);
    let (wo, _) = unit_and_length(next_p - cur.p);
    let (ci, co) = coefficients(scatter);
    let h = wi * ci + wo * co;
    let hn = clamped_hn(h, cur.n);
    DVec2::new(h.dot(cur.t) / hn, h.dot(cur.b) / hn)
}

/// Analytic `A_i, B_i, C_i` for the half-vector constraint at `cur` (= `x_i`), with
/// `prev` = `x_{i−1}` and `next` = `x_{i+1}`.
///
/// Derivation (all in `f64`): with `ω = d/|d|`, `dω = (I − ωωᵀ) d(d) / |d|`; each vertex moves
/// by its tangent map `P` ([`crate::LocalGeometry::tangent_map`]); the slope
/// `s = (h·t, h·b) / h·n` changes by `G dh` with rows `(t − s₁n)/h·n` and `(b − s₂n)/h·n`, and,
/// because `x_i`'s frame rotates minimally with its normal (`dn = [t b] W Δx`,
/// `dt = −n (t·dn)`, `db = −n (b·dn)`), by `−(I + s sᵀ) W Δx_i`.
///
/// Clamps: distances below [`MIN_DISTANCE`] are raised to it; `|h·n|` is kept at least
/// [`MIN_COSINE`]`·|h|` (and [`MIN_HALF_VECTOR_NORM`]) so that grazing half vectors give large
/// but finite slopes; refraction uses [`effective_eta`]. For finite inputs the result is finite.
pub fn constraint_derivatives(prev: &Vertex, cur: &Vertex, next: &Vertex, scatter: Scatter) -> ConstraintDerivatives {
    constraint_derivatives_with(prev, &prev.local(), cur, &cur.local(), next, &next.local(), scatter)
}

/// [`constraint_derivatives`] with each vertex's [`LocalGeometry`] already computed (a tracker
/// computes it once per vertex instead of once per use).
pub fn constraint_derivatives_with(
    prev: &Vertex,
    lp: &LocalGeometry,
    cur: &Vertex,
    lc: &LocalGeometry,
    next: &Vertex,
    ln: &LocalGeometry,
    scatter: Scatter,
) -> ConstraintDerivatives {
    constraint_derivatives_from(prev.p, &lp.tangent_map, cur, lc, next, ln, scatter)
}

/// [`constraint_derivatives_with`] reading of `x_{i−1}` only what `A_i` depends on: its
/// position and its tangent map (all a tracker keeps of it).
pub(crate) fn constraint_derivatives_from(
    prev_p: DVec3,
    prev_tangent_map: &[DVec3; 2],
    cur: &Vertex,
    lc: &LocalGeometry,
    next: &Vertex,
    ln: &LocalGeometry,
    scatter: Scatter,
) -> ConstraintDerivatives {
    let (t, b, n) = (cur.t, cur.b, cur.n);

    let (wi, inv_li) = unit_and_inverse_length(prev_p - cur.p);
    let (wo, inv_lo) = unit_and_inverse_length(next.p - cur.p);
    let (ci, co) = coefficients(scatter);
    let h = wi * ci + wo * co;
    let inv_hn = 1.0 / clamped_hn(h, n);
    let s = DVec2::new(h.dot(t) * inv_hn, h.dot(b) * inv_hn);
    // G = ∂s/∂h, two rows.
    let g1 = (t - n * s.x) * inv_hn;
    let g2 = (b - n * s.y) * inv_hn;
    // G ∂ω/∂(endpoint) is linear in the endpoint's offset: `(c/l) (G − (G ω) ωᵀ)`, two rows
    // each for ω_i and ω_o, formed once and applied to every tangent-map column (three
    // divisions and a dozen dot products instead of one of each per column).
    let rows = |w: DVec3, k: f64| [(g1 - w * g1.dot(w)) * k, (g2 - w * g2.dot(w)) * k];
    let ri = rows(wi, ci * inv_li);
    let ro = rows(wo, co * inv_lo);
    let rb = [ri[0] + ro[0], ri[1] + ro[1]];
    let apply = |r: &[DVec3; 2], p: &[DVec3; 2]| {
        DMat2::from_cols(DVec2::new(r[0].dot(p[0]), r[1].dot(p[0])), DVec2::new(r[0].dot(p[1]), r[1].dot(p[1])))
    };
    let a = apply(&ri, prev_tangent_map);
    let c = apply(&ro, &ln.tangent_map);
    let bpos = -apply(&rb, &lc.tangent_map);
    let i_ss = DMat2::from_cols(DVec2::new(1.0 + s.x * s.x, s.x * s.y), DVec2::new(s.x * s.y, 1.0 + s.y * s.y));
    ConstraintDerivatives { a, b: bpos - i_ss * lc.shape, c }
}

/// `var(Δh) = (α/√2)² I`: the slope-space covariance of a Beckmann lobe with roughness `α`
/// (each slope component of a Beckmann NDF is Gaussian with standard deviation `α/√2`).
/// Lambertian: `α = 1`; smooth: `α = 0`. `α` is clamped to `[0, MAX_ALPHA]`; NaN counts as
/// [`MAX_ALPHA`] (unknown roughness gives the widest footprint).
pub fn half_vector_variance(alpha: f64) -> DMat2 {
    let a = sanitize_alpha(alpha);
    DMat2::from_diagonal(DVec2::splat(0.5 * a * a))
}

/// Anisotropic variant of [`half_vector_variance`]: roughness `alpha.x` along the shading
/// tangent `t` and `alpha.y` along `b` (the BSDF's frame must be the vertex's shading frame).
pub fn half_vector_variance_aniso(alpha: DVec2) -> DMat2 {
    let ax = sanitize_alpha(alpha.x);
    let ay = sanitize_alpha(alpha.y);
    DMat2::from_diagonal(DVec2::new(0.5 * ax * ax, 0.5 * ay * ay))
}

fn sanitize_alpha(alpha: f64) -> f64 {
    if alpha.is_nan() {
        MAX_ALPHA
    } else {
        alpha.clamp(0.0, MAX_ALPHA)
    }
}

/// `1/√(ln 2)`: the ratio of Beckmann to GGX roughness with equal median slope.
pub const GGX_TO_BECKMANN: f64 = 1.201_122_408_786_449_8;

/// The Beckmann-equivalent roughness of a GGX (Trowbridge–Reitz) lobe with roughness `a`.
///
/// GGX slopes are heavy-tailed: their variance is infinite, so a slope-variance match is not
/// possible. We match the *median slope magnitude* instead (the radius in slope space that
/// contains half of the microfacet normals, weighted by projected area, i.e. `D(m)(m·n)`):
/// - GGX: `P(tan θ_m < r) = r² / (α_G² + r²)`, median `r = α_G`;
/// - Beckmann: `P(tan θ_m < r) = 1 − exp(−r²/α_B²)`, median `r = α_B √(ln 2)`.
///
/// Hence `α_B = α_G / √(ln 2) ≈ 1.2011 α_G`. (Matching the per-axis interquartile range gives
/// almost the same factor, 1.2105; the common shortcut `α_B = α_G` would under-estimate the
/// spread of GGX's tails by about 20%.) The result is clamped like [`half_vector_variance`]'s
/// input: negative → 0, NaN or huge → [`MAX_ALPHA`].
pub fn ggx_to_beckmann_alpha(a: f32) -> f32 {
    (sanitize_alpha(a as f64) * GGX_TO_BECKMANN).min(MAX_ALPHA) as f32
}
