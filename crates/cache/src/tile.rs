//! Tiles: keys, texel storage with a border, filling, and the bilinear tap.
//!
//! A texel's value is [`texel_value`]: the fill's answer for [`request`], rounded to the texture
//! format. A tile stores those values for its `(T + 1)²` texels; a direct evaluation computes the
//! same values one by one. [`lerp2`] is the one bilinear arithmetic both paths use, so a tap
//! gives the same bits either way.

use std::hash::{BuildHasher, Hash, Hasher};
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::Arc;

use glam::Vec2;
use half::f16;

use crate::stats::{Budget, TextureCounters};
use crate::{TexelFormat, TexelRequest, TextureDesc, TextureId, TilePlace};

/// Channels of a texel as returned by lookups (zero beyond the texture's channels).
pub(crate) type Texel = [f32; 3];

/// A tile's address: texture, level and signed tile coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Key {
    pub tex: u32,
    pub level: u8,
    pub x: i32,
    pub y: i32,
}

impl Key {
    /// A well-mixed 64-bit hash (splitmix64 finaliser over the packed fields).
    #[inline]
    pub fn hash64(&self) -> u64 {
        let xy = u64::from(self.x as u32) | (u64::from(self.y as u32) << 32);
        let tl = (u64::from(self.tex) << 8 | u64::from(self.level)).wrapping_add(1);
        let mut h = xy ^ tl.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        h ^ (h >> 31)
    }
}

impl Hash for Key {
    #[inline]
    fn hash<H: Hasher>(&self, state: &mut H) {
        state.write_u64(self.hash64());
    }
}

/// Hasher for [`Key`]s: passes [`Key::hash64`] through.
#[derive(Default)]
pub(crate) struct KeyHasher(u64);

impl Hasher for KeyHasher {
    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }
    #[inline]
    fn write_u64(&mut self, v: u64) {
        self.0 = v;
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
    }
}

/// [`BuildHasher`] of [`KeyHasher`].
#[derive(Clone, Copy, Default)]
pub(crate) struct BuildKeyHasher;

impl BuildHasher for BuildKeyHasher {
    type Hasher = KeyHasher;
    #[inline]
    fn build_hasher(&self) -> KeyHasher {
        KeyHasher(0)
    }
}

/// Texel storage, row-major, channels interleaved.
pub(crate) enum Texels {
    F32(Box<[f32]>),
    F16(Box<[f16]>),
}

/// Bytes a tile is charged beyond its texels: the tile record in its `Arc`, a hash-map slot and a
/// CLOCK ring slot (hash-table slack is not counted).
pub(crate) const TILE_OVERHEAD: usize =
    std::mem::size_of::<Tile>() + 2 * std::mem::size_of::<usize>() + 48 + std::mem::size_of::<usize>();

/// Bytes one tile of `desc` takes: `(T + 1)²` texels plus [`TILE_OVERHEAD`].
pub(crate) fn tile_bytes(desc: &TextureDesc, tile_size: u32) -> usize {
    let side = tile_size as usize + 1;
    side * side * usize::from(desc.channels) * desc.format.bytes() + TILE_OVERHEAD
}

/// One filled tile. Its bytes are charged to the budget from creation to drop.
pub(crate) struct Tile {
    pub key: Key,
    texels: Texels,
    channels: usize,
    side: usize,
    /// CLOCK reference bit, set by hits.
    pub referenced: AtomicBool,
    /// Set once the tile left the cache; holders may still read it (its content stays valid).
    pub evicted: AtomicBool,
    /// Bytes reserved for it (released on drop).
    bytes: usize,
    budget: Arc<Budget>,
    counters: Arc<TextureCounters>,
}

impl Tile {
    /// Allocates a tile whose `bytes` were reserved in `budget`, charging its actual size, and
    /// fills it: every texel, border included, is [`texel_value`].
    #[allow(clippy::too_many_arguments)]
    pub fn fill<F>(
        key: Key,
        desc: &TextureDesc,
        tile_size: u32,
        bytes: usize,
        budget: Arc<Budget>,
        counters: Arc<TextureCounters>,
        fill: &F,
    ) -> Tile
    where
        F: Fn(TexelRequest) -> Texel + ?Sized,
    {
        let side = tile_size as usize + 1;
        let ch = usize::from(desc.channels);
        let n = side * side * ch;
        let texels = match desc.format {
            TexelFormat::F32 => Texels::F32(vec![0.0; n].into_boxed_slice()),
            TexelFormat::F16 => Texels::F16(vec![f16::ZERO; n].into_boxed_slice()),
        };
        let actual = match &texels {
            Texels::F32(v) => std::mem::size_of_val(&**v),
            Texels::F16(v) => std::mem::size_of_val(&**v),
        } + TILE_OVERHEAD;
        debug_assert_eq!(actual, bytes, "reservation and allocation disagree");
        budget.allocate(actual);
        counters.level(key.level).add_resident(actual);
        // From here on the tile owns the charge: a panicking fill drops it and releases it.
        let mut tile = Tile {
            key,
            texels,
            channels: ch,
            side,
            referenced: AtomicBool::new(false),
            evicted: AtomicBool::new(false),
            bytes,
            budget,
            counters,
        };
        let density = level_density(desc, key.level);
        let size = i64::from(tile_size);
        let (i0, j0) = (i64::from(key.x) * size, i64::from(key.y) * size);
        // Centre coordinates depend on one index each: compute each once, exactly as
        // `request` does, so direct evaluation sees the same bits.
        let us: Vec<f32> = (0..side as i64).map(|x| texel_coord(i0 + x, density)).collect();
        let vs: Vec<f32> = (0..side as i64).map(|y| texel_coord(j0 + y, density)).collect();
        let texel_size = (1.0 / density) as f32;
        let (texture, level) = (TextureId(key.tex), key.level);
        let count = (side * side) as u32;
        let raw = |x: usize, y: usize| {
            let texel = [i0 + x as i64, j0 + y as i64];
            let place = Some(TilePlace { tile: [key.x, key.y], index: (y * side + x) as u32, count });
            fill(TexelRequest { texture, level, texel, uv: Vec2::new(us[x], vs[y]), texel_size, place })
        };
        match &mut tile.texels {
            Texels::F32(v) => fill_rows(v, side, ch, raw),
            Texels::F16(v) => {
                let mut saturated = 0u64;
                fill_rows(v, side, ch, |x, y| {
                    raw(x, y).map(|c| {
                        let (h, sat) = to_f16(c);
                        saturated += u64::from(sat);
                        h
                    })
                });
                if saturated > 0 {
                    tile.counters.level(key.level).texels_saturated.fetch_add(saturated, Relaxed);
                }
            }
        }
        tile
    }

    /// Texels stored (border included).
    pub fn texel_count(&self) -> usize {
        self.side * self.side
    }

    /// Marks the tile used (CLOCK), writing only if the bit is clear.
    #[inline]
    pub fn touch(&self) {
        if !self.referenced.load(Relaxed) {
            self.referenced.store(true, Relaxed);
        }
    }

    /// The bilinear tap between local texels `(lx, ly)` and `(lx + 1, ly + 1)` with weights
    /// `(fx, fy)`; `lx, ly < T`.
    #[inline]
    pub fn bilinear(&self, lx: usize, ly: usize, fx: f32, fy: f32) -> Texel {
        let row = self.side * self.channels;
        let i = ly * row + lx * self.channels;
        match (&self.texels, self.channels) {
            (Texels::F32(v), 1) => tap::<f32, 1>(v, i, row, fx, fy),
            (Texels::F32(v), 2) => tap::<f32, 2>(v, i, row, fx, fy),
            (Texels::F32(v), _) => tap::<f32, 3>(v, i, row, fx, fy),
            (Texels::F16(v), 1) => tap_f16::<1>(v, i, row, fx, fy),
            (Texels::F16(v), 2) => tap_f16::<2>(v, i, row, fx, fy),
            (Texels::F16(v), _) => tap_f16::<3>(v, i, row, fx, fy),
        }
    }
}

impl Drop for Tile {
    fn drop(&mut self) {
        let actual = match &self.texels {
            Texels::F32(v) => std::mem::size_of_val(&**v),
            Texels::F16(v) => std::mem::size_of_val(&**v),
        } + TILE_OVERHEAD;
        self.counters.level(self.key.level).sub_resident(actual);
        self.budget.free(actual, self.bytes);
    }
}

/// Writes `value(x, y)` (first `ch` channels) for every texel of a `side × side` tile.
#[inline]
fn fill_rows<T: Copy, const N: usize>(
    v: &mut [T],
    side: usize,
    ch: usize,
    mut value: impl FnMut(usize, usize) -> [T; N],
) {
    for (y, row) in v.chunks_exact_mut(side * ch).enumerate() {
        for (x, texel) in row.chunks_exact_mut(ch).enumerate() {
            texel.copy_from_slice(&value(x, y)[..ch]);
        }
    }
}

/// A texel's storage type, read back as `f32`.
trait Channel: Copy {
    fn get(self) -> f32;
}

impl Channel for f32 {
    #[inline]
    fn get(self) -> f32 {
        self
    }
}

impl Channel for f16 {
    #[inline]
    fn get(self) -> f32 {
        f16_to_f32(self.to_bits())
    }
}

/// The `f32` of half-precision bits `h`, exactly as IEEE conversion gives it (all 65 536 inputs
/// are checked against the `half` crate). Written out because `half`'s own conversion checks the
/// processor's features on every call and calls out of line: a tap's twelve channels cost more
/// than the rest of the lookup.
#[inline(always)]
pub(crate) fn f16_to_f32(h: u16) -> f32 {
    let h = u32::from(h);
    let mag = h & 0x7fff;
    // Normal numbers: the exponent rebiased by 127 − 15 = 112, the mantissa widened.
    let normal = f32::from_bits((mag << 13) + (112 << 23));
    // Subnormals (and zero): the mantissa is an integer count of 2⁻²⁴ (both steps exact).
    let subnormal = mag as f32 * f32::from_bits((127 - 24) << 23);
    // Infinities and NaNs keep their payload under an all-ones exponent.
    let special = f32::from_bits((mag << 13) | 0x7f80_0000);
    let v = if mag < 0x400 {
        subnormal
    } else if mag >= 0x7c00 {
        special
    } else {
        normal
    };
    f32::from_bits(v.to_bits() | (h & 0x8000) << 16)
}

/// Bilinear tap in a tile's storage: texel index `i` of the lower-left texel, `row` values per row.
#[inline]
fn tap<T: Channel, const C: usize>(v: &[T], i: usize, row: usize, fx: f32, fy: f32) -> Texel {
    let q = &v[i..i + row + 2 * C];
    let at = |k: usize| {
        let mut t = [0.0; 3];
        for c in 0..C {
            t[c] = q[k + c].get();
        }
        t
    };
    lerp2(at(0), at(C), at(row), at(row + C), fx, fy)
}

/// [`tap`] of half-precision texels: on processors with F16C, the two rows' `2C` values are
/// converted four or eight at a time (a tap's twelve conversions one by one cost as much as the
/// rest of a lookup); the arithmetic after the conversion is the same, so are the bits.
#[inline]
fn tap_f16<const C: usize>(v: &[f16], i: usize, row: usize, fx: f32, fy: f32) -> Texel {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("f16c") && std::is_x86_feature_detected!("avx") {
        // SAFETY: the processor has both features the function is compiled for.
        return unsafe { tap_f16c::<C>(v, i, row, fx, fy) };
    }
    tap::<f16, C>(v, i, row, fx, fy)
}

/// [`tap_f16`] with F16C's conversion of eight halves at once per row.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "f16c,avx")]
unsafe fn tap_f16c<const C: usize>(v: &[f16], i: usize, row: usize, fx: f32, fy: f32) -> Texel {
    use std::arch::x86_64::{__m128i, _mm256_cvtph_ps, _mm256_storeu_ps, _mm_loadu_si128};
    let q = &v[i..i + row + 2 * C];
    let (mut lo, mut hi) = ([0u16; 8], [0u16; 8]);
    for k in 0..2 * C {
        lo[k] = q[k].to_bits();
        hi[k] = q[row + k].to_bits();
    }
    let (mut a, mut b) = ([0.0f32; 8], [0.0f32; 8]);
    // SAFETY: unaligned loads and stores of 16 and 32 bytes within the arrays above.
    unsafe {
        _mm256_storeu_ps(a.as_mut_ptr(), _mm256_cvtph_ps(_mm_loadu_si128(lo.as_ptr().cast::<__m128i>())));
        _mm256_storeu_ps(b.as_mut_ptr(), _mm256_cvtph_ps(_mm_loadu_si128(hi.as_ptr().cast::<__m128i>())));
    }
    let at = |r: &[f32; 8], k: usize| {
        let mut t = [0.0; 3];
        t[..C].copy_from_slice(&r[k..k + C]);
        t
    };
    lerp2(at(&a, 0), at(&a, C), at(&b, 0), at(&b, C), fx, fy)
}

/// `a + (b − a) t` per channel.
#[inline]
pub(crate) fn lerp3(a: Texel, b: Texel, t: f32) -> Texel {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t]
}

/// Bilinear interpolation of texels `t00, t10` (lower row) and `t01, t11` at `(fx, fy)`.
#[inline]
pub(crate) fn lerp2(t00: Texel, t10: Texel, t01: Texel, t11: Texel, fx: f32, fy: f32) -> Texel {
    lerp3(lerp3(t00, t10, fx), lerp3(t01, t11, fx), fy)
}

/// Texel density of level ℓ in texels per uv unit, exact (`d₀ · 2^−ℓ`).
#[inline]
pub(crate) fn level_density(desc: &TextureDesc, level: u8) -> f64 {
    f64::from(desc.texels_per_uv) * (-f64::from(level)).exp2()
}

/// The uv coordinate of the centre of texel index `i` at density `density`: `(i + ½)/d`.
#[inline]
fn texel_coord(i: i64, density: f64) -> f32 {
    ((i as f64 + 0.5) / density) as f32
}

/// The request for texel `ij` of `level` at density `density`.
#[inline]
pub(crate) fn request(tex: TextureId, level: u8, ij: [i64; 2], density: f64) -> TexelRequest {
    TexelRequest {
        texture: tex,
        level,
        texel: ij,
        uv: Vec2::new(texel_coord(ij[0], density), texel_coord(ij[1], density)),
        texel_size: (1.0 / density) as f32,
        place: None,
    }
}

/// The largest finite half float.
pub(crate) const F16_MAX: f32 = 65504.0;

/// `v` rounded to a half float, saturating at ±[`F16_MAX`] (a finite value never becomes an
/// infinity, whose bilinear taps would read as NaN), and whether it saturated. NaN stays NaN:
/// the fill that produced it reports it.
#[inline]
pub(crate) fn to_f16(v: f32) -> (f16, bool) {
    if v.abs() <= F16_MAX || v.is_nan() {
        (f16::from_f32(v), false)
    } else {
        (f16::from_f32(v.clamp(-F16_MAX, F16_MAX)), true)
    }
}

/// The fill's answer for texel `ij`, unrounded.
#[inline]
fn raw_value<F>(tex: TextureId, level: u8, ij: [i64; 2], density: f64, fill: &F) -> Texel
where
    F: Fn(TexelRequest) -> Texel + ?Sized,
{
    fill(request(tex, level, ij, density))
}

/// The value a tile stores for texel `ij`: the fill's answer rounded to `desc.format`, zero
/// beyond `desc.channels`.
#[inline]
pub(crate) fn texel_value<F>(
    tex: TextureId,
    desc: &TextureDesc,
    level: u8,
    ij: [i64; 2],
    density: f64,
    fill: &F,
) -> Texel
where
    F: Fn(TexelRequest) -> Texel + ?Sized,
{
    let v = raw_value(tex, level, ij, density, fill);
    let mut t = [0.0; 3];
    for c in 0..usize::from(desc.channels) {
        t[c] = match desc.format {
            TexelFormat::F32 => v[c],
            TexelFormat::F16 => f16_to_f32(to_f16(v[c]).0.to_bits()),
        };
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The F16C tap gives the portable tap's bits, on random texels of every channel count
    /// (infinities, NaNs and subnormals among them).
    #[test]
    fn f16_taps_agree_bit_for_bit() {
        let mut s = 0x2545_F491_u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let v: Vec<f16> = (0..4096).map(|_| f16::from_bits(next() as u16)).collect();
        for _ in 0..20_000 {
            let (fx, fy) = ((next() % 1000) as f32 / 1000.0, (next() % 1000) as f32 / 1000.0);
            let row = 51;
            let i = (next() % 3000) as usize;
            let same = |a: Texel, b: Texel| {
                a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
            };
            assert!(same(tap_f16::<1>(&v, i, row, fx, fy), tap::<f16, 1>(&v, i, row, fx, fy)));
            assert!(same(tap_f16::<2>(&v, i, row, fx, fy), tap::<f16, 2>(&v, i, row, fx, fy)));
            assert!(same(tap_f16::<3>(&v, i, row, fx, fy), tap::<f16, 3>(&v, i, row, fx, fy)));
        }
    }

    #[test]
    fn f16_conversion_matches_half_on_every_input() {
        for h in 0..=u16::MAX {
            let (ours, theirs) = (f16_to_f32(h), f16::from_bits(h).to_f32());
            assert!(
                ours.to_bits() == theirs.to_bits() || (ours.is_nan() && theirs.is_nan()),
                "{h:#06x}: {ours:e} ({:#010x}) against {theirs:e} ({:#010x})",
                ours.to_bits(),
                theirs.to_bits()
            );
        }
    }

    #[test]
    fn lerp2_of_equal_texels_is_exact() {
        let t = [0.1, -3.7, 1e20];
        for (fx, fy) in [(0.0, 0.0), (0.3, 0.9), (0.999, 0.5)] {
            assert_eq!(lerp2(t, t, t, t, fx, fy), t);
        }
    }

    #[test]
    fn lerp2_hits_corners() {
        let (a, b, c, d) = ([1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0], [4.0, 0.0, 0.0]);
        assert_eq!(lerp2(a, b, c, d, 0.0, 0.0), a);
        assert_eq!(lerp2(a, b, c, d, 1.0, 0.0), b);
        assert_eq!(lerp2(a, b, c, d, 0.0, 1.0), c);
        assert_eq!(lerp2(a, b, c, d, 1.0, 1.0), d);
        assert_eq!(lerp2(a, b, c, d, 0.5, 0.5), [2.5, 0.0, 0.0]);
    }

    #[test]
    fn keys_hash_apart() {
        let mut seen = std::collections::HashSet::new();
        for tex in 0..3 {
            for level in 0..4 {
                for x in -8..8 {
                    for y in -8..8 {
                        assert!(seen.insert(Key { tex, level, x, y }.hash64()));
                    }
                }
            }
        }
    }

    #[test]
    fn texel_centres_and_sizes() {
        let desc = TextureDesc { channels: 1, format: TexelFormat::F32, texels_per_uv: 16.0, max_level: 4 };
        let d = level_density(&desc, 2);
        assert_eq!(d, 4.0);
        let r = request(TextureId(0), 2, [-1, 3], d);
        assert_eq!(r.uv, Vec2::new(-0.125, 0.875));
        assert_eq!(r.texel_size, 0.25);
    }
}
