//! [`TileCache`]: sharded tile maps, single-flight fills, the byte budget with CLOCK eviction,
//! and the per-thread micro-cache.
//!
//! Locks, never nested except CLOCK → shard during eviction: a shard's `RwLock` guards its map
//! (read on hits, write to insert, publish or remove); the `clock` mutex guards the eviction
//! ring. No lock is held while the fill function runs, so a fill may itself look up other
//! textures (a cached node upstream of another).

use std::cell::RefCell;
use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, RwLock, RwLockReadGuard, RwLockWriteGuard};
use std::thread::ThreadId;

use glam::{Mat2, Vec2};

use crate::filter::{self, ProbeTables};
use crate::stats::{Budget, CacheStats, TextureCounters};
use crate::tile::{self, lerp2, texel_value, BuildKeyHasher, Key, Texel, Tile};
use crate::{
    level_for, CacheConfig, CacheError, Eviction, Filter, FilterKind, InFlight, TexelFormat, TexelRequest, TextureDesc,
    TextureId, MAX_CHANNELS, MAX_LEVEL, MICRO_CACHE_MAX,
};

/// Shards of the tile map (a power of two).
const SHARDS: usize = 64;

/// Most evictions one reservation may make before it gives up and evaluates directly.
const MAX_EVICTIONS_PER_RESERVE: usize = 64;

/// Most evicted keys remembered for counting refills (about 16 MiB, outside the budget); beyond
/// it, evictions are not remembered and `refills` undercounts.
const EVICTED_KEYS_MAX: usize = 1 << 20;

/// Texel coordinates are clamped to `±2³¹` so tile coordinates fit an `i32` at any tile size.
const TEXEL_LIMIT: f64 = 2_147_483_000.0;

/// A virtual mip-mapped texture cache; see the crate documentation for its invariants.
///
/// Textures are added before use ([`TileCache::add_texture`] takes `&mut self`); lookups and
/// statistics take `&self` from any number of threads.
pub struct TileCache {
    id: u64,
    config: CacheConfig,
    textures: Vec<Texture>,
    shards: Box<[RwLock<TileMap>]>,
    clock: Mutex<Clock>,
    budget: Arc<Budget>,
    probes: ProbeTables,
}

type TileMap = HashMap<Key, Slot, BuildKeyHasher>;

struct Texture {
    desc: TextureDesc,
    tile_bytes: usize,
    /// Texel density per level, `d₀ · 2^−ℓ`.
    density: Box<[f64]>,
    counters: Arc<TextureCounters>,
}

#[derive(Clone)]
enum Slot {
    Ready(Arc<Tile>),
    Filling(Arc<Flight>),
}

/// A fill in progress: threads that [`InFlight::Wait`] block on it.
struct Flight {
    filler: ThreadId,
    /// `None` while filling; then the tile, or `None` if the fill failed (panicked or found no
    /// room in the budget).
    done: Mutex<Option<Option<Arc<Tile>>>>,
    ready: Condvar,
}

impl Flight {
    fn wait(&self) -> Option<Arc<Tile>> {
        let mut done = lock(&self.done);
        loop {
            if let Some(r) = &*done {
                return r.clone();
            }
            done = self.ready.wait(done).unwrap_or_else(|e| e.into_inner());
        }
    }

    fn complete(&self, tile: Option<Arc<Tile>>) {
        *lock(&self.done) = Some(tile);
        self.ready.notify_all();
    }
}

/// The eviction ring (front: next candidate) and the keys evicted and not yet filled again.
struct Clock {
    ring: VecDeque<Arc<Tile>>,
    evicted: HashSet<Key, BuildKeyHasher>,
}

static NEXT_CACHE_ID: AtomicU64 = AtomicU64::new(0);

struct MicroEntry {
    cache: u64,
    key: Key,
    tile: Arc<Tile>,
}

/// A thread's recent tiles, shared by all caches on the thread: direct-mapped (a tile has one
/// slot, [`micro_slot`], and replaces whatever held it).
struct Micro {
    slots: [Option<MicroEntry>; MICRO_CACHE_MAX],
}

thread_local! {
    static MICRO: RefCell<Micro> = const { RefCell::new(Micro { slots: [const { None }; MICRO_CACHE_MAX] }) };
}

/// The micro-cache slot, among `n`, of tile `key` of cache `cache`.
#[inline]
fn micro_slot(cache: u64, key: &Key, n: usize) -> usize {
    let h = key.hash64() ^ cache.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    (((h >> 32) * n as u64) >> 32) as usize
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

fn read(m: &RwLock<TileMap>) -> RwLockReadGuard<'_, TileMap> {
    m.read().unwrap_or_else(|e| e.into_inner())
}

fn write(m: &RwLock<TileMap>) -> RwLockWriteGuard<'_, TileMap> {
    m.write().unwrap_or_else(|e| e.into_inner())
}

/// `(⌊s − ½⌋, fraction)`: the lower texel of a bilinear tap at texel-space coordinate `s`
/// (`floor` by hand: the baseline x86-64 target has no rounding instruction, and the libm call
/// costs more than the rest of the tap's arithmetic).
#[inline]
fn split(s: f64) -> (i64, f32) {
    let s = (s - 0.5).clamp(-TEXEL_LIMIT, TEXEL_LIMIT); // NaN stays NaN and converts to 0
    let t = s as i64;
    let i = if (t as f64) > s { t - 1 } else { t };
    (i, (s - i as f64) as f32)
}

/// The lower texel and fractions of a bilinear tap at `uv` on a level of density `d`.
#[inline]
fn tap_texel(d: f64, uv: Vec2) -> ((i64, f32), (i64, f32)) {
    (split(f64::from(uv.x) * d), split(f64::from(uv.y) * d))
}

/// The tile holding texel `(i0, j0)` (power-of-two tiles: arithmetic shifts floor negative
/// coordinates too).
#[inline]
fn tap_tile(i0: i64, j0: i64, tile_size: u32) -> (i64, i64) {
    let shift = tile_size.trailing_zeros();
    (i0 >> shift, j0 >> shift)
}

/// A tile of a texture: its level and signed tile coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileRef {
    /// The level.
    pub level: u8,
    /// Tile column.
    pub x: i32,
    /// Tile row.
    pub y: i32,
}

/// The tiles a trilinear lookup reads (see [`trilinear_taps`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrilinearTaps {
    /// The footprint's level by [`level_for`], before clamping (negative: finer than level 0).
    pub level: f32,
    /// The continuous level, clamped to the texture's levels.
    pub lod: f32,
    /// The tile of the finer level `⌊lod⌋`.
    pub lower: TileRef,
    /// The tile of level `⌊lod⌋ + 1` when the lookup blends it in (fractional `lod` below the
    /// coarsest level).
    pub upper: Option<TileRef>,
}

/// The tiles that [`TileCache::lookup`] with [`Filter::TRILINEAR`] reads for a footprint
/// `(uv, cov_uv)` on a texture `desc` with tiles of `tile_size` texels: the same arithmetic as
/// the lookup, for profilers and models that predict which tiles a render touches.
pub fn trilinear_taps(desc: &TextureDesc, tile_size: u32, uv: Vec2, cov_uv: Mat2) -> TrilinearTaps {
    let hi = desc.max_level;
    let level = level_for(cov_uv, desc.texels_per_uv);
    let lod = level.clamp(0.0, f32::from(hi));
    let l0 = lod as u8;
    let tile_at = |level: u8| {
        let ((i0, _), (j0, _)) = tap_texel(tile::level_density(desc, level), uv);
        let (x, y) = tap_tile(i0, j0, tile_size);
        TileRef { level, x: x as i32, y: y as i32 }
    };
    let upper = (lod - f32::from(l0) > 0.0 && l0 < hi).then(|| tile_at(l0 + 1));
    TrilinearTaps { level, lod, lower: tile_at(l0), upper }
}

/// Bytes one tile of `desc` is charged against the budget with tiles of `tile_size` texels
/// (what [`TileCache::tile_bytes`] returns for such a texture).
pub fn tile_bytes_for(desc: &TextureDesc, tile_size: u32) -> usize {
    tile::tile_bytes(desc, tile_size)
}

/// Removes the fill's placeholder and fails its flight if the fill does not complete (a panic).
struct FillGuard<'a> {
    cache: &'a TileCache,
    key: Key,
    flight: &'a Arc<Flight>,
    armed: bool,
}

impl Drop for FillGuard<'_> {
    fn drop(&mut self) {
        if self.armed {
            self.cache.remove_flight(self.key, self.flight);
            self.flight.complete(None);
        }
    }
}

impl TileCache {
    /// A cache with `config`. Errors: a zero budget, a budget below the smallest tile (one `f16`
    /// channel), a tile size that is not a power of two in 2..=1024, or a micro-cache above
    /// [`MICRO_CACHE_MAX`].
    pub fn new(config: CacheConfig) -> Result<TileCache, CacheError> {
        if !(2..=1024).contains(&config.tile_size) || !config.tile_size.is_power_of_two() {
            return Err(CacheError::TileSize(config.tile_size));
        }
        if config.micro_cache > MICRO_CACHE_MAX {
            return Err(CacheError::MicroCache(config.micro_cache));
        }
        if config.budget_bytes == 0 {
            return Err(CacheError::ZeroBudget);
        }
        let smallest = TextureDesc { channels: 1, format: TexelFormat::F16, texels_per_uv: 1.0, max_level: 0 };
        let tile = tile::tile_bytes(&smallest, config.tile_size);
        if tile > config.budget_bytes {
            return Err(CacheError::BudgetBelowOneTile {
                budget: config.budget_bytes,
                tile,
                tile_size: config.tile_size,
            });
        }
        Ok(TileCache {
            id: NEXT_CACHE_ID.fetch_add(1, Relaxed),
            config,
            textures: Vec::new(),
            shards: (0..SHARDS).map(|_| RwLock::new(TileMap::default())).collect(),
            clock: Mutex::new(Clock { ring: VecDeque::new(), evicted: HashSet::default() }),
            budget: Arc::new(Budget::new(config.budget_bytes)),
            probes: ProbeTables::new(),
        })
    }

    /// Adds a virtual texture. Errors: 0 or more than [`MAX_CHANNELS`] channels, a density that
    /// is not finite and positive, `max_level` above [`MAX_LEVEL`], or a tile above the budget.
    pub fn add_texture(&mut self, desc: TextureDesc) -> Result<TextureId, CacheError> {
        if desc.channels == 0 || desc.channels > MAX_CHANNELS {
            return Err(CacheError::Channels(desc.channels));
        }
        if !(desc.texels_per_uv.is_finite() && desc.texels_per_uv > 0.0) {
            return Err(CacheError::Density(desc.texels_per_uv));
        }
        if desc.max_level > MAX_LEVEL {
            return Err(CacheError::MaxLevel(desc.max_level));
        }
        let tile_bytes = tile::tile_bytes(&desc, self.config.tile_size);
        if tile_bytes > self.config.budget_bytes {
            return Err(CacheError::BudgetBelowOneTile {
                budget: self.config.budget_bytes,
                tile: tile_bytes,
                tile_size: self.config.tile_size,
            });
        }
        let levels = usize::from(desc.max_level) + 1;
        self.textures.push(Texture {
            desc,
            tile_bytes,
            density: (0..=desc.max_level).map(|l| tile::level_density(&desc, l)).collect(),
            counters: Arc::new(TextureCounters::new(levels)),
        });
        Ok(TextureId(self.textures.len() as u32 - 1))
    }

    /// The configuration.
    pub fn config(&self) -> &CacheConfig {
        &self.config
    }

    /// A texture's description. Panics on an id of another cache.
    pub fn texture(&self, tex: TextureId) -> &TextureDesc {
        &self.textures[tex.0 as usize].desc
    }

    /// Bytes one tile of `tex` is charged against the budget: `(T + 1)²` texels plus a fixed
    /// per-tile overhead for its record and map slots.
    pub fn tile_bytes(&self, tex: TextureId) -> usize {
        self.textures[tex.0 as usize].tile_bytes
    }

    /// Whether the tile whose own texels (not its border) include texel `texel` of `tex` at
    /// `level` is resident now (filled and not evicted). A hint: another thread may fill or evict
    /// it right after.
    pub fn is_resident(&self, tex: TextureId, level: u8, texel: [i64; 2]) -> bool {
        let (x, y) = tap_tile(texel[0], texel[1], self.config.tile_size);
        let key = Key { tex: tex.0, level, x: x as i32, y: y as i32 };
        matches!(read(self.shard(&key)).get(&key), Some(Slot::Ready(_)))
    }

    /// Tiles in the cache now (not counting fills in progress or evicted tiles still read).
    pub fn resident_tiles(&self) -> usize {
        lock(&self.clock).ring.len()
    }

    /// The filtered value of texture `tex` over the footprint centred at `uv` with uv covariance
    /// `cov_uv`, filtered by `filter`. `fill` is called only for texels of tiles that are not
    /// resident (see [`TexelRequest`]); it must be a pure function of its request for results to
    /// be deterministic. Channels beyond the texture's are zero. Panics on an id of another
    /// cache.
    pub fn lookup<F>(&self, tex: TextureId, uv: Vec2, cov_uv: Mat2, filter: Filter, fill: &F) -> [f32; 3]
    where
        F: Fn(TexelRequest) -> [f32; 3] + ?Sized,
    {
        self.lookup_with_level(tex, uv, cov_uv, self.filter_level(tex, cov_uv, filter), filter, fill)
    }

    /// [`TileCache::lookup`] whose caller already computed `level`, which must be
    /// [`level_for`]`(cov_uv, texels_per_uv)` of the texture's description: a caller that
    /// compares the level with a threshold first (two logarithms and a square root) need not
    /// have it computed twice. Anisotropic filters ignore it (their probes' level is their own).
    pub fn lookup_with_level<F>(
        &self,
        tex: TextureId,
        uv: Vec2,
        cov_uv: Mat2,
        level: f32,
        filter: Filter,
        fill: &F,
    ) -> [f32; 3]
    where
        F: Fn(TexelRequest) -> [f32; 3] + ?Sized,
    {
        self.lookup_in(&Shared, tex, uv, cov_uv, level, filter, fill)
    }

    /// The level [`TileCache::lookup_with_level`] wants for `filter`: [`level_for`] of the
    /// footprint for trilinear lookups (anisotropic ones choose their probes' level themselves).
    fn filter_level(&self, tex: TextureId, cov_uv: Mat2, filter: Filter) -> f32 {
        match filter.kind {
            FilterKind::Trilinear => level_for(cov_uv, self.textures[tex.0 as usize].desc.texels_per_uv),
            FilterKind::Anisotropic { .. } => f32::NAN,
        }
    }

    /// [`TileCache::lookup_with_level`] keeping recent tiles and counts in `local`.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn lookup_in<L: Local, F>(
        &self,
        local: &L,
        tex: TextureId,
        uv: Vec2,
        cov_uv: Mat2,
        level: f32,
        filter: Filter,
        fill: &F,
    ) -> [f32; 3]
    where
        F: Fn(TexelRequest) -> [f32; 3] + ?Sized,
    {
        let t = &self.textures[tex.0 as usize];
        if self.config.count_requests {
            local.count_lookup(t, tex);
        }
        let hi = filter.max_level.min(t.desc.max_level);
        let lo = filter.min_level.min(hi);
        let d0 = t.desc.texels_per_uv;
        match filter.kind {
            FilterKind::Trilinear => {
                debug_assert_eq!(level.to_bits(), level_for(cov_uv, d0).to_bits());
                let lod = level.clamp(f32::from(lo), f32::from(hi));
                filter::trilinear(lod, hi, |l| self.bilinear(local, t, tex, l, uv, fill))
            }
            FilterKind::Anisotropic { max_anisotropy } => {
                filter::anisotropic(cov_uv, d0, lo, hi, max_anisotropy, &self.probes, |offset, lod| {
                    filter::trilinear(lod, hi, |l| self.bilinear(local, t, tex, l, uv + offset, fill))
                })
            }
        }
    }

    /// Trilinear lookup at a level the caller computed (e.g. with `footprint::lod`), clamped to
    /// the texture's levels.
    pub fn lookup_level<F>(&self, tex: TextureId, uv: Vec2, level: f32, fill: &F) -> [f32; 3]
    where
        F: Fn(TexelRequest) -> [f32; 3] + ?Sized,
    {
        let t = &self.textures[tex.0 as usize];
        if self.config.count_requests {
            Shared.count_lookup(t, tex);
        }
        let hi = t.desc.max_level;
        let lod = if level.is_nan() { f32::from(hi) } else { level.clamp(0.0, f32::from(hi)) };
        filter::trilinear(lod, hi, |l| self.bilinear(&Shared, t, tex, l, uv, fill))
    }

    /// A snapshot of the statistics, per texture and level.
    pub fn stats(&self) -> CacheStats {
        let mut s = CacheStats {
            budget_bytes: 0,
            tile_size: self.config.tile_size,
            resident_bytes: 0,
            peak_bytes: 0,
            budget_checks: 0,
            over_budget: 0,
            textures: self
                .textures
                .iter()
                .enumerate()
                .map(|(i, t)| t.counters.snapshot(TextureId(i as u32), t.tile_bytes))
                .collect(),
        };
        self.budget.fill_stats(&mut s);
        s
    }

    /// Bytes of live tiles now (the budgeted quantity).
    pub fn resident_bytes(&self) -> usize {
        self.budget.allocated()
    }

    /// One bilinear tap of `level` at `uv`: from a tile, or from texels evaluated directly.
    #[inline]
    fn bilinear<L: Local, F>(&self, local: &L, t: &Texture, tex: TextureId, level: u8, uv: Vec2, fill: &F) -> Texel
    where
        F: Fn(TexelRequest) -> Texel + ?Sized,
    {
        let d = t.density[usize::from(level)];
        let ((i0, fx), (j0, fy)) = tap_texel(d, uv);
        let mask = i64::from(self.config.tile_size) - 1;
        let (tx, ty) = tap_tile(i0, j0, self.config.tile_size);
        let (lx, ly) = ((i0 & mask) as usize, (j0 & mask) as usize);
        let key = Key { tex: tex.0, level, x: tx as i32, y: ty as i32 };
        if self.config.count_requests {
            local.count_request(t, tex, level);
        }
        if let Some(v) = local.get(self, &key, |tile| tile.bilinear(lx, ly, fx, fy)) {
            return v;
        }
        match self.acquire(t, key, fill) {
            Some(tile) => {
                let v = tile.bilinear(lx, ly, fx, fy);
                local.put(self, key, tile);
                v
            }
            None => {
                let texel = |di: i64, dj: i64| texel_value(tex, &t.desc, level, [i0 + di, j0 + dj], d, fill);
                lerp2(texel(0, 0), texel(1, 0), texel(0, 1), texel(1, 1), fx, fy)
            }
        }
    }

    #[inline]
    fn shard(&self, key: &Key) -> &RwLock<TileMap> {
        // Middle bits: the map itself uses the low bits (bucket) and the top 7 (tag).
        &self.shards[(key.hash64() >> 32) as usize & (SHARDS - 1)]
    }

    /// The resident tile `key`, filling it on a miss; `None`: evaluate its texels directly.
    fn acquire<F>(&self, t: &Texture, key: Key, fill: &F) -> Option<Arc<Tile>>
    where
        F: Fn(TexelRequest) -> Texel + ?Sized,
    {
        let shard = self.shard(&key);
        let flight = {
            let map = read(shard);
            match map.get(&key) {
                Some(Slot::Ready(tile)) => {
                    tile.touch();
                    return Some(tile.clone());
                }
                Some(Slot::Filling(f)) => Some(f.clone()),
                None => None,
            }
        };
        match flight {
            Some(f) => self.join(t, &key, &f),
            None => self.miss(t, key, fill),
        }
    }

    /// A tile someone else is filling: wait for it or evaluate directly, per [`InFlight`].
    fn join(&self, t: &Texture, key: &Key, flight: &Flight) -> Option<Arc<Tile>> {
        let c = t.counters.level(key.level);
        let wait = self.config.in_flight == InFlight::Wait && flight.filler != std::thread::current().id();
        let tile = if wait { flight.wait() } else { None };
        match &tile {
            Some(_) => c.waits.fetch_add(1, Relaxed),
            None => c.direct.fetch_add(1, Relaxed),
        };
        tile
    }

    /// A miss: claim the tile (single flight), reserve its bytes, fill it, publish it.
    fn miss<F>(&self, t: &Texture, key: Key, fill: &F) -> Option<Arc<Tile>>
    where
        F: Fn(TexelRequest) -> Texel + ?Sized,
    {
        match self.fill_absent(t, key, fill, false) {
            Ok(tile) => tile,
            Err(Slot::Ready(tile)) => {
                tile.touch();
                Some(tile)
            }
            Err(Slot::Filling(f)) => self.join(t, &key, &f),
        }
    }

    /// Fills tile `tile` of `tex` at `level` with `fill` and makes it resident, unless it is
    /// resident or being filled already or the budget has no room for it; `true` if it was
    /// filled. For a caller that computed the texture's texels alongside another texture's tile
    /// fill (the same level, tile and texel layout: [`TexelRequest::place`] says where each
    /// texel lies) and keeps them, so that the tile is resident for every thread from then on
    /// instead of filled again by whichever looks it up first. `fill` is asked for the tile's
    /// texels as a fill asks (and must give what a fill would).
    pub fn prefill<F>(&self, tex: TextureId, level: u8, tile: [i32; 2], fill: &F) -> bool
    where
        F: Fn(TexelRequest) -> Texel + ?Sized,
    {
        let t = &self.textures[tex.0 as usize];
        if level > t.desc.max_level {
            return false;
        }
        let key = Key { tex: tex.0, level, x: tile[0], y: tile[1] };
        matches!(self.fill_absent(t, key, fill, true), Ok(Some(_)))
    }

    /// Claims tile `key` (single flight), reserves its bytes, fills it and publishes it;
    /// `Ok(None)` when the budget has no room (joiners then evaluate directly), `Err` with the
    /// slot that holds the key when it is taken. `prefill`: for [`TileCache::prefill`], not a request's
    /// miss.
    fn fill_absent<F>(&self, t: &Texture, key: Key, fill: &F, prefill: bool) -> Result<Option<Arc<Tile>>, Slot>
    where
        F: Fn(TexelRequest) -> Texel + ?Sized,
    {
        let shard = self.shard(&key);
        let flight =
            Arc::new(Flight { filler: std::thread::current().id(), done: Mutex::new(None), ready: Condvar::new() });
        {
            let mut map = write(shard);
            if let Some(taken) = map.get(&key) {
                return Err(taken.clone());
            }
            map.insert(key, Slot::Filling(flight.clone()));
        }
        let mut guard = FillGuard { cache: self, key, flight: &flight, armed: true };
        let c = t.counters.level(key.level);
        if !self.reserve(t.tile_bytes) {
            if !prefill {
                c.direct.fetch_add(1, Relaxed);
            }
            return Ok(None); // the guard fails the flight: joiners evaluate directly too
        }
        let tile = Tile::fill(
            key,
            &t.desc,
            self.config.tile_size,
            t.tile_bytes,
            self.budget.clone(),
            t.counters.clone(),
            fill,
        );
        let tile = Arc::new(tile);
        guard.armed = false;
        write(shard).insert(key, Slot::Ready(tile.clone()));
        {
            let mut clock = lock(&self.clock);
            clock.ring.push_back(tile.clone());
            if clock.evicted.remove(&key) {
                c.refills.fetch_add(1, Relaxed);
            }
        }
        c.fills.fetch_add(1, Relaxed);
        if prefill {
            c.prefills.fetch_add(1, Relaxed);
        }
        c.texels_filled.fetch_add(tile.texel_count() as u64, Relaxed);
        flight.complete(Some(tile.clone()));
        Ok(Some(tile))
    }

    /// Removes `key`'s placeholder if it is still `flight`'s.
    fn remove_flight(&self, key: Key, flight: &Arc<Flight>) {
        let mut map = write(self.shard(&key));
        if matches!(map.get(&key), Some(Slot::Filling(f)) if Arc::ptr_eq(f, flight)) {
            map.remove(&key);
        }
    }

    /// Reserves `bytes` in the budget, evicting tiles to make room; `false` if it cannot.
    fn reserve(&self, bytes: usize) -> bool {
        for _ in 0..MAX_EVICTIONS_PER_RESERVE {
            if self.budget.try_reserve(bytes) {
                return true;
            }
            if !self.evict_one() {
                break;
            }
        }
        self.budget.try_reserve(bytes)
    }

    /// Evicts one tile by the CLOCK sweep (or FIFO); `false` if none is resident. The tile's
    /// bytes return to the budget when its last reader lets it go.
    fn evict_one(&self) -> bool {
        let victim = {
            let mut clock = lock(&self.clock);
            let mut second_chances = clock.ring.len();
            loop {
                let Some(tile) = clock.ring.pop_front() else { return false };
                if self.config.eviction == Eviction::Clock && second_chances > 0 && tile.referenced.load(Relaxed) {
                    tile.referenced.store(false, Relaxed);
                    clock.ring.push_back(tile);
                    second_chances -= 1;
                    continue;
                }
                if clock.evicted.len() < EVICTED_KEYS_MAX {
                    clock.evicted.insert(tile.key);
                }
                break tile;
            }
        };
        victim.evicted.store(true, Relaxed);
        let key = victim.key;
        {
            let mut map = write(self.shard(&key));
            if matches!(map.get(&key), Some(Slot::Ready(t)) if Arc::ptr_eq(t, &victim)) {
                map.remove(&key);
            }
        }
        self.textures[key.tex as usize].counters.level(key.level).evictions.fetch_add(1, Relaxed);
        true
    }

    /// Reads tile `key` from this thread's micro-cache, if it is there and not evicted.
    #[inline]
    fn micro_get<R>(&self, key: &Key, read: impl FnOnce(&Tile) -> R) -> Option<R> {
        let n = self.config.micro_cache;
        if n == 0 {
            return None;
        }
        MICRO
            .try_with(|m| {
                let mut m = m.try_borrow_mut().ok()?;
                let i = micro_slot(self.id, key, n);
                let e = m.slots[i].as_ref()?;
                if !(e.cache == self.id && e.key == *key) {
                    return None;
                }
                let tile = &e.tile;
                if tile.evicted.load(Relaxed) {
                    m.slots[i] = None; // let its bytes go back to the budget
                    return None;
                }
                tile.touch();
                Some(read(tile))
            })
            .ok()
            .flatten()
    }

    /// Puts a tile into its slot of this thread's micro-cache.
    #[inline]
    fn micro_put(&self, key: Key, tile: Arc<Tile>) {
        let n = self.config.micro_cache;
        if n == 0 {
            return;
        }
        let _ = MICRO.try_with(|m| {
            if let Ok(mut m) = m.try_borrow_mut() {
                let i = micro_slot(self.id, &key, n);
                m.slots[i] = Some(MicroEntry { cache: self.id, key, tile });
            }
        });
    }
}

/// Where a lookup finds the tiles it read recently and counts its requests.
trait Local {
    /// Reads tile `key` if it is held here and was not evicted.
    fn get<R>(&self, cache: &TileCache, key: &Key, read: impl FnOnce(&Tile) -> R) -> Option<R>;
    /// Holds `tile` for later lookups.
    fn put(&self, cache: &TileCache, key: Key, tile: Arc<Tile>);
    /// Counts one lookup of `tex`.
    fn count_lookup(&self, t: &Texture, tex: TextureId);
    /// Counts one tile request of `tex` at `level`.
    fn count_request(&self, t: &Texture, tex: TextureId, level: u8);
}

/// The calling thread's micro-cache and the cache's striped counters: what [`TileCache`]'s own
/// lookups use.
struct Shared;

impl Local for Shared {
    #[inline]
    fn get<R>(&self, cache: &TileCache, key: &Key, read: impl FnOnce(&Tile) -> R) -> Option<R> {
        cache.micro_get(key, read)
    }
    #[inline]
    fn put(&self, cache: &TileCache, key: Key, tile: Arc<Tile>) {
        cache.micro_put(key, tile)
    }
    #[inline]
    fn count_lookup(&self, t: &Texture, _: TextureId) {
        t.counters.count_lookup();
    }
    #[inline]
    fn count_request(&self, t: &Texture, _: TextureId, level: u8) {
        t.counters.count_request(level);
    }
}

/// A [`Reader`]'s slot: a tile and its key.
type ReaderSlot = Option<(Key, Arc<Tile>)>;

/// Counts a [`Reader`] keeps per texture: lookups, then requests per level.
const READER_COUNTS: usize = 2 + MAX_LEVEL as usize;

/// One thread's handle for many lookups into a [`TileCache`]: the same results as the cache's
/// own lookups, bit for bit, with the recent tiles in a table of the reader's own instead of the
/// thread's micro-cache, and the hit-path counts kept in plain integers until the reader is
/// dropped (or [`Reader::flush`]ed).
///
/// The table has [`CacheConfig::micro_cache`] slots rounded up to a power of two, indexed by a
/// multiplicative hash of the tile's key; each holds a strong reference to its tile, as the
/// micro-cache does (the same budget caveat applies, per live reader). A hit reads the slot,
/// checks the tile's eviction flag and taps it: no thread-local access, no shared counter, no
/// lock. Lookups are re-entrant (a miss's fill may look up other textures through the same
/// reader): the table is borrowed only around reads and writes of one slot.
pub struct Reader<'c> {
    cache: &'c TileCache,
    slots: RefCell<Box<[ReaderSlot]>>,
    /// `64 − log2(slots)`: the hash's top bits index the table.
    shift: u32,
    /// Per texture [`READER_COUNTS`] counts: lookups, then requests at each level.
    counts: Box<[std::cell::Cell<u64>]>,
}

impl TileCache {
    /// A [`Reader`] for one thread's lookups.
    pub fn reader(&self) -> Reader<'_> {
        let n = self.config.micro_cache.next_power_of_two().max(2);
        let slots = if self.config.micro_cache == 0 { 0 } else { n };
        Reader {
            cache: self,
            slots: RefCell::new((0..slots).map(|_| None).collect()),
            shift: 64 - n.trailing_zeros(),
            counts: (0..self.textures.len() * READER_COUNTS).map(|_| std::cell::Cell::new(0)).collect(),
        }
    }
}

impl Reader<'_> {
    /// [`TileCache::lookup`] through this reader.
    pub fn lookup<F>(&self, tex: TextureId, uv: Vec2, cov_uv: Mat2, filter: Filter, fill: &F) -> [f32; 3]
    where
        F: Fn(TexelRequest) -> [f32; 3] + ?Sized,
    {
        self.lookup_with_level(tex, uv, cov_uv, self.cache.filter_level(tex, cov_uv, filter), filter, fill)
    }

    /// [`TileCache::lookup_with_level`] through this reader.
    #[inline]
    pub fn lookup_with_level<F>(
        &self,
        tex: TextureId,
        uv: Vec2,
        cov_uv: Mat2,
        level: f32,
        filter: Filter,
        fill: &F,
    ) -> [f32; 3]
    where
        F: Fn(TexelRequest) -> [f32; 3] + ?Sized,
    {
        self.cache.lookup_in(self, tex, uv, cov_uv, level, filter, fill)
    }

    /// Adds the counts kept so far to the cache's statistics.
    pub fn flush(&self) {
        for (t, counts) in self.cache.textures.iter().zip(self.counts.chunks_exact(READER_COUNTS)) {
            for (slot, c) in counts.iter().enumerate() {
                t.counters.add_counted(slot, c.replace(0));
            }
        }
    }

    #[inline]
    fn slot(&self, key: &Key) -> usize {
        let h = u64::from(key.x as u32).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ u64::from(key.y as u32).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
            ^ (u64::from(key.tex) << 8 | u64::from(key.level)).wrapping_mul(0x1656_67B1_9E37_79F9);
        (h >> self.shift) as usize
    }

    #[inline]
    fn bump(&self, tex: TextureId, slot: usize) {
        let c = &self.counts[tex.0 as usize * READER_COUNTS + slot];
        c.set(c.get() + 1);
    }
}

impl Local for Reader<'_> {
    #[inline]
    fn get<R>(&self, _: &TileCache, key: &Key, read: impl FnOnce(&Tile) -> R) -> Option<R> {
        let mut slots = self.slots.try_borrow_mut().ok()?;
        if slots.is_empty() {
            return None;
        }
        let i = self.slot(key);
        let (k, tile) = slots[i].as_ref()?;
        if k != key {
            return None;
        }
        if tile.evicted.load(Relaxed) {
            slots[i] = None; // let its bytes go back to the budget
            return None;
        }
        tile.touch();
        Some(read(tile))
    }
    #[inline]
    fn put(&self, _: &TileCache, key: Key, tile: Arc<Tile>) {
        if let Ok(mut slots) = self.slots.try_borrow_mut() {
            if !slots.is_empty() {
                let i = self.slot(&key);
                slots[i] = Some((key, tile));
            }
        }
    }
    #[inline]
    fn count_lookup(&self, _: &Texture, tex: TextureId) {
        self.bump(tex, 0);
    }
    #[inline]
    fn count_request(&self, _: &Texture, tex: TextureId, level: u8) {
        self.bump(tex, 1 + usize::from(level));
    }
}

impl Drop for Reader<'_> {
    fn drop(&mut self) {
        self.flush();
    }
}

impl std::fmt::Debug for TileCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TileCache")
            .field("config", &self.config)
            .field("textures", &self.textures.iter().map(|t| t.desc).collect::<Vec<_>>())
            .field("resident_bytes", &self.budget.allocated())
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    const T: u32 = 8;

    fn desc(channels: u8, format: TexelFormat) -> TextureDesc {
        TextureDesc { channels, format, texels_per_uv: 16.0, max_level: 6 }
    }

    fn cache(budget_tiles: usize, micro_cache: usize) -> (TileCache, TextureId) {
        let d = desc(3, TexelFormat::F32);
        let one = tile::tile_bytes(&d, T);
        let config =
            CacheConfig { tile_size: T, budget_bytes: budget_tiles * one, micro_cache, ..CacheConfig::default() };
        let mut c = TileCache::new(config).unwrap();
        let id = c.add_texture(d).unwrap();
        (c, id)
    }

    /// A point lookup at level `level` (level-clamped filter).
    fn at<F: Fn(TexelRequest) -> Texel>(c: &TileCache, id: TextureId, uv: Vec2, level: u8, fill: &F) -> Texel {
        c.lookup(id, uv, Mat2::ZERO, Filter::TRILINEAR.levels(level, level), fill)
    }

    #[test]
    fn cache_is_send_and_sync() {
        fn check<T: Send + Sync>() {}
        check::<TileCache>();
    }

    #[test]
    fn bad_settings_are_errors() {
        let ok = CacheConfig::default();
        assert_eq!(TileCache::new(CacheConfig { budget_bytes: 0, ..ok }).unwrap_err(), CacheError::ZeroBudget);
        assert!(matches!(
            TileCache::new(CacheConfig { budget_bytes: 300, ..ok }).unwrap_err(),
            CacheError::BudgetBelowOneTile { budget: 300, .. }
        ));
        assert_eq!(TileCache::new(CacheConfig { tile_size: 1, ..ok }).unwrap_err(), CacheError::TileSize(1));
        assert_eq!(TileCache::new(CacheConfig { tile_size: 24, ..ok }).unwrap_err(), CacheError::TileSize(24));
        assert_eq!(TileCache::new(CacheConfig { tile_size: 2048, ..ok }).unwrap_err(), CacheError::TileSize(2048));
        let too_many = MICRO_CACHE_MAX + 1;
        assert_eq!(
            TileCache::new(CacheConfig { micro_cache: too_many, ..ok }).unwrap_err(),
            CacheError::MicroCache(too_many)
        );
        let mut c = TileCache::new(ok).unwrap();
        let d = desc(3, TexelFormat::F32);
        assert_eq!(c.add_texture(TextureDesc { channels: 4, ..d }).unwrap_err(), CacheError::Channels(4));
        assert_eq!(c.add_texture(TextureDesc { channels: 0, ..d }).unwrap_err(), CacheError::Channels(0));
        for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert!(matches!(c.add_texture(TextureDesc { texels_per_uv: bad, ..d }), Err(CacheError::Density(_))));
        }
        assert_eq!(c.add_texture(TextureDesc { max_level: 32, ..d }).unwrap_err(), CacheError::MaxLevel(32));
        // A budget that fits the smallest tile but not a 3-channel f32 one.
        let small = tile::tile_bytes(&desc(1, TexelFormat::F16), 16);
        let mut c = TileCache::new(CacheConfig { budget_bytes: small, ..ok }).unwrap();
        assert!(c.add_texture(desc(1, TexelFormat::F16)).is_ok());
        assert!(matches!(c.add_texture(d), Err(CacheError::BudgetBelowOneTile { .. })));
        // Messages name the numbers.
        let msg = TileCache::new(CacheConfig { budget_bytes: 300, ..ok }).unwrap_err().to_string();
        assert!(msg.contains("300 bytes") && msg.contains("16×16"), "{msg}");
    }

    #[test]
    fn formats_round_and_extra_channels_are_zero() {
        let fill = |_: TexelRequest| [0.1, 0.2, 0.3];
        for (ch, format) in [(1, TexelFormat::F32), (2, TexelFormat::F16), (3, TexelFormat::F16)] {
            let mut c = TileCache::new(CacheConfig::default()).unwrap();
            let id = c.add_texture(desc(ch, format)).unwrap();
            let v =
                c.lookup(id, Vec2::new(0.3, -7.2), Mat2::from_diagonal(Vec2::splat(1e-3)), Filter::TRILINEAR, &fill);
            for (k, &want) in [0.1f32, 0.2, 0.3].iter().enumerate() {
                let want = match (k < usize::from(ch), format) {
                    (false, _) => 0.0,
                    (true, TexelFormat::F32) => want,
                    (true, TexelFormat::F16) => half::f16::from_f32(want).to_f32(),
                };
                assert_eq!(v[k], want, "{ch} {format:?} channel {k}");
            }
        }
    }

    /// Half-float tiles clamp values beyond ±65504 instead of storing infinities (a bilinear
    /// tap weighs its four texels, and 0 × ∞ is NaN), and count them; NaN is stored as NaN.
    #[test]
    fn half_floats_saturate_and_count_instead_of_overflowing() {
        let mut c = TileCache::new(CacheConfig::default()).unwrap();
        let id = c.add_texture(desc(3, TexelFormat::F16)).unwrap();
        // Channel 0 grows past the half range across the tile, channel 1 is far beyond it
        // (negative), channel 2 stays in range.
        let fill = |r: TexelRequest| [65000.0 + 100.0 * r.texel[0] as f32, -1e30, 1.5];
        let fine = Mat2::from_diagonal(Vec2::splat(1e-6));
        for k in 0..32 {
            let uv = Vec2::new(k as f32 * 0.05, 0.02);
            let v = c.lookup(id, uv, fine, Filter::TRILINEAR, &fill);
            assert!(v.iter().all(|x| x.is_finite()), "uv {uv}: {v:?}");
            assert!(v[0] <= 65504.0 && v[0] > 64000.0, "{v:?}");
            assert_eq!(v[1], -65504.0);
            assert_eq!(v[2], 1.5);
        }
        let total = c.stats().total();
        assert!(total.texels_filled > 0);
        // Channel 1 saturates at every texel; channel 0 wherever 65000 + 100 x > 65504.
        assert!(total.texels_saturated > total.texels_filled, "{total:?}");
        assert!(total.texels_saturated < 2 * total.texels_filled, "{total:?}");
        // F32 textures store what they are given.
        let mut c = TileCache::new(CacheConfig::default()).unwrap();
        let id = c.add_texture(desc(1, TexelFormat::F32)).unwrap();
        let v = c.lookup(id, Vec2::new(0.3, 0.3), fine, Filter::TRILINEAR, &|_| [1e30, 0.0, 0.0]);
        assert_eq!(v[0], 1e30);
        assert_eq!(c.stats().total().texels_saturated, 0);
        // NaN stays NaN (the fill that made it is where it is reported).
        let mut c = TileCache::new(CacheConfig::default()).unwrap();
        let id = c.add_texture(desc(1, TexelFormat::F16)).unwrap();
        let v = c.lookup(id, Vec2::new(0.3, 0.3), fine, Filter::TRILINEAR, &|_| [f32::NAN, 0.0, 0.0]);
        assert!(v[0].is_nan());
    }
    /// Bilinear interpolation reproduces an affine function, across tile borders and at negative
    /// tile coordinates, and hits texel values exactly at texel centres.
    #[test]
    fn bilinear_reproduces_affine_functions_everywhere() {
        let (c, id) = cache(64, 4);
        let fill = |r: TexelRequest| [r.uv.x + 2.0 * r.uv.y, r.texel[0] as f32, r.texel[1] as f32];
        for level in [0u8, 1, 3] {
            let d = 16.0 * (-(level as f32)).exp2();
            for k in 0..400 {
                let uv = Vec2::new(-3.0 + k as f32 * 0.0173, 2.1 - k as f32 * 0.0111);
                let v = at(&c, id, uv, level, &fill);
                // Inside the range of texel centres the interpolant is exact up to rounding.
                assert!((v[0] - (uv.x + 2.0 * uv.y)).abs() < 1e-5, "level {level} uv {uv}: {v:?}");
                assert!((v[1] - (uv.x * d - 0.5)).abs() < 1e-3);
                // Texel centres read one texel exactly.
                let ij = (uv * d).floor();
                let centre = (ij + 0.5) / d;
                assert_eq!(at(&c, id, centre, level, &fill)[1..], [ij.x, ij.y]);
            }
        }
    }

    /// Level clamping: the fill only sees levels inside the clamp, whatever the footprint.
    #[test]
    fn level_clamp_bounds_the_levels_read() {
        let (c, id) = cache(64, 0);
        let seen = Cell::new((u8::MAX, 0u8));
        let fill = |r: TexelRequest| {
            let (lo, hi) = seen.get();
            seen.set((lo.min(r.level), hi.max(r.level)));
            [1.0; 3]
        };
        for cov in [Mat2::ZERO, Mat2::IDENTITY * 1e-4, Mat2::IDENTITY * 100.0] {
            for kind in [Filter::TRILINEAR, Filter::anisotropic(8.0)] {
                c.lookup(id, Vec2::new(0.2, 0.7), cov, kind.levels(2, 4), &fill);
            }
        }
        assert_eq!(seen.get(), (2, 4));
        // Above the texture's levels: clamped to max_level (6).
        c.lookup(id, Vec2::ZERO, Mat2::IDENTITY * 1e6, Filter::TRILINEAR.levels(9, 200), &fill);
        assert_eq!(seen.get(), (2, 6));
        assert_eq!(c.lookup_level(id, Vec2::ZERO, f32::NAN, &fill), [1.0; 3]);
    }

    /// Counts in a scripted single-threaded run: fills, hits, CLOCK's second chance, refills.
    #[test]
    fn statistics_follow_a_scripted_run() {
        let (c, id) = cache(2, 0); // two tiles
        let fill = |_: TexelRequest| [1.0; 3];
        let tile = |x: f32| Vec2::new((x * 8.0 + 1.0) / 16.0, 0.1); // level 0: 16 texels/uv, T = 8
        at(&c, id, tile(0.0), 0, &fill); // A: fill
        at(&c, id, tile(1.0), 0, &fill); // B: fill
        at(&c, id, tile(0.0), 0, &fill); // A: hit (reference bit)
        at(&c, id, tile(2.0), 0, &fill); // C: evicts B (A has a second chance)
        at(&c, id, tile(0.0), 0, &fill); // A: hit
        at(&c, id, tile(1.0), 0, &fill); // B: refill
        let s = c.stats();
        let l0 = s.textures[0].levels[0];
        assert_eq!((l0.requests, l0.hits, l0.misses, l0.fills, l0.evictions, l0.refills), (6, 2, 4, 4, 2, 1));
        assert_eq!(l0.texels_filled, 4 * 81);
        assert_eq!(s.textures[0].lookups, 6);
        assert_eq!(s.resident_bytes, 2 * c.tile_bytes(id) as u64);
        assert_eq!(s.peak_bytes, s.resident_bytes);
        assert_eq!(l0.resident_bytes, s.resident_bytes);
        assert_eq!((s.budget_checks, s.over_budget), (4, 0));
        assert_eq!(c.resident_tiles(), 2);
        // FIFO evicts A for C, then A's refill evicts B and B's refill evicts C.
        let mut fifo = TileCache::new(CacheConfig { eviction: Eviction::Fifo, ..*c.config() }).unwrap();
        let id = fifo.add_texture(desc(3, TexelFormat::F32)).unwrap();
        for x in [0.0, 1.0, 0.0, 2.0, 0.0, 1.0] {
            at(&fifo, id, tile(x), 0, &fill);
        }
        let l0 = fifo.stats().textures[0].levels[0];
        assert_eq!((l0.fills, l0.evictions, l0.refills, l0.hits), (5, 3, 2, 1));
    }

    /// A fill asks for its tile's texels with their places (row by row, border included), and
    /// a tile made by `prefill` from the values a fill was given is that fill's tile: lookups
    /// read the same bits and never call their fill. `prefill` leaves a resident tile alone and
    /// a level the texture lacks untouched.
    #[test]
    fn prefill_makes_the_tile_a_fill_would() {
        let value = |r: &TexelRequest| [r.uv.x * 3.0 - r.uv.y, (5.0 * r.uv.y).sin(), f32::from(r.level)];
        let (a, id) = cache(64, 0);
        let seen = std::cell::RefCell::new(Vec::new());
        let fill = |r: TexelRequest| {
            seen.borrow_mut().push(r);
            value(&r)
        };
        let uv = Vec2::new(0.30, 0.55); // level 1: 8 texels per uv, tile (0, 0) of T = 8
        let want = at(&a, id, uv, 1, &fill);
        let reqs = seen.take();
        let side = T as usize + 1;
        assert_eq!(reqs.len(), side * side);
        for (k, r) in reqs.iter().enumerate() {
            let place = r.place.expect("a tile fill's texels have places");
            assert_eq!((place.tile, place.index, place.count), ([0, 0], k as u32, (side * side) as u32));
            assert_eq!(r.texel, [(k % side) as i64, (k / side) as i64]);
        }
        let (b, bid) = cache(64, 0);
        let values: Vec<[f32; 3]> = reqs.iter().map(value).collect();
        let from_values = |r: TexelRequest| values[r.place.unwrap().index as usize];
        assert!(b.prefill(bid, 1, [0, 0], &from_values));
        let never = |_: TexelRequest| -> [f32; 3] { panic!("the prefilled tile was filled again") };
        assert_eq!(at(&b, bid, uv, 1, &never).map(f32::to_bits), want.map(f32::to_bits));
        assert!(!b.prefill(bid, 1, [0, 0], &never), "a resident tile is made again");
        assert!(!b.prefill(bid, 7, [0, 0], &never), "level 7 of a texture of levels 0–6");
        let l1 = b.stats().textures[0].levels[1];
        assert_eq!((l1.fills, l1.prefills, l1.misses, l1.hits), (1, 1, 0, 1));
        // Texels evaluated alone (no room for a tile: one tile of budget, pinned by this
        // thread's micro-cache) have no place; those of fills come a whole tile at a time.
        let (tiny, tid) = cache(1, 4);
        let (alone, placed) = (Cell::new(0u64), Cell::new(0u64));
        let count = |r: TexelRequest| {
            let c = if r.place.is_some() { &placed } else { &alone };
            c.set(c.get() + 1);
            [0.0; 3]
        };
        for k in 0..64 {
            let uv = Vec2::new(k as f32 * 0.37 % 4.0, k as f32 * 0.61 % 4.0);
            at(&tiny, tid, uv, 0, &count);
        }
        let t = tiny.stats().total();
        assert!(t.direct > 0 && t.fills > 0, "{t:?}");
        assert_eq!(placed.get(), t.fills * (side * side) as u64);
        assert!(alone.get() > 0);
    }

    /// Lookups answered by direct evaluation (no room in the budget) equal those answered by
    /// tiles, bit for bit.
    #[test]
    fn direct_evaluation_matches_tiles_bit_for_bit() {
        let fill = |r: TexelRequest| {
            let (u, v) = (r.uv.x, r.uv.y);
            [(7.0 * u).sin() * (3.0 * v).cos(), u * v, f32::from(r.level)]
        };
        let (big, id) = cache(4096, 4);
        // One tile of budget, pinned by this thread's micro-cache: every other tile is direct.
        let (tiny, tid) = cache(1, 4);
        let mut s = 0x1234_5678_u64;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        for _ in 0..2000 {
            let uv = Vec2::new(rnd() * 8.0 - 4.0, rnd() * 8.0 - 4.0);
            let cov = Mat2::from_cols(Vec2::new(rnd() * 1e-2, 0.0), Vec2::new(0.0, rnd() * 1e-3));
            for f in [Filter::TRILINEAR, Filter::anisotropic(8.0)] {
                let a = big.lookup(id, uv, cov, f, &fill);
                let b = tiny.lookup(tid, uv, cov, f, &fill);
                assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits), "uv {uv} cov {cov}");
            }
        }
        let t = tiny.stats().total();
        assert!(t.direct > 1000 && t.fills >= 1, "{t:?}");
        assert!(tiny.stats().peak_bytes <= tiny.config().budget_bytes as u64);
    }

    /// The micro-cache's slots spread a render's working set: the tiles of three textures'
    /// coarse levels (8 × 8, 4 × 4 and 2 × 2 tiles each) land in about as many distinct slots of
    /// 256 as keys thrown at random would (135 expected for 252 keys), and always in range.
    #[test]
    fn micro_slots_spread_tiles() {
        let mut used = std::collections::HashSet::new();
        let mut keys = 0;
        for tex in 0..3u32 {
            for (level, side) in [(8u8, 8i32), (9, 4), (10, 2)] {
                for x in 0..side {
                    for y in 0..side {
                        let slot = micro_slot(7, &Key { tex, level, x, y }, 256);
                        assert!(slot < 256);
                        used.insert(slot);
                        keys += 1;
                    }
                }
            }
        }
        let expected = 256.0 * (1.0 - (-(keys as f64) / 256.0).exp());
        assert!(used.len() as f64 > 0.85 * expected, "{} slots for {keys} keys", used.len());
        // Another cache's tiles take other slots.
        let k = Key { tex: 0, level: 8, x: 1, y: 2 };
        assert!((0..8u64).map(|c| micro_slot(c, &k, 256)).collect::<std::collections::HashSet<_>>().len() > 4);
    }

    /// Evicted tiles still read by a thread keep counting until that thread lets them go.
    #[test]
    fn micro_cache_releases_evicted_tiles() {
        let (c, id) = cache(1, 4);
        let fill = |_: TexelRequest| [1.0; 3];
        at(&c, id, Vec2::new(0.1, 0.1), 0, &fill); // tile A, resident and in the micro-cache
        assert!(c.evict_one());
        assert_eq!(c.resident_bytes(), c.tile_bytes(id)); // still held by this thread
        at(&c, id, Vec2::new(0.1, 0.1), 0, &fill); // sees A evicted, drops it, refills
        let l0 = c.stats().textures[0].levels[0];
        assert_eq!((l0.fills, l0.refills, l0.direct), (2, 1, 0));
        assert_eq!(c.resident_bytes(), c.tile_bytes(id));
    }

    /// A [`Reader`] answers every lookup with the cache's own bits (tiles resident or not, both
    /// filters, re-entrant fills through the same reader), and once dropped its counts equal the
    /// cache's own counting of the same lookups (fills too where the budget holds every tile;
    /// under a tight one, which tiles stay pinned depends on the handle).
    #[test]
    fn reader_matches_the_cache_bit_for_bit_and_counts_alike() {
        let inner_desc = desc(1, TexelFormat::F16);
        for (budget_tiles, micro) in [(4096, 64), (4096, 0), (3, 4), (4096, 1)] {
            let d = desc(3, TexelFormat::F16);
            let one = tile::tile_bytes(&d, T);
            let config = CacheConfig {
                tile_size: T,
                budget_bytes: budget_tiles * one,
                micro_cache: micro,
                ..CacheConfig::default()
            };
            let make = || {
                let mut c = TileCache::new(config).unwrap();
                let outer = c.add_texture(d).unwrap();
                let inner = c.add_texture(inner_desc).unwrap();
                (c, outer, inner)
            };
            let (a, a_out, a_in) = make();
            let (b, b_out, b_in) = make();
            let inner_fill = |r: TexelRequest| [(5.0 * r.uv.x).sin() + r.uv.y, 0.0, 0.0];
            let mut s = 0x9E37_79B9_u64;
            let mut rnd = || {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 40) as f32 / (1u64 << 24) as f32
            };
            let reader = b.reader();
            // The outer texture's fill looks the inner one up (a cached node upstream of another).
            let fill_a = |r: TexelRequest| {
                let v = a.lookup(a_in, r.uv, r.covariance(), Filter::TRILINEAR, &inner_fill)[0];
                [v, r.uv.x * v, f32::from(r.level)]
            };
            let fill_b = |r: TexelRequest| {
                let v = reader.lookup(b_in, r.uv, r.covariance(), Filter::TRILINEAR, &inner_fill)[0];
                [v, r.uv.x * v, f32::from(r.level)]
            };
            for k in 0..3000 {
                let uv = Vec2::new(rnd() * 4.0 - 2.0, rnd() * 4.0 - 2.0);
                let sx = 10f32.powf(rnd() * 3.0 - 3.5);
                let cov = Mat2::from_cols(Vec2::new(sx * sx, 0.0), Vec2::new(0.0, sx * sx * rnd()));
                let f = if k % 3 == 0 { Filter::anisotropic(8.0) } else { Filter::TRILINEAR };
                let x = a.lookup(a_out, uv, cov, f, &fill_a);
                let y = reader.lookup(b_out, uv, cov, f, &fill_b);
                assert_eq!(x.map(f32::to_bits), y.map(f32::to_bits), "budget {budget_tiles} micro {micro} uv {uv}");
            }
            drop(reader);
            let (sa, sb) = (a.stats(), b.stats());
            // Under the tight budget the inner texture is looked up once per texel evaluated, and
            // which outer tiles stay pinned (hence which texels are evaluated) depends on the handle.
            let compared = if budget_tiles > 3 { 2 } else { 1 };
            for (ta, tb) in sa.textures.iter().zip(&sb.textures).take(compared) {
                assert_eq!(ta.lookups, tb.lookups, "budget {budget_tiles} micro {micro}");
                for (la, lb) in ta.levels.iter().zip(&tb.levels) {
                    assert_eq!(la.requests, lb.requests, "budget {budget_tiles} micro {micro}");
                    if budget_tiles > 3 {
                        assert_eq!(la.fills, lb.fills, "budget {budget_tiles} micro {micro}");
                    }
                }
            }
            assert_eq!(sb.textures[0].lookups, 3000);
            assert!(sb.total().requests > 6000);
        }
    }

    /// A reader's slots spread a render's working set like keys thrown at random (see
    /// `micro_slots_spread_tiles`), and a reader lets go of a tile evicted under it.
    #[test]
    fn reader_slots_spread_and_release_evicted_tiles() {
        let (c, id) = cache(1, 256);
        let r = c.reader();
        let mut used = std::collections::HashSet::new();
        let mut keys = 0;
        for tex in 0..3u32 {
            for (level, side) in [(8u8, 8i32), (9, 4), (10, 2)] {
                for x in 0..side {
                    for y in 0..side {
                        used.insert(r.slot(&Key { tex, level, x, y }));
                        keys += 1;
                    }
                }
            }
        }
        let expected = 256.0 * (1.0 - (-(keys as f64) / 256.0).exp());
        assert!(used.len() as f64 > 0.85 * expected, "{} slots for {keys} keys", used.len());
        assert!(used.iter().all(|&i| i < 256));
        let fill = |_: TexelRequest| [1.0; 3];
        let one = Filter::TRILINEAR.levels(0, 0);
        r.lookup(id, Vec2::new(0.1, 0.1), Mat2::ZERO, one, &fill);
        assert!(c.evict_one());
        assert_eq!(c.resident_bytes(), c.tile_bytes(id)); // still held by the reader
        r.lookup(id, Vec2::new(0.1, 0.1), Mat2::ZERO, one, &fill); // sees it evicted, refills
        assert_eq!(c.resident_bytes(), c.tile_bytes(id));
        drop(r);
        let l0 = c.stats().textures[0].levels[0];
        assert_eq!((l0.requests, l0.fills, l0.refills), (2, 2, 1));
    }
}
