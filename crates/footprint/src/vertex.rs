//! What the renderer describes at each path vertex, and the local surface shape derived from it.

use glam::{DMat2, DVec2, DVec3};

use crate::UV_CONDITION_LIMIT;

/// A path vertex as the renderer knows it: position, shading frame, surface derivatives and uv.
///
/// Conventions:
/// - `(t, b, n)` is the orthonormal *shading* frame with `n = t × b`. Footprints at this vertex
///   are 2×2 covariances of offsets `Δx = (Δx₁, Δx₂)` in the tangent plane spanned by `t, b`.
/// - `dpdu, dpdv` are the surface's position derivatives with respect to its `(u, v)`
///   parameterisation, and `dndu, dndv` the derivatives of the *shading normal `n` as given*
///   (flip them together with `n` if the renderer flips the normal to face the ray). Any
///   component of `dndu, dndv` along `n` is ignored (a unit normal only changes orthogonally).
/// - `uv` is the texture coordinate; `(u, v)` is assumed to be the same parameterisation as the
///   one `dpdu, dpdv` refer to (so the texture-space Jacobian follows from them).
///
/// A vertex moves *on its surface*: `Δx` is the projection of the displacement onto the shading
/// tangent plane, so to first order the point moves by `t Δx₁ + b Δx₂` plus, where the shading
/// normal differs from the geometric one, a component along `n` (see [`LocalGeometry`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vertex {
    /// Position.
    pub p: DVec3,
    /// Shading normal (unit length, `t × b`).
    pub n: DVec3,
    /// Shading tangent (unit length).
    pub t: DVec3,
    /// Shading bitangent (unit length).
    pub b: DVec3,
    /// ∂p/∂u.
    pub dpdu: DVec3,
    /// ∂p/∂v.
    pub dpdv: DVec3,
    /// ∂n/∂u of the shading normal.
    pub dndu: DVec3,
    /// ∂n/∂v of the shading normal.
    pub dndv: DVec3,
    /// Texture coordinates.
    pub uv: DVec2,
}

impl Vertex {
    /// A vertex on a plane with normal `n` at `p`; the frame comes from [`orthonormal_basis`],
    /// `(u, v)` are the offsets along `(t, b)` and `uv = (0, 0)`.
    pub fn on_plane(p: DVec3, n: DVec3) -> Self {
        let n = n.normalize();
        let (t, b) = orthonormal_basis(n);
        Vertex { p, n, t, b, dpdu: t, dpdv: b, dndu: DVec3::ZERO, dndv: DVec3::ZERO, uv: DVec2::ZERO }
    }

    /// A point without surface, such as a pinhole camera: an arbitrary frame, zero derivatives.
    /// Suitable as the first vertex `x₀` of a path, whose offsets are never used.
    pub fn point(p: DVec3) -> Self {
        Vertex {
            p,
            n: DVec3::Z,
            t: DVec3::X,
            b: DVec3::Y,
            dpdu: DVec3::ZERO,
            dpdv: DVec3::ZERO,
            dndu: DVec3::ZERO,
            dndv: DVec3::ZERO,
            uv: DVec2::ZERO,
        }
    }

    /// The local first-order shape of the surface at this vertex, in the shading frame.
    ///
    /// With `M = [t b]ᵀ [dpdu dpdv]` (the map from `(Δu, Δv)` to tangent-plane offsets `Δx`):
    /// - the geometric maps (tangent map and shape operator) use the pseudo-inverse of `M`, with
    ///   singular values below [`UV_CONDITION_LIMIT`] × the largest treated as zero: a direction
    ///   the parameterisation does not cover is taken to be flat and to stay in the shading
    ///   tangent plane;
    /// - the uv Jacobian uses the inverse of `M` with its singular values raised to at least
    ///   [`UV_CONDITION_LIMIT`] × the largest: a nearly degenerate mapping (a sphere's pole, a
    ///   sliver triangle) gives a large but finite texture footprint, continuous as the mapping
    ///   degenerates. If `M` is zero (no parameterisation, or constant uv) everything derived
    ///   from it is zero.
    pub fn local(&self) -> LocalGeometry {
        let (t, b, n) = (self.t, self.b, self.n);
        let m = self.uv_map();
        // One decomposition serves both inverses, and none is needed where the map is clearly
        // well conditioned (both are then its inverse).
        let (j_geo, j_uv) = if crate::mat::certainly_conditioned(m, UV_CONDITION_LIMIT, 0.0) {
            let inv = m.inverse();
            (inv, inv)
        } else {
            Self::regularised_inverses(m)
        };
        // Offsets along n of the true surface per tangent-plane offset.
        let ndp = DVec2::new(n.dot(self.dpdu), n.dot(self.dpdv));
        let k = DVec2::new(ndp.dot(j_geo.x_axis), ndp.dot(j_geo.y_axis));
        let p0 = t + n * k.x;
        let p1 = b + n * k.y;
        // dn per unit tangent-plane offset, in (t, b) coordinates.
        let dn0 = self.dndu * j_geo.x_axis.x + self.dndv * j_geo.x_axis.y;
        let dn1 = self.dndu * j_geo.y_axis.x + self.dndv * j_geo.y_axis.y;
        let shape = DMat2::from_cols(DVec2::new(t.dot(dn0), b.dot(dn0)), DVec2::new(t.dot(dn1), b.dot(dn1)));
        LocalGeometry { tangent_map: [p0, p1], shape, uv_jacobian: j_uv }
    }

    /// The pseudo-inverse and the clamped inverse of the uv map `m` (see [`Vertex::local`]).
    fn regularised_inverses(m: DMat2) -> (DMat2, DMat2) {
        let sv = crate::mat::singular_values(m);
        let smax = sv.0;
        if smax > 0.0 && smax.is_finite() {
            let floor = UV_CONDITION_LIMIT * smax;
            (crate::mat::pseudo_inverse_sv(m, sv, floor), crate::mat::clamped_inverse_sv(m, sv, floor))
        } else {
            (DMat2::ZERO, DMat2::ZERO)
        }
    }

    /// `M = [t b]ᵀ [dpdu dpdv]`: the tangent-plane offset per uv offset.
    #[inline]
    fn uv_map(&self) -> DMat2 {
        let (t, b) = (self.t, self.b);
        DMat2::from_cols(DVec2::new(t.dot(self.dpdu), b.dot(self.dpdu)), DVec2::new(t.dot(self.dpdv), b.dot(self.dpdv)))
    }

    /// [`LocalGeometry::uv_jacobian`] of [`Vertex::local`] alone, without the rest of the local
    /// geometry (the texture footprint needs only it).
    pub fn uv_jacobian(&self) -> DMat2 {
        let m = self.uv_map();
        if crate::mat::certainly_conditioned(m, UV_CONDITION_LIMIT, 0.0) {
            return m.inverse();
        }
        let sv = crate::mat::singular_values(m);
        if sv.0 > 0.0 && sv.0.is_finite() {
            crate::mat::clamped_inverse_sv(m, sv, UV_CONDITION_LIMIT * sv.0)
        } else {
            DMat2::ZERO
        }
    }
}

/// First-order shape of the surface around a [`Vertex`], in its shading frame `(t, b, n)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalGeometry {
    /// `P = ∂p/∂Δx` (3×2, as two columns): how the point moves on its surface per tangent-plane
    /// offset. Its `(t, b)` components are the identity; the `n` components are non-zero where
    /// the shading normal is not the geometric one.
    pub tangent_map: [DVec3; 2],
    /// The shape operator (Weingarten map) `W` in `(t, b)` coordinates: `dn = [t b] W Δx`.
    /// For a sphere of radius `R` with outward normal, `W = I / R`.
    pub shape: DMat2,
    /// `J_uv = ∂(u, v)/∂Δx` (clamped inverse, see [`Vertex::local`]).
    pub uv_jacobian: DMat2,
}

impl LocalGeometry {
    /// Unit normal of the true tangent plane (`span P`), on the side of the vertex's shading
    /// normal `n`; `n` if degenerate. Computed on request: only a path's first vertex and the
    /// ray-cone and pbrt estimators read it, and it was a third of [`Vertex::local`].
    pub fn geometric_normal(&self, n: DVec3) -> DVec3 {
        let g = self.tangent_map[0].cross(self.tangent_map[1]);
        let gl = g.length();
        if gl > 1e-12 && gl.is_finite() {
            let g = g / gl;
            if g.dot(n) < 0.0 {
                -g
            } else {
                g
            }
        } else {
            n
        }
    }
}

/// How the path continues at a vertex: the half-vector constraint that relates its neighbours.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scatter {
    /// Reflection: `h = ω_i + ω_o`.
    Reflection,
    /// Refraction with relative index of refraction `eta = η_o / η_i`: the index on the side
    /// the path continues into (`ω_o`, towards `x_{i+1}`) over the index on the side it came
    /// from (`ω_i`, towards `x_{i-1}`). Entering glass from air: `eta = 1.5`. The generalised
    /// half vector is `h = −(η_i ω_i + η_o ω_o) ∝ −(ω_i + eta ω_o)`.
    Refraction {
        /// `η_o / η_i`.
        eta: f64,
    },
}

/// A right-handed orthonormal basis `(t, b)` with `t × b = n` for a unit `n` (Duff et al. 2017).
pub fn orthonormal_basis(n: DVec3) -> (DVec3, DVec3) {
    let sign = 1.0f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let bb = n.x * n.y * a;
    let t = DVec3::new(1.0 + sign * n.x * n.x * a, sign * bb, -sign * n.x);
    let b = DVec3::new(bb, sign + n.y * n.y * a, -n.y);
    (t, b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_is_right_handed() {
        for n in [
            DVec3::Z,
            -DVec3::Z,
            DVec3::X,
            DVec3::new(0.3, -0.5, 0.2).normalize(),
            DVec3::new(-0.1, 0.2, -0.9).normalize(),
        ] {
            let (t, b) = orthonormal_basis(n);
            assert!((t.cross(b) - n).length() < 1e-12, "{n}");
            assert!(t.dot(n).abs() < 1e-12 && b.dot(n).abs() < 1e-12);
        }
    }

    /// The uv Jacobian alone is the one of the whole local geometry, bit for bit, and inverts
    /// the uv map where it is well conditioned; degenerate maps (parallel or zero derivatives)
    /// give the same finite clamped result both ways.
    #[test]
    fn uv_jacobian_alone_is_the_local_one() {
        let n = DVec3::new(0.2, 0.3, 0.9).normalize();
        let (t, b) = orthonormal_basis(n);
        let cases = [
            (t * 0.3 + b * 0.8, t * -0.6 + b * 0.2),
            (t * 1e3 + n * 0.1, b * 1e-2),
            (t * 0.5, t * 0.5000001),
            (t * 0.5, t * 0.5),
            (DVec3::ZERO, DVec3::ZERO),
            (t * f64::NAN, b),
        ];
        for (dpdu, dpdv) in cases {
            let v =
                Vertex { p: DVec3::ZERO, n, t, b, dpdu, dpdv, dndu: DVec3::ZERO, dndv: DVec3::ZERO, uv: DVec2::ZERO };
            let (alone, local) = (v.uv_jacobian(), v.local().uv_jacobian);
            assert_eq!(
                alone.to_cols_array().map(f64::to_bits),
                local.to_cols_array().map(f64::to_bits),
                "{dpdu} {dpdv}"
            );
            let m = v.uv_map();
            let (smax, smin) = crate::mat::singular_values(m);
            if smin.abs() > 1e-3 * smax {
                assert!((alone * m).abs_diff_eq(DMat2::IDENTITY, 1e-9), "{dpdu} {dpdv}: {}", alone * m);
            }
        }
    }

    #[test]
    fn sphere_shape_operator() {
        let r = 2.5;
        let n = DVec3::new(0.2, 0.3, 0.9).normalize();
        let (t, b) = orthonormal_basis(n);
        // Spherical-coordinate parameterisation, outward normal: dn = dp / R.
        let dpdu = (t * 0.3 + b * 0.8) * 1.7;
        let dpdv = t * -0.6 + b * 0.2;
        let v = Vertex { p: n * r, n, t, b, dpdu, dpdv, dndu: dpdu / r, dndv: dpdv / r, uv: DVec2::ZERO };
        let l = v.local();
        assert!((l.shape - DMat2::IDENTITY / r).abs_diff_eq(DMat2::ZERO, 1e-12));
        assert!((l.tangent_map[0] - t).length() < 1e-12);
        assert!((l.geometric_normal(n) - n).length() < 1e-12);
    }
}
