//! Random numbers and the warps that turn them into directions and points.
//!
//! [`Rng`] is a PCG32 stream. Every camera sample gets its own stream, keyed by the render seed,
//! the pixel and the sample index, so an image does not depend on how work is split over threads.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// PCG32 (O'Neill 2014): 64-bit LCG state, 32-bit xorshift-rotate output.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

const PCG_MULT: u64 = 6364136223846793005;

/// SplitMix64 finaliser: a bijective 64-bit mix used to derive independent stream keys.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d049bb133111eb);
    z ^ (z >> 31)
}

/// Point `sample` of a pixel's well-spread set in the unit square: the R2 sequence (the additive
/// recurrence on the plastic number, Roberts 2018) shifted by a random offset per pixel (a
/// Cranley–Patterson rotation, drawn from a stream no camera sample uses). Each point is
/// uniform on its own, so estimates stay unbiased, while any run of consecutive points covers
/// the square evenly whatever their count: a pixel's samples cover its filter like a jittered
/// grid, and smooth integrands (filtered textures, soft lighting) converge much faster than
/// with independent points. Depends only on `seed`, `pixel` and `sample`.
pub fn pixel_sample(seed: u64, pixel: u64, sample: u64) -> Vec2 {
    PixelSequence::new(seed, pixel).at(sample)
}

/// A pixel's [`pixel_sample`] sequence: its random shift, drawn once for all its samples (a
/// stream set up per camera sample was a third of generating a camera ray).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelSequence {
    shift: [f64; 2],
}

impl PixelSequence {
    /// The sequence of pixel `pixel` in a render seeded by `seed`.
    pub fn new(seed: u64, pixel: u64) -> PixelSequence {
        let mut rng = Rng::for_sample(seed, pixel, u64::MAX);
        PixelSequence { shift: [rng.next_f32() as f64, rng.next_f32() as f64] }
    }

    /// Point `sample` of the sequence.
    #[inline]
    pub fn at(&self, sample: u64) -> Vec2 {
        // 1/g and 1/g² for the plastic number g, the real root of x³ = x + 1.
        const A: [f64; 2] = [0.754_877_666_246_692_8, 0.569_840_290_998_053_3];
        let at = |k: usize| (fract_nonnegative(self.shift[k] + sample as f64 * A[k]) as f32).min(ONE_MINUS_EPSILON);
        Vec2::new(at(0), at(1))
    }
}

/// `x.fract()` for `0 < x < 2⁶³` without libm's `trunc` (the baseline x86-64 target has no
/// rounding instruction): the conversion truncates, exactly, toward zero. Others (zeros of
/// either sign among them) go to `fract`.
#[inline]
fn fract_nonnegative(x: f64) -> f64 {
    if x > 0.0 && x < 9.2e18 {
        x - (x as u64) as f64
    } else {
        x.fract()
    }
}

/// The largest `f32` below 1.
const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

impl Rng {
    /// A stream seeded by `seed`, on stream number `stream`.
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut rng = Rng { state: 0, inc: (stream << 1) | 1 };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(seed);
        rng.next_u32();
        rng
    }

    /// The stream of camera sample `sample` of pixel `pixel` in a render seeded by `seed`.
    pub fn for_sample(seed: u64, pixel: u64, sample: u64) -> Self {
        let key = mix64(seed ^ mix64(pixel.wrapping_mul(0x9e3779b97f4a7c15) ^ mix64(sample)));
        Rng::new(key, mix64(key ^ 0xda3e39cb94b95bdb))
    }

    /// Next uniform 32-bit integer.
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(PCG_MULT).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform float in [0, 1).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// Two uniform floats in [0, 1)².
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let x = self.next_f32();
        Vec2::new(x, self.next_f32())
    }
}

/// Uniform point on the unit disk by the concentric map (Shirley–Chiu).
#[inline]
pub fn square_to_disk_concentric(u: Vec2) -> Vec2 {
    let a = 2.0 * u - Vec2::ONE;
    if a.x == 0.0 && a.y == 0.0 {
        return Vec2::ZERO;
    }
    // φ = t in the first case and π/2 − t in the second, with |t| ≤ π/4 either way: the sine and
    // cosine of t by polynomials (no range reduction and no call; libm's `sincosf` was 3 % of a
    // Cornell box), swapped for π/2 − t.
    if a.x.abs() > a.y.abs() {
        let (s, c) = sin_cos_quarter((PI / 4.0) * (a.y / a.x));
        Vec2::new(a.x * c, a.x * s)
    } else {
        let (s, c) = sin_cos_quarter((PI / 4.0) * (a.x / a.y));
        Vec2::new(a.y * s, a.y * c)
    }
}

/// `(sin t, cos t)` for `|t| ≤ π/4` by short minimax polynomials (odd of degree 7, even of
/// degree 8; the coefficients of the classic single-precision fits on this interval): within
/// 2 f32 ulp of the rounded values (see the tests), with one multiply-add step fewer in each
/// chain than the Taylor series the same accuracy needs.
#[inline]
fn sin_cos_quarter(t: f32) -> (f32, f32) {
    let z = t * t;
    let s = t + t * z * (-1.666_665_5e-1 + z * (8.332_161e-3 + z * -1.951_529_6e-4));
    let c = 1.0 - 0.5 * z + z * z * (4.166_664_6e-2 + z * (-1.388_731_6e-3 + z * 2.443_315_7e-5));
    (s, c)
}

/// Cosine-weighted direction on the +z hemisphere.
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_disk_concentric(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Density of [`square_to_cosine_hemisphere`] in solid angle.
#[inline]
pub fn cosine_hemisphere_pdf(v: Vec3) -> f32 {
    v.z.max(0.0) * FRAC_1_PI
}

/// Uniform direction on the unit sphere.
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`square_to_uniform_sphere`].
pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform direction in the cone of half-angle `acos(cos_max)` around +z.
///
/// Through the concentric disk: its points are uniform in area, so their squared radius `ρ²` is
/// uniform on [0, 1], and `cos θ = 1 − k ρ²` (with `k = 1 − cos_max`) is uniform on
/// `[cos_max, 1]`, as a uniform cone's is; the point's direction gives the azimuth. Then
/// `sin θ = ρ √(k (2 − k ρ²))`, without the cancellation of `√(1 − cos² θ)` in narrow cones, and
/// without a sine and cosine of the azimuth.
pub fn square_to_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let k = 1.0 - cos_max;
    let d = square_to_disk_concentric(u);
    let r2 = d.length_squared();
    let s = (k * (2.0 - k * r2)).max(0.0).sqrt();
    Vec3::new(d.x * s, d.y * s, 1.0 - k * r2)
}

/// Density of [`square_to_uniform_cone`].
#[inline]
pub fn uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_max))
}

/// Uniform barycentrics (b1, b2) on a triangle.
pub fn square_to_triangle(u: Vec2) -> Vec2 {
    let t = u.x.sqrt();
    Vec2::new(1.0 - t, u.y * t)
}

/// A discrete distribution sampled by inverting its cumulative sum.
#[derive(Clone, Debug, Default)]
pub struct Distribution1D {
    cdf: Vec<f32>,
    total: f32,
}

impl Distribution1D {
    /// Builds from non-negative weights; `None` when they sum to zero or are not finite.
    pub fn new(weights: &[f32]) -> Option<Self> {
        let mut cdf = Vec::with_capacity(weights.len() + 1);
        let mut acc = 0.0f64;
        cdf.push(0.0);
        for &w in weights {
            if !(w >= 0.0) || !w.is_finite() {
                return None;
            }
            acc += w as f64;
            cdf.push(acc as f32);
        }
        if !(acc > 0.0) {
            return None;
        }
        let total = acc as f32;
        for c in cdf.iter_mut() {
            *c /= total;
        }
        *cdf.last_mut().unwrap() = 1.0;
        Some(Distribution1D { cdf, total })
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.cdf.len() - 1
    }

    /// True when there are no entries.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Sum of the weights.
    pub fn total(&self) -> f32 {
        self.total
    }

    /// Probability of entry `i`.
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.cdf[i + 1] - self.cdf[i]
    }

    /// Samples an entry; returns it with `u` re-scaled to [0, 1) inside that entry.
    pub fn sample(&self, u: f32) -> (usize, f32) {
        let n = self.len();
        let i = self.cdf.partition_point(|&c| c <= u).saturating_sub(1).min(n - 1);
        let width = self.pmf(i);
        let rem = if width > 0.0 { ((u - self.cdf[i]) / width).clamp(0.0, 1.0 - f32::EPSILON) } else { 0.0 };
        (i, rem)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The polynomials against f64's sine and cosine over the whole quarter (and its ends): within 2
    /// f32 ulp of the correctly rounded values; and the disk map built on it puts every point of
    /// a 256 × 256 grid within 2e-7 of the libm form's, on the unit disk.
    #[test]
    fn quarter_sine_and_cosine_are_f32_exact() {
        // |a − b| in f32 spacings at b's magnitude.
        let ulps = |a: f32, b: f64| {
            let x = (b.abs() as f32).max(f32::MIN_POSITIVE);
            (a as f64 - b).abs() / (f32::from_bits(x.to_bits() + 1) - x) as f64
        };
        let mut worst = 0.0f64;
        for k in 0..=100_000 {
            let t = (k as f32 / 100_000.0 * 2.0 - 1.0) * (PI / 4.0);
            let (s, c) = sin_cos_quarter(t);
            worst = worst.max(ulps(s, (t as f64).sin())).max(ulps(c, (t as f64).cos()));
        }
        assert!(worst <= 2.0, "worst {worst} ulp");
        // The map in f64 as the reference: the polynomials' points are nearer to it than the libm
        // form's (which rounds π/2 − t before its sine and cosine) plus an f32 ulp at 1.
        let (mut ours, mut libms) = (0.0f64, 0.0f64);
        for i in 0..256 {
            for j in 0..256 {
                let u = Vec2::new((i as f32 + 0.5) / 256.0, (j as f32 + 0.5) / 256.0);
                let a = 2.0 * u - Vec2::ONE;
                let (r, phi, r64, phi64) = if a.x.abs() > a.y.abs() {
                    let t = (a.y / a.x) as f64;
                    (a.x, (PI / 4.0) * (a.y / a.x), a.x as f64, std::f64::consts::FRAC_PI_4 * t)
                } else {
                    let t = (a.x / a.y) as f64;
                    (
                        a.y,
                        PI / 2.0 - (PI / 4.0) * (a.x / a.y),
                        a.y as f64,
                        std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * t,
                    )
                };
                let exact = glam::DVec2::new(r64 * phi64.cos(), r64 * phi64.sin());
                let libm = Vec2::new(r * phi.cos(), r * phi.sin());
                let d = square_to_disk_concentric(u);
                assert!(d.length() <= 1.0 + 1e-6, "{u}: {d}");
                ours = ours.max((d.as_dvec2() - exact).length());
                libms = libms.max((libm.as_dvec2() - exact).length());
            }
        }
        println!("concentric disk, largest distance from the f64 map: polynomials {ours:e}, libm {libms:e}");
        assert!(ours <= libms + 6e-8 && ours < 2e-7, "polynomials {ours:e}, libm {libms:e}");
    }

    /// Uniform cones, wide to narrow: unit directions inside the cone, cos θ uniform on
    /// [cos_max, 1] and the azimuth uniform (8 bins each, within 5 standard errors), and in a
    /// narrow cone directions that are not quantised with cos θ.
    #[test]
    fn uniform_cone_is_uniform() {
        for cos_max in [-0.5f32, 0.3, 0.99, 0.999_99] {
            let mut rng = Rng::new(3, 9);
            let n = 40_000usize;
            let (mut zs, mut az) = ([0usize; 8], [0usize; 8]);
            for _ in 0..n {
                let v = square_to_uniform_cone(rng.next_2d(), cos_max);
                assert!((v.length() - 1.0).abs() < 1e-5, "{cos_max}: {v}");
                assert!(v.z >= cos_max - 1e-6 && v.z <= 1.0, "{cos_max}: {v}");
                let t = ((1.0 - v.z) / (1.0 - cos_max)).clamp(0.0, 0.999_999);
                zs[(t * 8.0) as usize] += 1;
                let phi = v.y.atan2(v.x) / (2.0 * PI) + 0.5;
                az[((phi * 8.0) as usize).min(7)] += 1;
            }
            let (e, sd) = (n as f64 / 8.0, (n as f64 / 8.0 * 7.0 / 8.0).sqrt());
            for k in zs.iter().chain(&az) {
                assert!((*k as f64 - e).abs() < 5.0 * sd, "{cos_max}: {zs:?} {az:?}");
            }
        }
        // In a narrow cone, cos θ has only some 170 f32 values between cos_max and 1; sin θ from
        // the disk's radius is not quantised with it (from √(1 − cos² θ) it would be).
        let mut rng = Rng::new(4, 2);
        let mut sines: Vec<u32> = (0..10_000)
            .map(|_| square_to_uniform_cone(rng.next_2d(), 0.999_99).truncate().length().to_bits())
            .collect();
        sines.sort_unstable();
        sines.dedup();
        assert!(sines.len() > 5_000, "{} distinct sines of 10000", sines.len());
    }

    #[test]
    fn streams_differ_and_repeat() {
        let a: Vec<u32> = (0..4).map(|_| 0).scan(Rng::for_sample(1, 2, 3), |r, _| Some(r.next_u32())).collect();
        let b: Vec<u32> = (0..4).map(|_| 0).scan(Rng::for_sample(1, 2, 3), |r, _| Some(r.next_u32())).collect();
        let c: Vec<u32> = (0..4).map(|_| 0).scan(Rng::for_sample(1, 2, 4), |r, _| Some(r.next_u32())).collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    /// The fraction without libm is `fract`, bit for bit, on the additive sequence's arguments
    /// (shifts in [0, 1) plus up to 2³² steps) and on edge values.
    #[test]
    fn fract_without_libm_is_fract() {
        let mut r = Rng::new(11, 3);
        for k in 0..200_000u64 {
            let x = r.next_f32() as f64 + (k * 21_474) as f64 * 0.754_877_666_246_692_8;
            assert_eq!(fract_nonnegative(x).to_bits(), x.fract().to_bits(), "{x}");
        }
        for x in [0.0, -0.0, 1.0, 0.5, 4_503_599_627_370_495.5, 9.1e18, 9.3e18, f64::INFINITY, f64::NAN, -2.5] {
            assert_eq!(fract_nonnegative(x).to_bits(), x.fract().to_bits(), "{x}");
        }
    }

    /// A pixel's sequence set up once gives every sample the point of the R2 recurrence shifted
    /// by the pixel's own stream, written out here with libm's `fract`.
    #[test]
    fn pixel_sequence_is_the_shifted_recurrence() {
        const A: [f64; 2] = [0.754_877_666_246_692_8, 0.569_840_290_998_053_3];
        for (seed, pixel) in [(0, 0), (7, 12_345), (u64::MAX, 99)] {
            let seq = PixelSequence::new(seed, pixel);
            let mut rng = Rng::for_sample(seed, pixel, u64::MAX);
            let shift = [rng.next_f32() as f64, rng.next_f32() as f64];
            for s in [0, 1, 2, 15, 1000, u64::from(u32::MAX)] {
                let at = |k: usize| ((shift[k] + s as f64 * A[k]).fract() as f32).min(ONE_MINUS_EPSILON);
                assert_eq!(seq.at(s), Vec2::new(at(0), at(1)));
                assert_eq!(pixel_sample(seed, pixel, s), seq.at(s));
            }
        }
    }

    #[test]
    fn uniform_floats_have_the_right_mean() {
        let mut r = Rng::new(7, 0);
        let n = 100_000;
        let mean: f64 = (0..n).map(|_| r.next_f32() as f64).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.005, "{mean}");
    }

    #[test]
    fn distribution_samples_follow_weights() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0]).unwrap();
        let mut counts = [0usize; 3];
        let mut r = Rng::new(3, 1);
        for _ in 0..40_000 {
            counts[d.sample(r.next_f32()).0] += 1;
        }
        assert_eq!(counts[1], 0);
        let f = counts[2] as f32 / 40_000.0;
        assert!((f - 0.75).abs() < 0.01, "{f}");
        assert!(Distribution1D::new(&[0.0, 0.0]).is_none());
        assert!(Distribution1D::new(&[f32::NAN]).is_none());
    }

    #[test]
    fn cosine_hemisphere_is_normalised() {
        let mut r = Rng::new(5, 5);
        // E[1/pdf] over samples of pdf equals the hemisphere's solid angle 2π.
        let n = 200_000;
        let s: f64 = (0..n)
            .map(|_| {
                let v = square_to_cosine_hemisphere(r.next_2d());
                1.0 / cosine_hemisphere_pdf(v).max(1e-6) as f64
            })
            .sum::<f64>()
            / n as f64;
        assert!((s - 2.0 * std::f64::consts::PI).abs() < 0.1, "{s}");
    }
}
