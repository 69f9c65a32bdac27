//! `trilinear_taps` predicts exactly which tiles a trilinear lookup fills: over random footprints
//! on a fresh cache large enough never to evict, the tiles filled per level equal the distinct
//! tiles the taps name, and every tap's tile is resident afterwards (a second lookup of the same
//! footprints fills nothing).

use cache::{trilinear_taps, CacheConfig, Filter, TexelFormat, TexelRequest, TextureDesc, TileCache, TileRef};
use glam::{Mat2, Vec2};
use std::collections::HashSet;

fn rng(state: &mut u64) -> f32 {
    *state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    ((*state >> 40) as f32) / (1u64 << 24) as f32
}

#[test]
fn taps_name_exactly_the_tiles_a_lookup_fills() {
    let desc = TextureDesc { channels: 2, format: TexelFormat::F16, texels_per_uv: 4096.0, max_level: 14 };
    let config = CacheConfig { count_requests: true, ..CacheConfig::with_budget(1 << 30) };
    let tile_size = config.tile_size;
    let mut cache = TileCache::new(config).unwrap();
    let tex = cache.add_texture(desc).unwrap();
    let fill = |r: TexelRequest| [r.uv.x, r.uv.y, 0.0];
    let mut s = 7u64;
    let mut taps: HashSet<TileRef> = HashSet::new();
    let mut footprints = Vec::new();
    for _ in 0..3000 {
        let uv = Vec2::new(rng(&mut s) * 6.0 - 3.0, rng(&mut s) * 6.0 - 3.0);
        // σ from 1e-5 to 10 uv units (below level 0 to beyond the coarsest), random anisotropy.
        let sigma = 10f32.powf(-5.0 + 6.0 * rng(&mut s));
        let r = Mat2::from_angle(std::f32::consts::TAU * rng(&mut s));
        let minor = sigma * (0.1 + 0.9 * rng(&mut s));
        let cov = r * Mat2::from_diagonal(Vec2::new(sigma * sigma, minor * minor)) * r.transpose();
        let t = trilinear_taps(&desc, tile_size, uv, cov);
        taps.insert(t.lower);
        taps.extend(t.upper);
        footprints.push((uv, cov));
        cache.lookup(tex, uv, cov, Filter::TRILINEAR, &fill);
    }
    let st = cache.stats();
    let levels = &st.textures[tex.0 as usize].levels;
    for (l, ls) in levels.iter().enumerate() {
        let predicted = taps.iter().filter(|t| usize::from(t.level) == l).count() as u64;
        assert_eq!(ls.fills, predicted, "level {l}: filled {} tiles, taps name {predicted}", ls.fills);
    }
    assert!(taps.len() > 1000, "the footprints should spread over many tiles, got {}", taps.len());
    let filled_before: u64 = levels.iter().map(|l| l.fills).sum();
    for (uv, cov) in footprints {
        cache.lookup(tex, uv, cov, Filter::TRILINEAR, &fill);
    }
    let filled_after: u64 = cache.stats().textures[tex.0 as usize].levels.iter().map(|l| l.fills).sum();
    assert_eq!(filled_before, filled_after, "a repeated lookup must hit the tiles its taps named");
}

/// A tile fill's texel requests, looked up on another texture of the same density at the texel's
/// own footprint, read only that level (no blend into the next): the model of nested fills
/// relies on it.
#[test]
fn texel_footprints_read_exactly_their_level() {
    let desc = TextureDesc { channels: 1, format: TexelFormat::F16, texels_per_uv: 16384.0, max_level: 20 };
    for level in 0..=20u8 {
        let d = 16384.0f64 * (-f64::from(level)).exp2();
        for i in [-17i64, 0, 5, 1000, 123_457] {
            let req = TexelRequest {
                texture: cache::TextureId(0),
                level,
                texel: [i, i],
                uv: Vec2::splat(((i as f64 + 0.5) / d) as f32),
                texel_size: (1.0 / d) as f32,
                place: None,
            };
            let t = trilinear_taps(&desc, 16, req.uv, req.covariance());
            assert_eq!(t.lower.level, level, "texel of level {level} read at lod {}", t.lod);
            assert!(t.upper.is_none(), "texel of level {level} blends into the next level (lod {})", t.lod);
        }
    }
}
