//! Statistics and the byte budget's accounting.
//!
//! Hit-path counters (lookups, tile requests) are striped per thread: each thread adds to its
//! own cache line, so counting costs one uncontended atomic add. Everything else (misses, fills,
//! evictions, bytes) is counted on the miss path in plain shared atomics.

use std::cell::Cell;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};

use crate::TextureId;

/// Counters of one level of one texture (or a sum of several).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LevelStats {
    /// Tile requests: one per bilinear tap (a trilinear lookup makes one or two, an anisotropic
    /// one up to two per probe). Zero when [`crate::CacheConfig::count_requests`] is off.
    pub requests: u64,
    /// Requests answered by a resident tile (`requests − misses`; zero when not counted).
    pub hits: u64,
    /// Requests that found no resident tile: `fills − prefills + waits + direct`.
    pub misses: u64,
    /// Tiles filled (on a miss or by [`crate::TileCache::prefill`]).
    pub fills: u64,
    /// Tiles made by [`crate::TileCache::prefill`] from texels computed alongside another
    /// texture's fill (counted in `fills`, not a request's miss).
    pub prefills: u64,
    /// Requests that waited for another thread's fill of the same tile ([`crate::InFlight::Wait`]).
    pub waits: u64,
    /// Requests answered by evaluating their texels directly: the tile was being filled
    /// ([`crate::InFlight::Evaluate`]), no room could be made within the budget, or a fill failed.
    pub direct: u64,
    /// Texels filled into tiles (border texels included).
    pub texels_filled: u64,
    /// Texels evaluated directly (four per direct request).
    pub texels_direct: u64,
    /// Channel values filled into half-float tiles that lay beyond ±65504 and were stored
    /// clamped to it (a value's magnitude, not its detail, is lost; zero for `F32` textures).
    pub texels_saturated: u64,
    /// Tiles evicted.
    pub evictions: u64,
    /// Fills of tiles that had been evicted before (the cache remembers up to 2²⁰ evicted keys;
    /// past that, a lower bound).
    pub refills: u64,
    /// Bytes of live tiles now.
    pub resident_bytes: u64,
    /// Most bytes of live tiles at any time (in sums: the sum of the parts' peaks).
    pub peak_bytes: u64,
}

impl std::ops::AddAssign<&LevelStats> for LevelStats {
    fn add_assign(&mut self, o: &LevelStats) {
        self.requests += o.requests;
        self.hits += o.hits;
        self.misses += o.misses;
        self.fills += o.fills;
        self.prefills += o.prefills;
        self.waits += o.waits;
        self.direct += o.direct;
        self.texels_filled += o.texels_filled;
        self.texels_direct += o.texels_direct;
        self.texels_saturated += o.texels_saturated;
        self.evictions += o.evictions;
        self.refills += o.refills;
        self.resident_bytes += o.resident_bytes;
        self.peak_bytes += o.peak_bytes;
    }
}

/// Counters of one texture.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureStats {
    /// The texture.
    pub id: TextureId,
    /// Filtered lookups (calls of [`crate::TileCache::lookup`]); zero when not counted.
    pub lookups: u64,
    /// Bytes one tile of this texture is charged.
    pub tile_bytes: u64,
    /// Per level, `0..=max_level`.
    pub levels: Vec<LevelStats>,
}

impl TextureStats {
    /// The sum over levels.
    pub fn total(&self) -> LevelStats {
        let mut t = LevelStats::default();
        for l in &self.levels {
            t += l;
        }
        t
    }
}

/// A snapshot of a cache's statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct CacheStats {
    /// The byte budget.
    pub budget_bytes: u64,
    /// The tile side.
    pub tile_size: u32,
    /// Bytes of live tiles now (resident, being filled, or evicted but still held by a reader).
    pub resident_bytes: u64,
    /// Most bytes of live tiles at any time.
    pub peak_bytes: u64,
    /// Tile allocations, each checked against the budget when it was made.
    pub budget_checks: u64,
    /// Allocations that found the live bytes above the budget (0 unless the cache is broken).
    pub over_budget: u64,
    /// Per texture, in [`TextureId`] order.
    pub textures: Vec<TextureStats>,
}

impl CacheStats {
    /// The sum over textures and levels.
    pub fn total(&self) -> LevelStats {
        let mut t = LevelStats::default();
        for tex in &self.textures {
            t += &tex.total();
        }
        t
    }
}

/// The byte budget: reservations (made before a fill) and allocations (the tile buffers made).
pub(crate) struct Budget {
    pub limit: usize,
    reserved: AtomicUsize,
    allocated: AtomicUsize,
    peak: AtomicUsize,
    checks: AtomicU64,
    over: AtomicU64,
}

impl Budget {
    pub fn new(limit: usize) -> Budget {
        Budget {
            limit,
            reserved: AtomicUsize::new(0),
            allocated: AtomicUsize::new(0),
            peak: AtomicUsize::new(0),
            checks: AtomicU64::new(0),
            over: AtomicU64::new(0),
        }
    }

    /// Reserves `bytes` if they fit under the limit.
    pub fn try_reserve(&self, bytes: usize) -> bool {
        self.reserved.fetch_update(Relaxed, Relaxed, |r| r.checked_add(bytes).filter(|&n| n <= self.limit)).is_ok()
    }

    /// Charges an allocation of `bytes` (made under a reservation) and checks the budget.
    pub fn allocate(&self, bytes: usize) {
        let now = self.allocated.fetch_add(bytes, Relaxed) + bytes;
        self.checks.fetch_add(1, Relaxed);
        if now > self.limit {
            self.over.fetch_add(1, Relaxed);
        }
        self.peak.fetch_max(now, Relaxed);
    }

    /// Releases an allocation and its reservation.
    pub fn free(&self, allocated: usize, reserved: usize) {
        self.allocated.fetch_sub(allocated, Relaxed);
        self.reserved.fetch_sub(reserved, Relaxed);
    }

    pub fn allocated(&self) -> usize {
        self.allocated.load(Relaxed)
    }

    pub fn fill_stats(&self, s: &mut CacheStats) {
        s.budget_bytes = self.limit as u64;
        s.resident_bytes = self.allocated.load(Relaxed) as u64;
        s.peak_bytes = self.peak.load(Relaxed) as u64;
        s.budget_checks = self.checks.load(Relaxed);
        s.over_budget = self.over.load(Relaxed);
    }
}

/// Miss-side counters of one level.
#[derive(Default)]
pub(crate) struct LevelCounters {
    pub fills: AtomicU64,
    pub prefills: AtomicU64,
    pub waits: AtomicU64,
    pub direct: AtomicU64,
    pub texels_filled: AtomicU64,
    pub texels_saturated: AtomicU64,
    pub evictions: AtomicU64,
    pub refills: AtomicU64,
    resident: AtomicU64,
    peak: AtomicU64,
}

impl LevelCounters {
    pub fn add_resident(&self, bytes: usize) {
        let now = self.resident.fetch_add(bytes as u64, Relaxed) + bytes as u64;
        self.peak.fetch_max(now, Relaxed);
    }

    pub fn sub_resident(&self, bytes: usize) {
        self.resident.fetch_sub(bytes as u64, Relaxed);
    }
}

/// Stripes of the hit-path counters (threads are spread over them round-robin).
const STRIPES: usize = 16;

/// One cache line of counters.
#[repr(align(64))]
#[derive(Default)]
struct Line([AtomicU64; 8]);

/// All counters of one texture.
pub(crate) struct TextureCounters {
    levels: Box<[LevelCounters]>,
    /// Per stripe `lines_per_stripe` lines: slot 0 lookups, slot `1 + ℓ` requests at level ℓ.
    hot: Box<[Line]>,
    lines_per_stripe: usize,
}

thread_local! {
    static STRIPE: Cell<usize> = const { Cell::new(usize::MAX) };
}

static NEXT_STRIPE: AtomicUsize = AtomicUsize::new(0);

/// This thread's stripe.
#[inline]
fn stripe() -> usize {
    STRIPE
        .try_with(|s| {
            let v = s.get();
            if v != usize::MAX {
                return v;
            }
            let v = NEXT_STRIPE.fetch_add(1, Relaxed) % STRIPES;
            s.set(v);
            v
        })
        .unwrap_or(0)
}

impl TextureCounters {
    pub fn new(levels: usize) -> TextureCounters {
        let lines_per_stripe = (levels + 1).div_ceil(8);
        TextureCounters {
            levels: (0..levels).map(|_| LevelCounters::default()).collect(),
            hot: (0..STRIPES * lines_per_stripe).map(|_| Line::default()).collect(),
            lines_per_stripe,
        }
    }

    #[inline]
    pub fn level(&self, level: u8) -> &LevelCounters {
        &self.levels[usize::from(level)]
    }

    #[inline]
    fn hot_add(&self, slot: usize) {
        let line = &self.hot[stripe() * self.lines_per_stripe + slot / 8];
        line.0[slot % 8].fetch_add(1, Relaxed);
    }

    fn hot_sum(&self, slot: usize) -> u64 {
        (0..STRIPES).map(|s| self.hot[s * self.lines_per_stripe + slot / 8].0[slot % 8].load(Relaxed)).sum()
    }

    /// Counts one filtered lookup.
    #[inline]
    pub fn count_lookup(&self) {
        self.hot_add(0);
    }

    /// Counts one tile request at `level`.
    #[inline]
    pub fn count_request(&self, level: u8) {
        self.hot_add(1 + usize::from(level));
    }

    /// Adds counts kept elsewhere (a [`crate::Reader`]'s): `n` of hit-path slot `slot` (0:
    /// lookups, `1 + ℓ`: requests at level ℓ).
    pub fn add_counted(&self, slot: usize, n: u64) {
        if n > 0 {
            let line = &self.hot[stripe() * self.lines_per_stripe + slot / 8];
            line.0[slot % 8].fetch_add(n, Relaxed);
        }
    }

    pub fn snapshot(&self, id: TextureId, tile_bytes: usize) -> TextureStats {
        let levels = self
            .levels
            .iter()
            .enumerate()
            .map(|(l, c)| {
                let requests = self.hot_sum(1 + l);
                let (fills, waits, direct) = (c.fills.load(Relaxed), c.waits.load(Relaxed), c.direct.load(Relaxed));
                let prefills = c.prefills.load(Relaxed);
                let misses = fills.saturating_sub(prefills) + waits + direct;
                LevelStats {
                    requests,
                    hits: requests.saturating_sub(misses),
                    misses,
                    fills,
                    prefills,
                    waits,
                    direct,
                    texels_filled: c.texels_filled.load(Relaxed),
                    texels_direct: 4 * direct,
                    texels_saturated: c.texels_saturated.load(Relaxed),
                    evictions: c.evictions.load(Relaxed),
                    refills: c.refills.load(Relaxed),
                    resident_bytes: c.resident.load(Relaxed),
                    peak_bytes: c.peak.load(Relaxed),
                }
            })
            .collect();
        TextureStats { id, lookups: self.hot_sum(0), tile_bytes: tile_bytes as u64, levels }
    }
}
