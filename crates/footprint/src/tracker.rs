//! Algorithm 1 of the supplemental as an O(1)-state tracker.

use glam::{DMat2, DVec2, DVec3};

use crate::constraint::{constraint_derivatives_from, ConstraintDerivatives};
use crate::mat::clamp_covariance;
use crate::vertex::{LocalGeometry, Scatter, Vertex};
use crate::{C_CONDITION_LIMIT, MAX_VARIANCE, MIN_C_SINGULAR_VALUE};

/// Propagates path footprints vertex by vertex (Algorithm 1).
///
/// State: `var_p = var(Δx_i)`, `var_pp = var(Δx_{i−1})`, `cov_p_pp = cov(Δx_i, Δx_{i−1})`
/// (2×2 each, in the respective vertices' tangent frames), plus the previous and current
/// [`Vertex`] so that [`advance`](Self::advance) can form `A_i, B_i, C_i` itself. No allocation.
///
/// Two ways to drive it:
/// - *matrix mode*: [`start`](Self::start) with `var(Δx₁)`, then [`step`](Self::step) with
///   `(A_i, B_i, C_i)` and `var(Δh_i)` for `i = 1, 2, …`; each call returns `var(Δx_{i+1})`.
/// - *vertex mode*: [`start_path`](Self::start_path) with the camera position and the first
///   hit, then [`advance`](Self::advance) once per bounce with the next vertex, the event at the
///   current vertex and its `var(Δh)`.
///
/// Starting sets `var(Δx₀) = 0` and `cov(Δx₁, Δx₀) = 0` (the camera is fixed), so the general
/// update reproduces lines 1–4 of Algorithm 1 for `i = 1` whatever `A₁` is.
///
/// Clamps (never NaN or infinite):
/// - `C_i⁻¹` is a regularised inverse: singular values of `C_i` are raised to at least
///   [`C_CONDITION_LIMIT`] × the largest and at least [`MIN_C_SINGULAR_VALUE`] (a grazing next
///   vertex or a very distant one gives a large but bounded footprint);
/// - every `var(Δx)` is symmetrised and its eigenvalues clamped to `[0, MAX_VARIANCE]`; when the
///   upper bound bites, the cross-covariance is reset to zero (the clamped footprint no longer
///   carries a linear relation to the previous vertex);
/// - non-finite inputs (or an overflow) make the tracker *lost*: the footprint becomes
///   `MAX_VARIANCE · I` with no correlation, and subsequent steps continue from there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FootprintTracker {
    var_p: DMat2,
    var_pp: DMat2,
    cov_p_pp: DMat2,
    /// Of the previous vertex `x_{i−1}`, what `A_i` reads: its position and its tangent map
    /// ([`LocalGeometry::tangent_map`]). A path copies its tracker at every hit (the state at a
    /// hit is kept aside until the path scatters there), and the whole previous vertex with its
    /// local geometry was a third of the copy.
    prev_p: DVec3,
    prev_tangent_map: [DVec3; 2],
    cur: Vertex,
    /// Local geometry of `cur`, computed once when it joined the path.
    cur_local: LocalGeometry,
}

/// The tangent map of [`Vertex::point`]'s local geometry (the camera's vertex).
const POINT_TANGENT_MAP: [DVec3; 2] = [DVec3::X, DVec3::Y];

impl FootprintTracker {
    /// Matrix mode: starts at `x₁` with footprint `var_x1` (e.g. [`crate::first_vertex_variance`]).
    pub fn start(var_x1: DMat2) -> Self {
        let p = Vertex::point(DVec3::ZERO);
        Self::start_path_with(DVec3::ZERO, &p, &p.local(), var_x1)
    }

    /// Vertex mode: starts a path at the camera (`x₀`, a fixed point) whose first hit is
    /// `first` (`x₁`) with footprint `var_x1`.
    pub fn start_path(camera: DVec3, first: &Vertex, var_x1: DMat2) -> Self {
        Self::start_path_with(camera, first, &first.local(), var_x1)
    }

    /// [`start_path`](Self::start_path) with `first`'s [`LocalGeometry`] already computed.
    pub fn start_path_with(camera: DVec3, first: &Vertex, local: &LocalGeometry, var_x1: DMat2) -> Self {
        // The camera's vertex is `Vertex::point(camera)`, whose tangent map is its frame's
        // (x, y): `A₁` meets only the zero variance and covariance of the fixed camera.
        FootprintTracker {
            var_p: clamp_covariance(var_x1, MAX_VARIANCE).cov,
            var_pp: DMat2::ZERO,
            cov_p_pp: DMat2::ZERO,
            prev_p: camera,
            prev_tangent_map: POINT_TANGENT_MAP,
            cur: *first,
            cur_local: *local,
        }
    }

    /// One iteration of Algorithm 1 for constraint `i` (the current vertex `x_i`): returns
    /// `var(Δx_{i+1})` and makes `x_{i+1}` current. `var_h = var(Δh_i)` in `x_i`'s slope space
    /// (see [`crate::half_vector_variance`]). The stored vertices are not touched; use
    /// [`advance`](Self::advance) to keep them in step.
    pub fn step(&mut self, d: &ConstraintDerivatives, var_h: DMat2) -> DMat2 {
        if !d.is_finite() || !var_h.is_finite() {
            return self.lose();
        }
        // An isotropic var(Δh) within bounds (every roughness the renderer passes) is its own
        // clamp: taken as it is, without the eigenvalue test.
        let isotropic = var_h.x_axis.y == 0.0 && var_h.y_axis.x == 0.0 && var_h.x_axis.x == var_h.y_axis.y;
        let var_h = if isotropic && (0.0..=MAX_VARIANCE).contains(&var_h.x_axis.x) {
            var_h
        } else {
            clamp_covariance(var_h, MAX_VARIANCE).cov
        };
        let (a, b) = (d.a, d.b);
        let c_inv = if crate::mat::certainly_conditioned(d.c, C_CONDITION_LIMIT, MIN_C_SINGULAR_VALUE) {
            d.c.inverse()
        } else {
            let (c_max, _) = crate::mat::singular_values(d.c);
            let floor = (C_CONDITION_LIMIT * c_max).max(MIN_C_SINGULAR_VALUE);
            crate::mat::clamped_inverse(d.c, floor)
        };

        // eq. (14): var(Δg_i) with Δg_i = A_i Δx_{i−1} + B_i Δx_i. `A cov(Δx_i, Δx_{i−1})ᵀ` and
        // `B var(Δx_i)` serve eq. (16) too.
        let a_cov = a * self.cov_p_pp.transpose();
        let b_var = b * self.var_p;
        let cross = b * a_cov.transpose();
        let var_g = a * self.var_pp * a.transpose() + b_var * b.transpose() + cross + cross.transpose();
        // eq. (13) and eq. (16).
        let var_next = c_inv * (var_h + var_g) * c_inv.transpose();
        let cov_next = -(c_inv * (a_cov + b_var));

        if !var_next.is_finite() || !cov_next.is_finite() {
            return self.lose();
        }
        let clamped = clamp_covariance(var_next, MAX_VARIANCE);
        self.var_pp = self.var_p;
        self.var_p = clamped.cov;
        self.cov_p_pp = if clamped.clamped_above { DMat2::ZERO } else { cov_next };
        self.var_p
    }

    /// Vertex mode: the path scatters at the current vertex `x_i` (`scatter`, with roughness
    /// giving `var_h = var(Δh_i)`) towards `next` (`x_{i+1}`). Forms `A_i, B_i, C_i` from the
    /// stored `x_{i−1}, x_i` and `next`, applies [`step`](Self::step), and returns
    /// `var(Δx_{i+1})` in `next`'s tangent frame.
    pub fn advance(&mut self, next: &Vertex, scatter: Scatter, var_h: DMat2) -> DMat2 {
        let next_local = next.local();
        let d = constraint_derivatives_from(
            self.prev_p,
            &self.prev_tangent_map,
            &self.cur,
            &self.cur_local,
            next,
            &next_local,
            scatter,
        );
        let v = self.step(&d, var_h);
        self.prev_p = self.cur.p;
        self.prev_tangent_map = self.cur_local.tangent_map;
        self.cur = *next;
        self.cur_local = next_local;
        v
    }

    fn lose(&mut self) -> DMat2 {
        let max = DMat2::from_diagonal(DVec2::splat(MAX_VARIANCE));
        self.var_pp = self.var_p;
        self.var_p = max;
        self.cov_p_pp = DMat2::ZERO;
        max
    }

    /// `var(Δx_i)` of the current vertex.
    pub fn var_current(&self) -> DMat2 {
        self.var_p
    }

    /// `var(Δx_{i−1})` of the previous vertex.
    pub fn var_previous(&self) -> DMat2 {
        self.var_pp
    }

    /// `cov(Δx_i, Δx_{i−1})`.
    pub fn cov_current_previous(&self) -> DMat2 {
        self.cov_p_pp
    }

    /// The current vertex `x_i` (vertex mode; a point at the origin in matrix mode).
    pub fn current_vertex(&self) -> &Vertex {
        &self.cur
    }

    /// The current vertex's [`LocalGeometry`] (its uv Jacobian gives the texture footprint
    /// there, [`crate::uv_covariance_with`]).
    pub fn current_local(&self) -> &LocalGeometry {
        &self.cur_local
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An isotropic var(Δh) within bounds is what the clamp would give, bit for bit (the
    /// tracker skips the clamp for it), at every roughness `half_vector_variance` makes.
    #[test]
    fn isotropic_roughness_is_its_own_clamp() {
        for k in 0..=2000 {
            let alpha = k as f64 / 1000.0;
            let v = crate::half_vector_variance(alpha);
            let c = clamp_covariance(v, MAX_VARIANCE);
            assert!(!c.clamped_above);
            assert_eq!(c.cov.to_cols_array().map(f64::to_bits), v.to_cols_array().map(f64::to_bits), "α {alpha}");
        }
        for x in [0.0, 1e-300, 1e-12, 0.3, 1e15, MAX_VARIANCE] {
            let v = DMat2::from_diagonal(DVec2::splat(x));
            assert_eq!(clamp_covariance(v, MAX_VARIANCE).cov, v);
        }
    }

    /// The camera's tangent map the tracker starts from is the one `Vertex::point` describes.
    #[test]
    fn camera_tangent_map_is_the_points() {
        for c in [DVec3::ZERO, DVec3::new(3.0, -2.0, 7.5)] {
            assert_eq!(Vertex::point(c).local().tangent_map, POINT_TANGENT_MAP);
        }
    }
}
