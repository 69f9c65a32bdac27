//! A virtual mip-mapped tile cache over the infinite uv plane.
//!
//! Any function of uv that can be evaluated *filtered* — in tessera, the output of a procedural
//! texture-graph node — can be cached as a virtual texture: a [`TileCache`] holds, per texture
//! ([`TextureId`], described by a [`TextureDesc`]), an unbounded pyramid of levels (level 0
//! finest; level ℓ has `2^−ℓ` of level 0's texels per uv unit), each cut into square tiles of
//! `T × T` texels addressed by signed tile coordinates. Tiles are made on demand: on a miss the
//! cache calls the caller's fill function once per texel with a [`TexelRequest`] (the texel
//! centre's uv and the texel size at that level), and the caller answers with the value filtered
//! to one texel's footprint. Later requests are filtered lookups in stored texels.
//!
//! The cache knows nothing of graphs: the fill is a closure. Principal types:
//!
//! - [`TileCache`] (`Send + Sync`): [`TileCache::lookup`] takes a uv centre, a 2×2 uv covariance
//!   and a [`Filter`] (trilinear or anisotropic, optionally level-clamped) and returns the
//!   filtered channels; [`TileCache::stats`] returns [`CacheStats`] (per texture, per level).
//! - [`CacheConfig`]: tile size, byte budget, what threads do about a tile another thread is
//!   filling ([`InFlight`]), [`Eviction`] policy, per-thread micro-cache size.
//! - [`level_for`]: the one documented function from a uv covariance to a level (the same
//!   definition as `footprint::lod`).
//!
//! # Invariants
//!
//! - **Layout.** Tile `(x, y)` of level ℓ owns the texels `i ∈ [xT, xT + T)`, `j ∈ [yT, yT + T)`,
//!   whose centres lie at `uv = ((i + ½)/d_ℓ, (j + ½)/d_ℓ)` with `d_ℓ = texels_per_uv · 2^−ℓ`. It
//!   stores `(T + 1)²` texels: its own and one border row and column (the first texels of its
//!   `+x`, `+y` and diagonal neighbours), so every bilinear tap reads exactly one tile.
//! - **What a texel holds.** The fill's answer for the texel's request, rounded to the texture's
//!   [`TexelFormat`]. The fill should return the value filtered with an isotropic Gaussian of
//!   standard deviation `texel_size` ([`TexelRequest::covariance`]): the footprint to which
//!   [`level_for`] assigns exactly that level.
//! - **Determinism.** A texel is a pure function of (texture, level, texel), hence a tile of
//!   (texture, level, tile). Every lookup result is a fixed arithmetic of such texels, whether
//!   they came from a resident tile, a fresh fill or direct evaluation, so results never depend
//!   on thread timing or on what was evicted (given a deterministic fill).
//! - **Budget.** The bytes of all live tiles — resident, being filled (reserved before the fill
//!   starts) and evicted but still read by some thread — never exceed
//!   [`CacheConfig::budget_bytes`]. When no room can be made, the lookup evaluates the texels it
//!   needs directly instead of caching them.
//! - **Single flight.** Concurrent misses on one tile fill it once; see [`InFlight`].
//! - **Prefilled tiles.** A caller that computes the texels of several textures laid out alike
//!   in one pass (a fill says where each texel lies, [`TexelRequest::place`]) hands the others'
//!   to [`TileCache::prefill`] when the fill ends, and every thread then finds them resident.
//! - **Hot path.** A hit allocates nothing and takes no lock when the tile is in the calling
//!   thread's micro-cache ([`CacheConfig::micro_cache`]); otherwise one shard read lock. A
//!   [`Reader`] (one per thread, as a renderer holds) keeps its recent tiles in a table of its own
//!   and its counts in plain integers: its hits touch no thread-local and no shared counter.

#![deny(missing_docs)]

mod cache;
mod filter;
mod lod;
mod stats;
mod tile;

use glam::{Mat2, Vec2};

pub use cache::{tile_bytes_for, trilinear_taps, Reader, TileCache, TileRef, TrilinearTaps};
pub use lod::{level_for, LOD_MAX, LOD_MIN};
pub use stats::{CacheStats, LevelStats, TextureStats};

/// Most channels a cached texture can have.
pub const MAX_CHANNELS: u8 = 3;
/// Highest `max_level` a texture can have (levels `0..=MAX_LEVEL`).
pub const MAX_LEVEL: u8 = 31;
/// Largest `max_anisotropy` an anisotropic [`Filter`] honours.
pub const MAX_ANISOTROPY: f32 = 16.0;
/// Most entries of the per-thread micro-cache ([`CacheConfig::micro_cache`]).
pub const MICRO_CACHE_MAX: usize = 256;
/// Tile side `T` used by [`CacheConfig::default`], chosen by the `tile_size` benchmark: on its
/// render-like trace (3 MiB budget, ~100 ns fill) T = 8, 16, 32, 64 took 1.26, 1.05, 1.02 and
/// 1.17 µs per lookup and filled 8.1, 7.1, 7.6 and 9.4 texels per lookup; 16 fills the fewest
/// texels (what matters when fills are expensive) for the same time as 32, and wastes 13 % on
/// borders (8: 27 %, 32: 6 %).
pub const DEFAULT_TILE_SIZE: u32 = 16;

/// How texels are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TexelFormat {
    /// 32-bit float per channel.
    F32,
    /// 16-bit float per channel (`half::f16`); values are rounded to nearest on fill, and
    /// magnitudes beyond 65504 (the largest finite half) are stored as ±65504 and counted in
    /// [`LevelStats::texels_saturated`].
    F16,
}

impl TexelFormat {
    /// Bytes per channel.
    pub const fn bytes(self) -> usize {
        match self {
            TexelFormat::F32 => 4,
            TexelFormat::F16 => 2,
        }
    }
}

/// A virtual texture: what one cached node's output looks like in the cache.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureDesc {
    /// Channels, 1 to [`MAX_CHANNELS`]; lookups return zero beyond them.
    pub channels: u8,
    /// Storage format of each channel.
    pub format: TexelFormat,
    /// Level 0's texel density, texels per uv unit (finite, positive).
    pub texels_per_uv: f32,
    /// Coarsest level (at most [`MAX_LEVEL`]); level ℓ has `texels_per_uv · 2^−ℓ` texels per uv.
    pub max_level: u8,
}

/// Identifies a texture of one [`TileCache`] (returned by [`TileCache::add_texture`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TextureId(pub u32);

/// What a thread does when the tile it needs is being filled by another thread.
///
/// [`InFlight::Evaluate`] is the default: a waiting render thread is a lost core, while
/// evaluating four texels costs a small fraction of a tile's `(T + 1)²`. Measured
/// (`in_flight` benchmark, two threads interleaving a render-like trace on a cold cache, 16×16
/// tiles, a ~100 ns fill): 750 ns per lookup with `Evaluate` against 1150 ns with `Wait`, for
/// 3 % more texels evaluated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InFlight {
    /// Block until the fill completes, then read the tile. Each texel's fill runs exactly once
    /// per tile fill; the waiting thread's core idles meanwhile.
    Wait,
    /// Evaluate the (at most four) texels the bilinear tap needs directly, through the same fill
    /// function, without waiting. Duplicates a little work but never blocks. Results are
    /// bit-identical to [`InFlight::Wait`] (texels are pure functions of their key).
    Evaluate,
}

/// Which resident tile makes room for a new one.
///
/// [`Eviction::Clock`] is the default: on the `eviction` benchmark's render-like trace under a
/// 1 MiB budget it filled 10.9 texels per lookup against FIFO's 15.6 (1.34 µs against 1.77 µs
/// per lookup).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Eviction {
    /// CLOCK (second chance): tiles enter unreferenced; a hit sets the tile's reference bit; the
    /// sweep clears set bits and evicts the first tile found clear.
    Clock,
    /// First in, first out (reference bits ignored); a baseline for benchmarks.
    Fifo,
}

/// Construction settings of a [`TileCache`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CacheConfig {
    /// Tile side `T` in texels, a power of two from 2 to 1024; a tile stores `(T + 1)²` texels.
    pub tile_size: u32,
    /// Most bytes all live tiles may take together, see [`TileCache::tile_bytes`].
    pub budget_bytes: usize,
    /// What a thread does about a tile another thread is filling.
    pub in_flight: InFlight,
    /// Eviction policy.
    pub eviction: Eviction,
    /// Tiles each thread keeps its own strong reference to (0 to [`MICRO_CACHE_MAX`]; each tile
    /// has one slot of them, by its hash), so a hit on one of them takes no lock and no shared
    /// write. These tiles stay alive (and counted in the budget) until the thread replaces them,
    /// even after eviction or after the cache is dropped, so a budget should be well above
    /// `threads × micro_cache × tile bytes`; below that, lookups fall back to direct
    /// evaluation. Default 64: a render's lookups at secondary bounces scatter over the few dozen
    /// coarse tiles of each cached node, which four round-robin entries (the earlier default)
    /// missed, sending two lookups in three to the shared map; 64 slots are about 150 KiB of
    /// tiles per thread.
    pub micro_cache: usize,
    /// Count lookups and tile requests on the hit path (per-thread striped counters). Off, hits
    /// and requests read 0 in [`CacheStats`]; miss-side counters are always kept.
    pub count_requests: bool,
}

impl Default for CacheConfig {
    /// Tile size [`DEFAULT_TILE_SIZE`], a 256 MiB budget, [`InFlight::Evaluate`],
    /// [`Eviction::Clock`], a 64-tile micro-cache, request counting on.
    fn default() -> Self {
        CacheConfig {
            tile_size: DEFAULT_TILE_SIZE,
            budget_bytes: 256 << 20,
            in_flight: InFlight::Evaluate,
            eviction: Eviction::Clock,
            micro_cache: 64,
            count_requests: true,
        }
    }
}

impl CacheConfig {
    /// The default configuration with a budget of `budget_bytes`.
    pub fn with_budget(budget_bytes: usize) -> Self {
        CacheConfig { budget_bytes, ..CacheConfig::default() }
    }
}

/// How a lookup filters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FilterKind {
    /// One level from [`level_for`] of the whole covariance (its major axis), bilinear in the two
    /// nearest levels, linear between them. Blurs anisotropic footprints along their minor axis.
    Trilinear,
    /// Trilinear probes along the footprint's major axis. The probes' level is [`level_for`] of
    /// the isotropic covariance `σ²I` with `σ = max(σ_minor, σ_major / max_anisotropy)`; the
    /// `2m + 1` probes (`m = ⌈1.25 r / σ_p⌉ ≤ ⌈1.25 · max_anisotropy⌉`) lie on the major axis
    /// about `1.8 σ_p` apart, with Gaussian weights whose variance is the remaining
    /// `r² = σ_major² − σ_p²` (`σ_p`: the probes' blur at their level), so the probes' mixture
    /// has the footprint's covariance.
    Anisotropic {
        /// Largest ratio `σ_major / σ_probe` (1 to [`MAX_ANISOTROPY`]); beyond it the probes
        /// blur the minor axis. Bounds the probe count.
        max_anisotropy: f32,
    },
}

/// A lookup's filter: a [`FilterKind`] and the range of levels it may read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Filter {
    /// Trilinear or anisotropic.
    pub kind: FilterKind,
    /// Finest level read (clamped to the texture's levels).
    pub min_level: u8,
    /// Coarsest level read (clamped to the texture's `max_level`; `min_level` is clamped to it).
    pub max_level: u8,
}

impl Filter {
    /// Trilinear over all the texture's levels.
    pub const TRILINEAR: Filter = Filter { kind: FilterKind::Trilinear, min_level: 0, max_level: u8::MAX };

    /// Anisotropic over all the texture's levels.
    pub const fn anisotropic(max_anisotropy: f32) -> Filter {
        Filter { kind: FilterKind::Anisotropic { max_anisotropy }, min_level: 0, max_level: u8::MAX }
    }

    /// The same filter reading only levels `min_level..=max_level` ("level-clamped").
    pub const fn levels(self, min_level: u8, max_level: u8) -> Filter {
        Filter { min_level, max_level, ..self }
    }
}

impl Default for Filter {
    fn default() -> Self {
        Filter::TRILINEAR
    }
}

/// One texel to fill: what the fill function is asked for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelRequest {
    /// The texture.
    pub texture: TextureId,
    /// The level.
    pub level: u8,
    /// The texel's integer coordinates `(i, j)` at that level.
    pub texel: [i64; 2],
    /// The texel centre, `((i + ½)/d_ℓ, (j + ½)/d_ℓ)`.
    pub uv: Vec2,
    /// The texel's size in uv units, `1/d_ℓ`.
    pub texel_size: f32,
    /// Where the texel lies in the tile fill that asks for it; `None` where it is evaluated
    /// alone, for a lookup that the budget could not give a tile (or that found its tile being
    /// filled by another thread). Its value must not depend on this.
    pub place: Option<TilePlace>,
}

/// A texel's place in a tile fill ([`TexelRequest::place`]): a fill asks for its tile's texels
/// once each, row by row, border included, `index` 0 first and `count − 1` last. A caller that
/// computes several textures laid out alike at once can keep the others' values for the fill's
/// duration and hand them to [`TileCache::prefill`] when it ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TilePlace {
    /// The tile's coordinates at its level: its own texels are `tile · T … tile · T + T − 1` per
    /// axis (`T` the tile size), its border the next one.
    pub tile: [i32; 2],
    /// The texel's position in the fill.
    pub index: u32,
    /// Texels the fill asks for, `(T + 1)²`.
    pub count: u32,
}

impl TexelRequest {
    /// The footprint a texel stands for: isotropic with standard deviation `texel_size`.
    pub fn covariance(&self) -> Mat2 {
        Mat2::from_diagonal(Vec2::splat(self.texel_size * self.texel_size))
    }
}

/// Invalid cache or texture settings.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CacheError {
    /// The budget is zero.
    #[error("the cache budget is 0 bytes; it must hold at least one tile")]
    ZeroBudget,
    /// The budget cannot hold even the smallest tile.
    #[error(
        "the cache budget of {budget} bytes is smaller than one tile ({tile} bytes for a {tile_size}×{tile_size} tile)"
    )]
    BudgetBelowOneTile {
        /// The budget in bytes.
        budget: usize,
        /// Bytes of the tile that does not fit.
        tile: usize,
        /// The tile side.
        tile_size: u32,
    },
    /// The tile side is out of range.
    #[error("tile size {0} is not a power of two from 2 to 1024 texels")]
    TileSize(u32),
    /// Too many per-thread micro-cache entries.
    #[error("micro-cache of {0} tiles is larger than {MICRO_CACHE_MAX}")]
    MicroCache(usize),
    /// A texture with no channels or more than [`MAX_CHANNELS`].
    #[error("a cached texture has 1 to {MAX_CHANNELS} channels, not {0}")]
    Channels(u8),
    /// A texel density that is not finite and positive.
    #[error("texels per uv unit must be finite and positive, not {0}")]
    Density(f32),
    /// A coarsest level beyond [`MAX_LEVEL`].
    #[error("max level {0} is beyond {MAX_LEVEL}")]
    MaxLevel(u8),
}
