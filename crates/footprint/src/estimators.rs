//! Comparison estimators for `--footprint raycone|pbrt`: simple, documented re-implementations
//! with the same per-bounce shape as [`crate::FootprintTracker`]. Both ignore roughness; both
//! return tangent-plane covariances so that [`crate::VertexFootprint`] and [`crate::lod`] apply as
//! for the covariance tracker.

use glam::{DMat2, DVec2, DVec3};

use crate::camera::{transfer, PIXEL_SIGMA};
use crate::constraint::effective_eta;
use crate::mat::clamp_covariance;
use crate::vertex::{orthonormal_basis, Scatter, Vertex};
use crate::{MAX_VARIANCE, MIN_COSINE};

/// The angle one pixel subtends at the centre of a pinhole camera with vertical field of view
/// `vertical_fov` (radians) and `image_height` pixels: `atan(2 tan(fov/2) / height)`.
pub fn pixel_spread_angle(vertical_fov: f64, image_height: u32) -> f64 {
    (2.0 * (0.5 * vertical_fov).tan() / image_height.max(1) as f64).atan()
}

/// `σ² M Mᵀ`, `M = [m0 m1]` (2×2 columns), clamped.
fn covariance_of_columns(m0: DVec2, m1: DVec2, sigma: f64) -> DMat2 {
    let m = DMat2::from_cols(m0, m1);
    clamp_covariance(m * m.transpose() * (sigma * sigma), MAX_VARIANCE).cov
}

fn to_tangent(v: &Vertex, d: DVec3) -> DVec2 {
    DVec2::new(v.t.dot(d), v.b.dot(d))
}

fn cos_floor(c: f64) -> f64 {
    if c.abs() >= MIN_COSINE {
        c
    } else {
        MIN_COSINE.copysign(c)
    }
}

/// Ray cones (Akenine-Möller et al., "Improved Shader and Texture Level of Detail Using Ray
/// Cones", JCGT 2021), isotropic, with roughness ignored.
///
/// State: the cone's (signed) width `w` and full spread angle `γ`, plus the ray. At the camera
/// `w = 0` and `γ` is the angle of one pixel ([`pixel_spread_angle`]). Per bounce:
/// - [`advance`](Self::advance): `w ← w + γ d` over the distance `d` to the hit;
/// - [`scatter`](Self::scatter): with `κ` the mean curvature `½ tr W` for the normal facing the
///   incoming ray and `Δφ = κ w / |cos θ|` the change of normal across the footprint (the
///   paper's arc-length approximation), reflection: `γ ← γ + 2Δφ`; refraction with
///   `eta = η_o/η_i`: `γ ← γ / eta − (1 − 1/eta) Δφ` (first-order Snell at normal incidence).
///   Every event is treated as its specular counterpart.
///
/// Footprint: the cone's cross-section is taken as an isotropic Gaussian with `σ = |w|/2` (so a
/// cone one pixel wide matches the ½-pixel pixel filter of [`crate::first_vertex_variance`]),
/// projected along the ray onto the tangent plane (`|cos θ| ≥ MIN_COSINE`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayCone {
    origin: DVec3,
    dir: DVec3,
    /// Signed cone width at the last hit (negative after the cone has passed a focus).
    pub width: f64,
    /// Full spread angle (radians; negative for a converging cone).
    pub spread: f64,
}

impl RayCone {
    /// A cone leaving a pinhole camera at `camera_origin` along `dir` with `w = 0`, `γ = pixel_spread`.
    pub fn new(camera_origin: DVec3, dir: DVec3, pixel_spread: f64) -> Self {
        RayCone { origin: camera_origin, dir: dir.normalize_or(DVec3::Z), width: 0.0, spread: pixel_spread }
    }

    /// Propagates the cone to `hit` and returns the footprint there.
    pub fn advance(&mut self, hit: &Vertex) -> DMat2 {
        let d = (hit.p - self.origin).length();
        self.width += self.spread * d;
        self.footprint(hit)
    }

    /// The footprint (tangent-plane covariance) of the cone at `hit` for its current width.
    pub fn footprint(&self, hit: &Vertex) -> DMat2 {
        let g = hit.local().geometric_normal(hit.n);
        let (e1, e2) = orthonormal_basis(self.dir);
        // Project the cross-section along the ray onto the tangent plane.
        let m0 = to_tangent(hit, transfer(e1, self.dir, DVec3::ZERO, 0.0, g));
        let m1 = to_tangent(hit, transfer(e2, self.dir, DVec3::ZERO, 0.0, g));
        covariance_of_columns(m0, m1, 0.5 * self.width.abs())
    }

    /// Changes the spread for the event at `hit` and continues along `new_dir`.
    pub fn scatter(&mut self, hit: &Vertex, new_dir: DVec3, scatter: Scatter) {
        let l = hit.local();
        let mut kappa = 0.5 * (l.shape.x_axis.x + l.shape.y_axis.y);
        if self.dir.dot(hit.n) > 0.0 {
            kappa = -kappa; // curvature seen from the side the ray arrives from
        }
        let cos = cos_floor(self.dir.dot(l.geometric_normal(hit.n))).abs();
        let dphi = kappa * self.width / cos;
        self.spread = match scatter {
            Scatter::Reflection => self.spread + 2.0 * dphi,
            Scatter::Refraction { eta } => {
                let e = effective_eta(eta);
                self.spread / e - (1.0 - 1.0 / e) * dphi
            }
        };
        if !self.spread.is_finite() || !self.width.is_finite() {
            self.spread = 0.0;
            self.width = MAX_VARIANCE.sqrt();
        }
        self.origin = hit.p;
        self.dir = new_dir.normalize_or(self.dir);
    }
}

/// A pbrt-v4-style estimator: ray differentials (Igehy 1999) propagated through specular
/// bounces; once a non-specular bounce drops them, every later hit approximates them as pbrt-v4's
/// `Camera::Approximate_dp_dxy` does — as if the hit were seen directly from the camera origin
/// by a ray whose direction differentials have the magnitude `pixel_spread` (pbrt uses the
/// smallest camera differential over the image; for a pinhole camera that is about one pixel's
/// angle at the image centre), intersected with the hit's tangent plane.
///
/// Footprint: `¼ (dpdx dpdxᵀ + dpdy dpdyᵀ)` in the tangent frame, i.e. the same ½-pixel pixel
/// filter as [`crate::first_vertex_variance`]; with α = 0 paths it agrees with the tracker.
/// `scale` multiplies all differentials (pbrt-v4 uses `max(⅛, 1/√spp)`; 1 disables it).
///
/// Differentials are dropped (as in pbrt-v4) when they become huge (`|·|² > 1e16`), non-finite,
/// or at total internal reflection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PbrtDifferentials {
    camera_origin: DVec3,
    pixel_spread: f64,
    scale: f64,
    origin: DVec3,
    dir: DVec3,
    d_origin: [DVec3; 2],
    d_dir: [DVec3; 2],
    has_differentials: bool,
    dp: [DVec3; 2],
}

impl PbrtDifferentials {
    /// Starts at a pinhole camera. `dir` and `d_dir_dpx`, `d_dir_dpy` follow the conventions of
    /// [`crate::first_vertex_jacobian`] (either both unnormalised or both normalised).
    pub fn new(
        camera_origin: DVec3,
        dir: DVec3,
        d_dir_dpx: DVec3,
        d_dir_dpy: DVec3,
        pixel_spread: f64,
        scale: f64,
    ) -> Self {
        let len = dir.length();
        let d = dir.normalize_or(DVec3::Z);
        // Derivative of the normalised direction.
        let nd = |dd: DVec3| (dd - d * d.dot(dd)) / len * scale;
        let mut s = PbrtDifferentials {
            camera_origin,
            pixel_spread,
            scale,
            origin: camera_origin,
            dir: d,
            d_origin: [DVec3::ZERO; 2],
            d_dir: [nd(d_dir_dpx), nd(d_dir_dpy)],
            has_differentials: true,
            dp: [DVec3::ZERO; 2],
        };
        s.check();
        s
    }

    /// Whether true ray differentials are still carried (no non-specular bounce yet).
    pub fn has_differentials(&self) -> bool {
        self.has_differentials
    }

    /// `(∂p/∂x, ∂p/∂y)` at the last hit (world space, per pixel, scaled).
    pub fn dp_dxy(&self) -> (DVec3, DVec3) {
        (self.dp[0], self.dp[1])
    }

    /// Moves to `hit`: transfers the differentials onto its tangent plane (or approximates them
    /// from the camera) and returns the footprint there.
    pub fn advance(&mut self, hit: &Vertex) -> DMat2 {
        let g = hit.local().geometric_normal(hit.n);
        if self.has_differentials {
            let s = (hit.p - self.origin).dot(self.dir);
            for k in 0..2 {
                self.dp[k] = transfer(self.d_origin[k], self.dir, self.d_dir[k], s, g);
            }
        } else {
            let to_p = hit.p - self.camera_origin;
            let dist = to_p.length();
            let d = to_p.normalize_or(DVec3::Z);
            let (e1, e2) = orthonormal_basis(d);
            let k = self.pixel_spread * self.scale;
            self.dp[0] = transfer(DVec3::ZERO, d, e1 * k, dist, g);
            self.dp[1] = transfer(DVec3::ZERO, d, e2 * k, dist, g);
        }
        if !self.dp[0].is_finite() || !self.dp[1].is_finite() {
            self.dp = [DVec3::X * MAX_VARIANCE.sqrt(), DVec3::Y * MAX_VARIANCE.sqrt()];
        }
        covariance_of_columns(to_tangent(hit, self.dp[0]), to_tangent(hit, self.dp[1]), PIXEL_SIGMA)
    }

    /// A specular event at `hit` (after [`advance`](Self::advance) to it): the direction
    /// differentials follow the law of reflection or Snell's law about the shading normal, whose
    /// change comes from the surface's shape operator; the ray continues along `new_dir`.
    pub fn scatter_specular(&mut self, hit: &Vertex, new_dir: DVec3, scatter: Scatter) {
        if self.has_differentials {
            let w = hit.local().shape;
            let d = self.dir;
            for k in 0..2 {
                let dx = to_tangent(hit, self.dp[k]);
                let wx = w * dx;
                let dn = hit.t * wx.x + hit.b * wx.y;
                let dd = self.d_dir[k];
                self.d_dir[k] = match scatter {
                    Scatter::Reflection => {
                        let n = hit.n;
                        dd - 2.0 * (dn * d.dot(n) + n * (dd.dot(n) + d.dot(dn)))
                    }
                    Scatter::Refraction { eta } => {
                        // ω_t = r d + μ n_f with n_f facing the incoming ray, r = 1/eta,
                        // c₁ = −d·n_f, c₂ = √(1 − r²(1 − c₁²)), μ = r c₁ − c₂.
                        let (n, dn) = if d.dot(hit.n) > 0.0 { (-hit.n, -dn) } else { (hit.n, dn) };
                        let r = 1.0 / effective_eta(eta);
                        let c1 = -d.dot(n);
                        let c2sq = 1.0 - r * r * (1.0 - c1 * c1);
                        if c2sq <= 0.0 {
                            self.has_differentials = false;
                            break;
                        }
                        let c2 = c2sq.sqrt();
                        let mu = r * c1 - c2;
                        let dc1 = -(dd.dot(n) + d.dot(dn));
                        let dc2 = r * r * c1 * dc1 / c2;
                        let dmu = r * dc1 - dc2;
                        dd * r + dn * mu + n * dmu
                    }
                };
                self.d_origin[k] = self.dp[k];
            }
        }
        self.origin = hit.p;
        self.dir = new_dir.normalize_or(self.dir);
        self.check();
    }

    /// A non-specular event at `hit`: the differentials are dropped (later hits use the camera
    /// approximation); the ray continues along `new_dir`.
    pub fn scatter_rough(&mut self, hit: &Vertex, new_dir: DVec3) {
        self.has_differentials = false;
        self.origin = hit.p;
        self.dir = new_dir.normalize_or(self.dir);
    }

    fn check(&mut self) {
        let big = |v: DVec3| !v.is_finite() || v.length_squared() > 1e16;
        if big(self.d_dir[0]) || big(self.d_dir[1]) || big(self.d_origin[0]) || big(self.d_origin[1]) {
            self.has_differentials = false;
        }
    }
}
