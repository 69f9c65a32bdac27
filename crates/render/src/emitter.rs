//! Emitters of the Mitsuba subset: `area`, `point`, `constant`, `envmap`, `directional`.
//!
//! Each can be sampled from a reference point (next-event estimation) and, where it is not a
//! delta light, report the solid-angle density of that sampling for multiple importance sampling.
//!
//! # Scene parameters
//!
//! The scene loader ([`crate::loader`]) builds an [`Emitter`] from each `<emitter>` element and
//! reads the parameters listed below. In these tables a `spectrum` is an `<rgb>`, a
//! `<spectrum>` with a single value, or a `<float>` (used for all three channels); it must be
//! finite and non-negative, or the scene fails to load. No emitter parameter accepts a
//! `<texture>`. Any parameter or nested object that an emitter does not read is reported as
//! unused at its line and stops the load, and an emitter type other than these five is an error
//! that names the supported ones. A scene without any emitter still loads, with a warning that
//! the image will be black.
//!
//! ## `area`
//!
//! Makes the shape it is nested in a light. It is accepted only inside a `<shape>`, one per
//! shape; at the top level of the scene it is an error:
//! `an area emitter must be nested in a <shape>`.
//!
//! | parameter  | type     | default | meaning                                                  |
//! |------------|----------|---------|----------------------------------------------------------|
//! | `radiance` | spectrum | 1       | emitted radiance, the same at every point and direction  |
//!
//! Light leaves only the side that the shape's shading normal faces; the shape's
//! `flip_normals` moves it to the other side. A `sphere` without `flip_normals` is sampled over
//! the cone of directions it covers as seen from the reference point; every other shape, and a
//! flipped sphere, is sampled uniformly by area.
//!
//! ```xml
//! <shape type="rectangle">
//!     <transform name="to_world">
//!         <rotate x="1" angle="90"/>
//!         <translate y="2"/>
//!     </transform>
//!     <emitter type="area">
//!         <rgb name="radiance" value="10, 9, 8"/>
//!     </emitter>
//! </shape>
//! ```
//!
//! ## `point`
//!
//! An isotropic point light. Rays cannot hit it; the value it delivers to a point at distance
//! `d` is `intensity / d²`.
//!
//! | parameter   | type      | default   | meaning                                            |
//! |-------------|-----------|-----------|----------------------------------------------------|
//! | `position`  | point     | (0, 0, 0) | where the light is (a `<vector>` is accepted too)  |
//! | `to_world`  | transform | none      | when given, applied to `position`                  |
//! | `intensity` | spectrum  | 1         | radiant intensity (W/sr)                           |
//!
//! With only `to_world`, the light sits at that transform's translation, as it moves the
//! default position, the origin.
//!
//! ```xml
//! <emitter type="point">
//!     <point name="position" x="0" y="4" z="1"/>
//!     <spectrum name="intensity" value="50"/>
//! </emitter>
//! ```
//!
//! ## `constant`
//!
//! Uniform radiance arriving from every direction at infinity; rays that leave the scene see
//! it. It is sampled uniformly over the sphere of directions. It reads no `to_world`.
//!
//! | parameter  | type     | default | meaning                                 |
//! |------------|----------|---------|-----------------------------------------|
//! | `radiance` | spectrum | 1       | radiance arriving from every direction  |
//!
//! ```xml
//! <emitter type="constant">
//!     <rgb name="radiance" value="0.6, 0.7, 1.0"/>
//! </emitter>
//! ```
//!
//! ## `envmap`
//!
//! A latitude-longitude image at infinity ([`EnvMap`]); rays that leave the scene see it.
//!
//! | parameter  | type      | default  | meaning                                             |
//! |------------|-----------|----------|-----------------------------------------------------|
//! | `filename` | string    | required | the image, relative to the scene file's folder      |
//! | `scale`    | float     | 1        | multiplier of the image's values (0 is allowed)     |
//! | `to_world` | transform | identity | orientation of the map                              |
//!
//! The image may be `.exr` (read as linear RGB; alpha is ignored) or `.png`, `.jpg`, `.jpeg`
//! (decoded from sRGB to linear); other extensions are an error. In the map's own frame the top
//! row of the image looks along +y and the bottom row along −y; the centre column looks along
//! +z, the column a quarter of the way from the left along +x, and the left and right edges
//! along −z. Lookups are bilinear with the `repeat` wrap mode. `to_world` should be a
//! rotation: its columns are normalised, which removes any scale, and its translation is
//! ignored.
//!
//! Directions are importance-sampled in proportion to luminance times `sin θ`. Each texel is
//! weighted by the largest luminance in a small neighbourhood around it, so that no direction
//! that receives radiance through a bilinear lookup has zero density. Errors: no `filename`
//! ("envmap needs a 'filename'"), a file that does not exist, an image with NaN or infinite
//! values, a negative or non-finite `scale`, and an image whose luminance is nowhere positive
//! ("envmap image is black everywhere").
//!
//! ```xml
//! <emitter type="envmap">
//!     <string name="filename" value="textures/sky.exr"/>
//!     <float name="scale" value="1.5"/>
//!     <transform name="to_world">
//!         <rotate y="1" angle="30"/>
//!     </transform>
//! </emitter>
//! ```
//!
//! ## `directional`
//!
//! Parallel light from infinitely far away, such as the sun. Like `point`, it is a delta light
//! that rays cannot hit.
//!
//! | parameter    | type      | default   | meaning                                           |
//! |--------------|-----------|-----------|---------------------------------------------------|
//! | `direction`  | vector    | (0, 0, 1) | direction of travel (a `<point>` is accepted too) |
//! | `to_world`   | transform | none      | when given, its linear part acts on `direction`   |
//! | `irradiance` | spectrum  | 1         | irradiance on a surface facing the light          |
//!
//! With only `to_world`, the light travels along the transform's image of +z. The direction is
//! normalised; if it is zero or not finite, that is an error ("directional emitter needs a
//! non-zero direction").
//!
//! ```xml
//! <emitter type="directional">
//!     <vector name="direction" x="-1" y="-1" z="-0.5"/>
//!     <rgb name="irradiance" value="3, 2.8, 2.5"/>
//! </emitter>
//! ```

use crate::geometry::{Shape, ShapeGeometry};
use crate::math::{luminance, Spectrum};
use crate::sampling::{self, Distribution1D};
use crate::texture::{Bitmap, WrapMode};
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::Arc;

/// A piecewise-constant 2D distribution over [0, 1)², rows then columns.
#[derive(Clone, Debug)]
pub struct Distribution2D {
    rows: Distribution1D,
    columns: Vec<Distribution1D>,
    width: usize,
    height: usize,
}

impl Distribution2D {
    /// From row-major non-negative weights; `None` when all are zero.
    pub fn new(weights: &[f32], width: usize, height: usize) -> Option<Self> {
        let uniform = vec![1.0; width];
        let mut columns = Vec::with_capacity(height);
        let mut row_w = Vec::with_capacity(height);
        for y in 0..height {
            let row = &weights[y * width..(y + 1) * width];
            let sum: f32 = row.iter().sum();
            row_w.push(sum);
            columns.push(Distribution1D::new(row).or_else(|| Distribution1D::new(&uniform))?);
        }
        Some(Distribution2D { rows: Distribution1D::new(&row_w)?, columns, width, height })
    }

    /// A point in [0, 1)² and its density.
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (y, uy) = self.rows.sample(u.y);
        let (x, ux) = self.columns[y].sample(u.x);
        let p = Vec2::new((x as f32 + ux) / self.width as f32, (y as f32 + uy) / self.height as f32);
        (p, self.pdf(p))
    }

    /// Density at a point of [0, 1)².
    pub fn pdf(&self, p: Vec2) -> f32 {
        let x = ((p.x * self.width as f32) as usize).min(self.width - 1);
        let y = ((p.y * self.height as f32) as usize).min(self.height - 1);
        self.rows.pmf(y) * self.columns[y].pmf(x) * (self.width * self.height) as f32
    }
}

/// A lat-long environment map (Mitsuba's `envmap`).
#[derive(Clone, Debug)]
pub struct EnvMap {
    /// The image (uv (0, 0) top-left, v down from the +y pole).
    pub bitmap: Arc<Bitmap>,
    /// World to the map's local frame (inverse of `to_world`'s rotation).
    pub to_local: Mat3,
    /// Map's local frame to world.
    pub to_world: Mat3,
    /// Radiance multiplier.
    pub scale: f32,
    dist: Distribution2D,
}

impl EnvMap {
    /// Builds the importance-sampling distribution (luminance × sin θ per texel).
    pub fn new(bitmap: Arc<Bitmap>, to_world: Mat3, scale: f32) -> Option<Self> {
        let (w, h) = (bitmap.width, bitmap.height);
        let mut weights = vec![0.0; w * h];
        for y in 0..h {
            let sin_theta = (PI * (y as f32 + 0.5) / h as f32).sin();
            for x in 0..w {
                // Bilinear lookups spread a texel over its neighbours: weight by the max of the
                // 2×2 neighbourhood so no direction with radiance gets zero density.
                let mut m = 0.0f32;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let xx = (x + dx) % w;
                    let yy = (y + dy).min(h - 1);
                    m = m.max(luminance(bitmap.texels[yy * w + xx]).max(0.0));
                    let xp = (x + w - dx) % w;
                    let yp = y.saturating_sub(dy);
                    m = m.max(luminance(bitmap.texels[yp * w + xp]).max(0.0));
                }
                weights[y * w + x] = m * sin_theta;
            }
        }
        let dist = Distribution2D::new(&weights, w, h)?;
        Some(EnvMap { bitmap, to_local: to_world.transpose(), to_world, scale, dist })
    }

    fn direction_to_uv(&self, d: Vec3) -> Vec2 {
        let l = self.to_local * d;
        let mut u = l.x.atan2(-l.z) * (0.5 / PI);
        if u < 0.0 {
            u += 1.0;
        }
        Vec2::new(u, l.y.clamp(-1.0, 1.0).acos() / PI)
    }

    fn uv_to_direction(&self, uv: Vec2) -> (Vec3, f32) {
        let phi = uv.x * 2.0 * PI;
        let theta = uv.y * PI;
        let (sp, cp) = phi.sin_cos();
        let (st, ct) = theta.sin_cos();
        (self.to_world * Vec3::new(sp * st, ct, -cp * st), st)
    }

    /// Radiance arriving from direction `d` (pointing away from the scene).
    pub fn eval(&self, d: Vec3) -> Spectrum {
        self.bitmap.bilinear(self.direction_to_uv(d), WrapMode::Repeat) * self.scale
    }

    fn sample(&self, u: Vec2) -> Option<(Vec3, f32)> {
        let (uv, pdf_uv) = self.dist.sample(u);
        let (d, sin_theta) = self.uv_to_direction(uv);
        if sin_theta <= 1e-6 || pdf_uv <= 0.0 {
            return None;
        }
        Some((d, pdf_uv / (2.0 * PI * PI * sin_theta)))
    }

    fn pdf(&self, d: Vec3) -> f32 {
        let uv = self.direction_to_uv(d);
        let sin_theta = (uv.y * PI).sin();
        if sin_theta <= 1e-6 {
            return 0.0;
        }
        self.dist.pdf(uv) / (2.0 * PI * PI * sin_theta)
    }
}

/// One light source.
#[derive(Clone, Debug)]
pub enum Emitter {
    /// A shape that emits `radiance` on the side its normal points to.
    Area {
        /// Index of the shape.
        shape: u32,
        /// Emitted radiance.
        radiance: Spectrum,
    },
    /// An isotropic point light (`intensity` in W/sr).
    Point {
        /// Position.
        position: Vec3,
        /// Radiant intensity.
        intensity: Spectrum,
    },
    /// Uniform radiance from every direction at infinity.
    Constant {
        /// Radiance.
        radiance: Spectrum,
    },
    /// An environment map at infinity.
    Env(Box<EnvMap>),
    /// Parallel light travelling along `direction`.
    Directional {
        /// Unit propagation direction.
        direction: Vec3,
        /// Irradiance on a surface facing the light.
        irradiance: Spectrum,
    },
}

/// A sampled direction toward an emitter.
#[derive(Clone, Copy, Debug)]
pub struct EmitterSample {
    /// Unit direction from the reference point toward the light.
    pub wi: Vec3,
    /// Distance to the light point (∞ for lights at infinity).
    pub dist: f32,
    /// Radiance (or, for delta lights, the incident radiance-like value) arriving along `wi`.
    pub value: Spectrum,
    /// Solid-angle density (1 for delta lights).
    pub pdf: f32,
    /// Point and directional lights cannot be hit by rays.
    pub delta: bool,
}

impl Emitter {
    /// True for lights infinitely far away (hit by escaping rays).
    pub fn is_infinite(&self) -> bool {
        matches!(self, Emitter::Constant { .. } | Emitter::Env(_))
    }

    /// Radiance seen along a ray escaping in direction `d` (infinite lights only).
    pub fn eval_escape(&self, d: Vec3) -> Spectrum {
        match self {
            Emitter::Constant { radiance } => *radiance,
            Emitter::Env(env) => env.eval(d),
            _ => Spectrum::ZERO,
        }
    }

    /// Samples a direction toward the light from `p`.
    pub fn sample(&self, shapes: &[Shape], p: Vec3, u: Vec2) -> Option<EmitterSample> {
        match self {
            Emitter::Area { shape, radiance } => {
                let shape = &shapes[*shape as usize];
                if let ShapeGeometry::Sphere { center, radius, .. } = &shape.geometry {
                    if !shape.flip_normals {
                        return sample_sphere_cone(*center, *radius, p, u, *radiance);
                    }
                }
                let s = shape.sample_area(u);
                let to = s.p - p;
                let dist2 = to.length_squared();
                if dist2 <= 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = to / dist;
                let cos_light = -s.n.dot(wi);
                if cos_light <= 0.0 {
                    return None;
                }
                let pdf = s.pdf_area * dist2 / cos_light;
                pdf.is_finite().then_some(EmitterSample { wi, dist, value: *radiance, pdf, delta: false })
            }
            Emitter::Point { position, intensity } => {
                let to = *position - p;
                let dist2 = to.length_squared();
                if dist2 <= 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                Some(EmitterSample { wi: to / dist, dist, value: *intensity / dist2, pdf: 1.0, delta: true })
            }
            Emitter::Constant { radiance } => {
                let wi = sampling::square_to_uniform_sphere(u);
                Some(EmitterSample {
                    wi,
                    dist: f32::INFINITY,
                    value: *radiance,
                    pdf: sampling::UNIFORM_SPHERE_PDF,
                    delta: false,
                })
            }
            Emitter::Env(env) => {
                let (wi, pdf) = env.sample(u)?;
                Some(EmitterSample { wi, dist: f32::INFINITY, value: env.eval(wi), pdf, delta: false })
            }
            Emitter::Directional { direction, irradiance } => {
                Some(EmitterSample { wi: -*direction, dist: f32::INFINITY, value: *irradiance, pdf: 1.0, delta: true })
            }
        }
    }

    /// Solid-angle density with which [`Emitter::sample`] from `p` produces the point `q`
    /// with normal `n` on an area light, or direction `d` toward an infinite light.
    pub fn pdf(&self, shapes: &[Shape], p: Vec3, q: Vec3, n: Vec3, d: Vec3) -> f32 {
        match self {
            Emitter::Area { shape, .. } => {
                let shape = &shapes[*shape as usize];
                if let ShapeGeometry::Sphere { center, radius, .. } = &shape.geometry {
                    if !shape.flip_normals {
                        return sphere_cone_pdf(*center, *radius, p, q);
                    }
                }
                let to = q - p;
                let dist2 = to.length_squared();
                let cos_light = -n.dot(to / dist2.sqrt());
                if cos_light <= 0.0 {
                    return 0.0;
                }
                dist2 / (cos_light * shape.area())
            }
            Emitter::Constant { .. } => sampling::UNIFORM_SPHERE_PDF,
            Emitter::Env(env) => env.pdf(d),
            Emitter::Point { .. } | Emitter::Directional { .. } => 0.0,
        }
    }
}

/// Uniform sampling of the cone of directions a sphere subtends (from outside), with an
/// area-sampling fallback inside it.
fn sample_sphere_cone(center: Vec3, radius: f32, p: Vec3, u: Vec2, radiance: Spectrum) -> Option<EmitterSample> {
    let to_c = center - p;
    let dc2 = to_c.length_squared();
    let r2 = radius * radius;
    if dc2 <= r2 * (1.0 + 1e-4) {
        // Inside or on the sphere: sample by area (the light faces outwards, so little arrives).
        let n = sampling::square_to_uniform_sphere(u);
        let q = center + n * radius;
        let to = q - p;
        let dist2 = to.length_squared();
        let dist = dist2.sqrt();
        let wi = to / dist;
        let cos_light = -n.dot(wi);
        if cos_light <= 0.0 || dist <= 0.0 {
            return None;
        }
        let pdf = dist2 / (cos_light * 4.0 * PI * r2);
        return Some(EmitterSample { wi, dist, value: radiance, pdf, delta: false });
    }
    let dc = dc2.sqrt();
    let sin_max2 = r2 / dc2;
    let cos_max = (1.0 - sin_max2).max(0.0).sqrt();
    let frame = crate::math::Frame::from_normal(to_c / dc);
    let local = sampling::square_to_uniform_cone(u, cos_max);
    let wi = frame.to_world(local);
    // Distance to the first intersection with the sphere along wi.
    let b = wi.dot(to_c);
    let disc = (r2 - (dc2 - b * b)).max(0.0);
    let dist = b - disc.sqrt();
    Some(EmitterSample { wi, dist, value: radiance, pdf: sampling::uniform_cone_pdf(cos_max), delta: false })
}

fn sphere_cone_pdf(center: Vec3, radius: f32, p: Vec3, q: Vec3) -> f32 {
    let dc2 = (center - p).length_squared();
    let r2 = radius * radius;
    if dc2 <= r2 * (1.0 + 1e-4) {
        let to = q - p;
        let dist2 = to.length_squared();
        let n = (q - center) / radius;
        let cos_light = -n.dot(to / dist2.sqrt());
        if cos_light <= 0.0 {
            return 0.0;
        }
        return dist2 / (cos_light * 4.0 * PI * r2);
    }
    let cos_max = (1.0 - r2 / dc2).max(0.0).sqrt();
    sampling::uniform_cone_pdf(cos_max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;

    #[test]
    fn sphere_cone_sampling_estimates_the_subtended_solid_angle() {
        // ∫ over the cone of 1 dω = 2π(1 − cos θmax); E[1/pdf] must match.
        let center = Vec3::new(0.0, 0.0, 3.0);
        let r = 1.0;
        let expected = 2.0 * PI * (1.0 - (1.0f32 - 1.0 / 9.0).sqrt());
        let mut rng = Rng::new(1, 1);
        let n = 10_000;
        let mut sum = 0.0;
        for _ in 0..n {
            let s = sample_sphere_cone(center, r, Vec3::ZERO, rng.next_2d(), Spectrum::ONE).unwrap();
            // Every sampled direction hits the sphere at the reported distance.
            let q = s.wi * s.dist;
            assert!(((q - center).length() - r).abs() < 1e-3);
            sum += 1.0 / s.pdf;
        }
        assert!((sum / n as f32 - expected).abs() < 1e-3 * expected);
    }

    #[test]
    fn envmap_pdf_matches_sampling_and_integrates_to_one() {
        let (w, h) = (16, 8);
        let texels = (0..w * h).map(|i| Vec3::splat(0.1 + (i % 7) as f32)).collect();
        let env =
            EnvMap::new(Arc::new(Bitmap { width: w, height: h, texels }), Mat3::from_rotation_y(0.4), 1.0).unwrap();
        let mut rng = Rng::new(4, 2);
        for _ in 0..1000 {
            let (d, pdf) = env.sample(rng.next_2d()).unwrap();
            assert!((env.pdf(d) - pdf).abs() < 1e-3 * pdf, "{} vs {pdf}", env.pdf(d));
        }
        // ∫ pdf dω over the sphere by uniform sampling = 1.
        let n = 200_000;
        let s: f32 = (0..n).map(|_| env.pdf(sampling::square_to_uniform_sphere(rng.next_2d()))).sum::<f32>()
            / n as f32
            / sampling::UNIFORM_SPHERE_PDF;
        assert!((s - 1.0).abs() < 0.02, "{s}");
    }
}
