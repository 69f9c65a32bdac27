//! Mitsuba's `perspective` sensor and the pixel reconstruction filters.

use crate::geometry::Ray;
use glam::{Affine3A, Vec2, Vec3};

/// Which image axis `fov` spans (Mitsuba's `fov_axis`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FovAxis {
    /// Horizontal (Mitsuba's default).
    X,
    /// Vertical.
    Y,
    /// The diagonal.
    Diagonal,
    /// The shorter image side.
    Smaller,
    /// The longer image side.
    Larger,
}

/// A pinhole camera looking along its local +z, local +x pointing to the image's left.
#[derive(Clone, Debug)]
pub struct Camera {
    origin: Vec3,
    /// Local axes in world space: x (left), y (up), z (forward), unit length.
    axes: [Vec3; 3],
    tan_half_x: f32,
    tan_half_y: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    near: f32,
    far: f32,
}

/// A primary ray and its differentials: how the unnormalised direction (local z = 1 scaled to
/// unit forward) changes per pixel along x and y.
#[derive(Clone, Copy, Debug)]
pub struct CameraRay {
    /// The ray, unit direction.
    pub ray: Ray,
    /// ∂d/∂x of the unnormalised direction `d` (forward component 1) per pixel.
    pub dd_dx: Vec3,
    /// ∂d/∂y per pixel.
    pub dd_dy: Vec3,
    /// The unnormalised direction itself.
    pub d_unnormalised: Vec3,
    /// The film position's offset from its pixel's centre, in pixels (set by
    /// [`crate::integrator::camera_sample`]; zero from [`Camera::generate_ray`]).
    pub film_offset: Vec2,
}

impl Camera {
    /// A camera from Mitsuba's parameters; `fov_deg` in degrees along `axis`.
    pub fn new(to_world: Affine3A, fov_deg: f32, axis: FovAxis, width: u32, height: u32, near: f32, far: f32) -> Self {
        let (w, h) = (width as f32, height as f32);
        let aspect = w / h;
        let t = (fov_deg.to_radians() * 0.5).tan();
        let tan_half_x = match axis {
            FovAxis::X => t,
            FovAxis::Y => t * aspect,
            FovAxis::Diagonal => t * aspect / (1.0 + aspect * aspect).sqrt(),
            FovAxis::Smaller => {
                if aspect > 1.0 {
                    t * aspect
                } else {
                    t
                }
            }
            FovAxis::Larger => {
                if aspect > 1.0 {
                    t
                } else {
                    t * aspect
                }
            }
        };
        let axes = [
            to_world.transform_vector3(Vec3::X).normalize(),
            to_world.transform_vector3(Vec3::Y).normalize(),
            to_world.transform_vector3(Vec3::Z).normalize(),
        ];
        Camera {
            origin: to_world.transform_point3(Vec3::ZERO),
            axes,
            tan_half_x,
            tan_half_y: tan_half_x / aspect,
            width,
            height,
            near,
            far,
        }
    }

    /// Angle subtended by one pixel at the image centre, vertically (for ray cones).
    pub fn pixel_spread_angle(&self) -> f64 {
        footprint::pixel_spread_angle(2.0 * (self.tan_half_y as f64).atan(), self.height)
    }

    /// Camera position.
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// The ray through continuous film position `film` (pixels, (0, 0) top-left corner).
    pub fn generate_ray(&self, film: Vec2) -> CameraRay {
        let sx = film.x / self.width as f32;
        let sy = film.y / self.height as f32;
        let local = Vec3::new((1.0 - 2.0 * sx) * self.tan_half_x, (1.0 - 2.0 * sy) * self.tan_half_y, 1.0);
        let d = self.axes[0] * local.x + self.axes[1] * local.y + self.axes[2];
        let inv_len = 1.0 / d.length();
        let dir = d * inv_len;
        let dd_dx = self.axes[0] * (-2.0 * self.tan_half_x / self.width as f32);
        let dd_dy = self.axes[1] * (-2.0 * self.tan_half_y / self.height as f32);
        // Clip planes are distances along the optical axis, as in Mitsuba.
        let ray = Ray { o: self.origin, d: dir, tmin: self.near / inv_len, tmax: self.far / inv_len };
        CameraRay { ray, dd_dx, dd_dy, d_unnormalised: d, film_offset: Vec2::ZERO }
    }

    /// Projects a world point to continuous film coordinates, if in front of the camera.
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        let v = p - self.origin;
        let z = v.dot(self.axes[2]);
        if z <= 0.0 {
            return None;
        }
        let x = v.dot(self.axes[0]) / z;
        let y = v.dot(self.axes[1]) / z;
        let sx = (1.0 - x / self.tan_half_x) * 0.5;
        let sy = (1.0 - y / self.tan_half_y) * 0.5;
        Some(Vec2::new(sx * self.width as f32, sy * self.height as f32))
    }
}

/// Pixel reconstruction filter, sampled by filter importance sampling: each camera sample of a
/// pixel is offset from the pixel centre with the filter's density, so every pixel is a plain
/// mean of its own samples (deterministic under any tiling) and has the same expectation as
/// Mitsuba's weighted splatting.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rfilter {
    /// Box of width 1 pixel.
    Box,
    /// Gaussian with standard deviation `stddev`, truncated at 4σ (Mitsuba's default, σ = ½).
    Gaussian {
        /// Standard deviation in pixels.
        stddev: f32,
    },
    /// Tent of radius `radius` pixels.
    Tent {
        /// Half-width in pixels.
        radius: f32,
    },
}

impl Rfilter {
    /// An offset from the pixel centre distributed as the filter when `u` is uniform on the unit
    /// square: each axis is warped separately by the inverse of the filter's 1D distribution,
    /// monotonically, so a well-spread set of `u` (see [`crate::sampling::pixel_sample`]) gives
    /// offsets that cover the filter as evenly. The Gaussian is truncated to ±4σ per axis, as
    /// Mitsuba's is.
    pub fn warp(&self, u: Vec2) -> Vec2 {
        match *self {
            Rfilter::Box => u - Vec2::splat(0.5),
            Rfilter::Tent { radius } => {
                let tent = |u: f32| {
                    if u < 0.5 {
                        -1.0 + (2.0 * u).sqrt()
                    } else {
                        1.0 - (2.0 - 2.0 * u).sqrt()
                    }
                };
                Vec2::new(tent(u.x), tent(u.y)) * radius
            }
            Rfilter::Gaussian { stddev } => {
                Vec2::new(truncated_normal_quantile(u.x as f64), truncated_normal_quantile(u.y as f64)) * stddev
            }
        }
    }
}

/// The `u`-quantile of the standard normal truncated to [−4, 4], as `f32`: see
/// [`truncated_normal_quantile_f64`].
fn truncated_normal_quantile(u: f64) -> f32 {
    truncated_normal_quantile_f64(u) as f32
}

/// The truncation of the Gaussian pixel filter, in standard deviations.
const QUANTILE_EDGE: f64 = 4.0;
/// Nodes of the tail table of [`quantile_tables`].
const QUANTILE_TABLE: usize = 256;

/// The `u`-quantile of the standard normal truncated to [−4, 4].
///
/// With `q = min(p, 1 − p)`: where `q ≥ 0.05` the lower quantile is read from a table in `q`.
/// In the tails, Abramowitz and Stegun's rational approximation (26.2.23) gives it as a function
/// of `t = √(−2 ln q)` to within 4.5·10⁻⁴, and its error, a smooth function of `t` on the `t`
/// the truncation leaves, is read from a second table and added back. Both tables are built
/// once ([`quantile_tables`]); a sample axis costs no `erfc` or `exp`, and a `ln` in one case in
/// ten. The result is within 10⁻⁹ of the exact quantile (the tests check it against bisection),
/// far below the `f32` the warp hands on.
fn truncated_normal_quantile_f64(u: f64) -> f64 {
    let (lo, tables) = quantile_tables();
    let p = lo + u.clamp(0.0, 1.0) * (1.0 - 2.0 * lo);
    let q = p.min(1.0 - p);
    let z = if q >= QUANTILE_CENTRAL {
        // Nine samples in ten: the quantile itself, tabulated in q, without the logarithm.
        tables.central.at(0.5 - q)
    } else {
        let t = (-2.0 * q.ln()).sqrt();
        -abramowitz_stegun(t) + tables.tail.at(t)
    };
    (if p < 0.5 { z } else { -z }).clamp(-QUANTILE_EDGE, QUANTILE_EDGE)
}

/// Tail mass below which [`truncated_normal_quantile_f64`] goes through `t = √(−2 ln q)`; above,
/// it reads the lower quantile from a table in `q` (1024 Hermite nodes on `[0.05, 0.5]`, whose
/// error there is below 5·10⁻¹¹).
const QUANTILE_CENTRAL: f64 = 0.05;

/// Abramowitz and Stegun's 26.2.23: the upper quantile of the standard normal at tail mass `q`
/// from `t = √(−2 ln q)`, to within 4.5·10⁻⁴.
#[inline]
fn abramowitz_stegun(t: f64) -> f64 {
    t - (2.515517 + t * (0.802853 + t * 0.010328)) / (1.0 + t * (1.432788 + t * (0.189269 + t * 0.001308)))
}

/// A function at evenly spaced arguments from `t0`, with its slope: cubic Hermite between them.
struct HermiteTable {
    t0: f64,
    inv_h: f64,
    /// Per node: the value and its slope times the spacing.
    e: Vec<(f64, f64)>,
}

/// [`truncated_normal_quantile_f64`]'s tables: the exact lower quantile against `½ − q` near the
/// centre, and the error of [`abramowitz_stegun`] (exact lower quantile minus its negation)
/// against `t` from `t(½)` to `t(Φ(−4))` in the tails.
struct QuantileTables {
    central: HermiteTable,
    tail: HermiteTable,
}

impl HermiteTable {
    /// Samples `f` (value and derivative) at `n` nodes evenly spaced on `[a, b]`.
    fn new(a: f64, b: f64, n: usize, f: impl Fn(f64) -> (f64, f64)) -> HermiteTable {
        let h = (b - a) / (n - 1) as f64;
        let e = (0..n)
            .map(|k| {
                let (v, d) = f(a + k as f64 * h);
                (v, h * d)
            })
            .collect();
        HermiteTable { t0: a, inv_h: 1.0 / h, e }
    }

    #[inline]
    fn at(&self, t: f64) -> f64 {
        let x = ((t - self.t0) * self.inv_h).max(0.0);
        let i = (x as usize).min(self.e.len() - 2);
        let f = (x - i as f64).min(1.0);
        let ((e0, d0), (e1, d1)) = (self.e[i], self.e[i + 1]);
        let (f2, f3) = (f * f, f * f * f);
        (2.0 * f3 - 3.0 * f2 + 1.0) * e0 + (f3 - 2.0 * f2 + f) * d0 + (3.0 * f2 - 2.0 * f3) * e1 + (f3 - f2) * d1
    }
}

/// The truncation's tail mass `Φ(−4)` and the quantile's tables, built on first use (about 1300
/// exact quantiles).
fn quantile_tables() -> (f64, &'static QuantileTables) {
    use graph::gaussian::{cdf, pdf};
    use std::sync::OnceLock;
    static TABLES: OnceLock<(f64, QuantileTables)> = OnceLock::new();
    // The exact lower quantile of q: Newton on Φ from the approximation, to round-off.
    let exact = |q: f64, t: f64| {
        let mut z = -abramowitz_stegun(t);
        for _ in 0..4 {
            z -= (cdf(z) - q) / pdf(z);
        }
        z
    };
    let (lo, tables) = TABLES.get_or_init(|| {
        let lo = cdf(-QUANTILE_EDGE);
        let (t0, t1) = ((2.0 * 2f64.ln()).sqrt(), (-2.0 * lo.ln()).sqrt());
        let tail = HermiteTable::new(t0, t1, QUANTILE_TABLE, |t| {
            let q = (-0.5 * t * t).exp();
            let z = exact(q, t);
            // Its slope from Φ(z(t)) = e^{−t²/2}: φ(z) z′ = −t q; the approximation's by a
            // central difference (its third derivative is small: error below 1e-12).
            let dz = -t * q / pdf(z);
            let d = 1e-5;
            let das = (abramowitz_stegun(t + d) - abramowitz_stegun(t - d)) / (2.0 * d);
            (z + abramowitz_stegun(t), dz + das)
        });
        // In x = ½ − q: z(x) is the lower quantile of q, dz/dx = −1/φ(z).
        let central = HermiteTable::new(0.0, 0.5 - QUANTILE_CENTRAL, 1024, |x| {
            let q = 0.5 - x;
            let z = if x == 0.0 { 0.0 } else { exact(q, (-2.0 * q.ln()).sqrt()) };
            (z, -1.0 / pdf(z))
        });
        (lo, QuantileTables { central, tail })
    });
    (*lo, tables)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;

    fn lookat(origin: Vec3, target: Vec3, up: Vec3) -> Affine3A {
        let dir = (target - origin).normalize();
        let left = up.cross(dir).normalize();
        let new_up = dir.cross(left);
        Affine3A::from_cols(left.into(), new_up.into(), dir.into(), origin.into())
    }

    #[test]
    fn image_x_runs_to_the_cameras_right_and_row_zero_is_up() {
        let cam =
            Camera::new(lookat(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 40.0, FovAxis::X, 200, 100, 0.01, 1e4);
        // Looking down -z with y up, the camera's right is world +x.
        let right = cam.generate_ray(Vec2::new(199.0, 50.0)).ray.d;
        assert!(right.x > 0.0);
        let top = cam.generate_ray(Vec2::new(100.0, 0.0)).ray.d;
        assert!(top.y > 0.0);
        // Horizontal field of view is 40°.
        let l = cam.generate_ray(Vec2::new(0.0, 50.0)).ray.d;
        let r = cam.generate_ray(Vec2::new(200.0, 50.0)).ray.d;
        assert!((l.angle_between(r).to_degrees() - 40.0).abs() < 1e-3);
        // Projection inverts ray generation.
        let p = cam.generate_ray(Vec2::new(37.5, 81.25)).ray.at(3.0);
        assert!((cam.project(p).unwrap() - Vec2::new(37.5, 81.25)).length() < 1e-3);
    }

    #[test]
    fn differentials_match_finite_differences() {
        let cam =
            Camera::new(lookat(Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO, Vec3::Y), 50.0, FovAxis::Y, 64, 48, 0.01, 1e4);
        let a = cam.generate_ray(Vec2::new(10.0, 20.0));
        let b = cam.generate_ray(Vec2::new(11.0, 20.0));
        let c = cam.generate_ray(Vec2::new(10.0, 21.0));
        assert!((b.d_unnormalised - a.d_unnormalised - a.dd_dx).length() < 1e-5);
        assert!((c.d_unnormalised - a.d_unnormalised - a.dd_dy).length() < 1e-5);
    }

    /// The quantile against bisection on Φ (60 halvings of [−4, 4]: exact to round-off), on a
    /// grid dense at the ends where the quantile is steepest.
    #[test]
    fn gaussian_quantile_matches_bisection() {
        use graph::gaussian::cdf;
        let lo = cdf(-4.0);
        let mut worst: f64 = 0.0;
        for i in 0..=4000 {
            let v = i as f64 / 4000.0;
            for u in [v, v.powi(6), 1.0 - v.powi(6)] {
                let p = lo + u * (1.0 - 2.0 * lo);
                let (mut a, mut b) = (-4.0f64, 4.0f64);
                for _ in 0..60 {
                    let m = 0.5 * (a + b);
                    if cdf(m) < p {
                        a = m;
                    } else {
                        b = m;
                    }
                }
                let err = (truncated_normal_quantile_f64(u) - 0.5 * (a + b)).abs();
                worst = worst.max(err);
                assert!(err < 1e-9, "u {u}: {} against {}", truncated_normal_quantile_f64(u), 0.5 * (a + b));
            }
        }
        eprintln!("largest error against bisection: {worst:.1e}");
    }

    #[test]
    fn gaussian_warp_inverts_the_truncated_normal_and_is_monotone() {
        use graph::gaussian::cdf;
        let lo = cdf(-4.0);
        let mut last = f32::NEG_INFINITY;
        for i in 0..=20_000 {
            let u = i as f64 / 20_000.0;
            let z = truncated_normal_quantile(u);
            assert!(z >= last && (-4.0..=4.0).contains(&z), "u {u}: {z} after {last}");
            last = z;
            // Φ of the quantile gives u back (to the f32 rounding of z).
            let back = (cdf(z as f64) - lo) / (1.0 - 2.0 * lo);
            assert!((back - u).abs() < 2e-7, "u {u}: z {z} gives {back}");
        }
        assert!(truncated_normal_quantile(0.5).abs() < 1e-9);
        let g = Rfilter::Gaussian { stddev: 0.5 };
        assert_eq!(g.warp(Vec2::new(0.0, 1.0)), Vec2::new(-2.0, 2.0));
    }

    #[test]
    fn filters_have_their_variance() {
        let mut rng = Rng::new(1, 2);
        for (f, var) in [
            (Rfilter::Box, 1.0 / 12.0),
            (Rfilter::Tent { radius: 1.0 }, 1.0 / 6.0),
            (Rfilter::Gaussian { stddev: 0.5 }, 0.25),
        ] {
            let n = 200_000;
            let m: f64 =
                (0..n).map(|_| (f.warp(Vec2::new(rng.next_f32(), rng.next_f32())).x as f64).powi(2)).sum::<f64>()
                    / n as f64;
            assert!((m - var).abs() < 0.01 * var.max(0.1) + 0.002, "{f:?}: {m} vs {var}");
        }
    }
}
