//! Concurrency: the budget under contention, torn tiles, determinism against a single-threaded
//! run, single-flight fills, and a fill that panics.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering::Relaxed};
use std::sync::Barrier;
use std::time::Duration;

use cache::{CacheConfig, Eviction, Filter, InFlight, TexelFormat, TexelRequest, TextureDesc, TextureId, TileCache};
use glam::{Mat2, Vec2};

/// xorshift64*: a small deterministic generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn f32(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn mix(mut h: u64) -> u64 {
    h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^ (h >> 31)
}

/// Signatures (integers 1..=1000, exact in f16): channel 0 identifies the texel's tile, channel 1
/// the texel, channel 2 the level. A texel read before its tile was filled reads 0.
fn signature(r: &TexelRequest, tile_size: i64) -> [f32; 3] {
    let (i, j) = (r.texel[0], r.texel[1]);
    let key =
        |a: i64, b: i64| mix(u64::from(r.texture.0) << 56 ^ u64::from(r.level) << 48 ^ (a as u64) << 24 ^ b as u64);
    let tile = key(i.div_euclid(tile_size), j.div_euclid(tile_size)) % 1000 + 1;
    let texel = mix(key(i, j)) % 1000 + 1;
    [tile as f32, texel as f32, f32::from(r.level) + 1.0]
}

const T: u32 = 8;

fn textures() -> [TextureDesc; 2] {
    [
        TextureDesc { channels: 3, format: TexelFormat::F32, texels_per_uv: 16.0, max_level: 6 },
        TextureDesc { channels: 2, format: TexelFormat::F16, texels_per_uv: 32.0, max_level: 7 },
    ]
}

fn make(config: CacheConfig) -> (TileCache, [TextureId; 2]) {
    let mut c = TileCache::new(config).unwrap();
    let [a, b] = textures();
    let ids = [c.add_texture(a).unwrap(), c.add_texture(b).unwrap()];
    (c, ids)
}

#[derive(Clone, Copy, Debug)]
enum Query {
    /// Read texel `ij` of `level` at its centre; must equal its signature exactly.
    Texel { tex: usize, level: u8, ij: [i64; 2] },
    /// A filtered lookup; must equal the single-threaded result bit for bit.
    Filtered { tex: usize, uv: Vec2, cov: Mat2, filter: Filter },
}

fn queries(seed: u64, n: usize) -> Vec<Query> {
    let mut rng = Rng(seed | 1);
    let descs = textures();
    (0..n)
        .map(|_| {
            let tex = rng.below(2) as usize;
            let d = descs[tex];
            if rng.below(5) < 2 {
                let level = rng.below(u64::from(d.max_level) + 1) as u8;
                let half = (64.0 * (-f32::from(level)).exp2()).max(4.0) as i64;
                let ij = [rng.below(2 * half as u64) as i64 - half, rng.below(2 * half as u64) as i64 - half];
                Query::Texel { tex, level, ij }
            } else {
                let uv = Vec2::new(rng.f32() * 8.0 - 4.0, rng.f32() * 8.0 - 4.0);
                // Major σ from ¼ texel to 64 texels of level 0, anisotropy up to 16, any angle.
                let s1 = (rng.f32() * 8.0 - 2.0).exp2() / d.texels_per_uv;
                let s2 = s1 / (1.0 + 15.0 * rng.f32());
                let r = Mat2::from_angle(rng.f32() * 6.3);
                let cov = r * Mat2::from_diagonal(Vec2::new(s1 * s1, s2 * s2)) * r.transpose();
                let filter = match rng.below(4) {
                    0 => Filter::TRILINEAR,
                    1 => Filter::TRILINEAR.levels(1, 4),
                    2 => Filter::anisotropic(8.0),
                    _ => Filter::anisotropic(16.0).levels(0, 3),
                };
                Query::Filtered { tex, uv, cov, filter }
            }
        })
        .collect()
}

fn run(c: &TileCache, ids: [TextureId; 2], q: &Query) -> [f32; 3] {
    let fill = |r: TexelRequest| signature(&r, i64::from(T));
    match *q {
        Query::Texel { tex, level, ij } => {
            let d = f64::from(textures()[tex].texels_per_uv) * (-f64::from(level)).exp2();
            let uv = Vec2::new(((ij[0] as f64 + 0.5) / d) as f32, ((ij[1] as f64 + 0.5) / d) as f32);
            let v = c.lookup(ids[tex], uv, Mat2::ZERO, Filter::TRILINEAR.levels(level, level), &fill);
            let mut want = signature(
                &TexelRequest { texture: ids[tex], level, texel: ij, uv, texel_size: 0.0, place: None },
                i64::from(T),
            );
            if tex == 1 {
                want[2] = 0.0; // two channels
            }
            assert_eq!(v, want, "torn or wrong texel {ij:?} of level {level}, texture {tex}");
            v
        }
        Query::Filtered { tex, uv, cov, filter } => c.lookup(ids[tex], uv, cov, filter, &fill),
    }
}

/// Sets the flag when dropped, also while unwinding.
struct StopOnDrop<'a>(&'a AtomicBool);

impl Drop for StopOnDrop<'_> {
    fn drop(&mut self) {
        self.0.store(true, Relaxed);
    }
}

/// Eight threads on a budget of six tiles, random lookups over all levels: the budget holds at
/// every allocation and whenever a watcher looks, no texel is read unfilled, and every result
/// equals the single-threaded, never-evicting run bit for bit — under every policy setting.
#[test]
fn stress_tiny_budget_many_threads() {
    const THREADS: usize = 8;
    const PER_THREAD: usize = 1200;
    let lists: Vec<Vec<Query>> = (0..THREADS).map(|t| queries(0x9E37 + t as u64 * 7919, PER_THREAD)).collect();

    let (reference, ids) = make(CacheConfig { tile_size: T, budget_bytes: 1 << 30, ..CacheConfig::default() });
    let want: Vec<Vec<[u32; 3]>> =
        lists.iter().map(|l| l.iter().map(|q| run(&reference, ids, q).map(f32::to_bits)).collect()).collect();
    assert_eq!(reference.stats().total().evictions, 0);

    let settings = [
        (InFlight::Wait, 4, Eviction::Clock),
        (InFlight::Evaluate, 0, Eviction::Clock),
        (InFlight::Wait, 0, Eviction::Fifo),
        (InFlight::Evaluate, 2, Eviction::Fifo),
    ];
    for (in_flight, micro_cache, eviction) in settings {
        let budget = 6 * reference.tile_bytes(ids[0]);
        let config =
            CacheConfig { tile_size: T, budget_bytes: budget, in_flight, eviction, micro_cache, count_requests: true };
        let (c, ids) = make(config);
        let done = AtomicBool::new(false);
        let watched = AtomicUsize::new(0);
        std::thread::scope(|s| {
            let _stop = StopOnDrop(&done); // a failing worker must stop the watcher too
            s.spawn(|| {
                while !done.load(Relaxed) {
                    assert!(c.resident_bytes() <= budget, "budget exceeded: {} > {budget}", c.resident_bytes());
                    watched.fetch_add(1, Relaxed);
                    std::thread::yield_now();
                }
            });
            let workers: Vec<_> = lists
                .iter()
                .zip(&want)
                .map(|(list, want)| {
                    let c = &c;
                    s.spawn(move || {
                        for (k, (q, w)) in list.iter().zip(want).enumerate() {
                            let got = run(c, ids, q).map(f32::to_bits);
                            assert_eq!(&got, w, "query {k} {q:?} differs from the single-threaded run");
                        }
                    })
                })
                .collect();
            for w in workers {
                w.join().unwrap();
            }
        });
        let s = c.stats();
        let t = s.total();
        let label = format!("{in_flight:?} micro {micro_cache} {eviction:?}: {t:?}");
        assert_eq!(s.over_budget, 0, "{label}");
        assert!(s.peak_bytes <= budget as u64, "{label}");
        assert_eq!(s.budget_checks, t.fills, "every allocation is checked: {label}");
        assert!(t.evictions > 100 && t.fills > 100 && t.refills > 0, "the budget must bite: {label}");
        assert!(t.hits > 0 && t.misses == t.fills + t.waits + t.direct, "{label}");
        assert!(watched.load(Relaxed) > 0);
        eprintln!("{label}; watcher looked {} times", watched.load(Relaxed));
    }
}

/// Concurrent misses on one tile fill each texel once ([`InFlight::Wait`]); with
/// [`InFlight::Evaluate`] the others evaluate their four texels each instead of waiting.
#[test]
fn single_flight_fills_each_texel_once() {
    const THREADS: usize = 8;
    for in_flight in [InFlight::Wait, InFlight::Evaluate] {
        let config = CacheConfig { tile_size: 16, in_flight, ..CacheConfig::default() };
        let mut c = TileCache::new(config).unwrap();
        let id = c.add_texture(textures()[0]).unwrap();
        for (round, level) in [0u8, 2, 5].into_iter().enumerate() {
            let calls = AtomicUsize::new(0);
            let fill = |r: TexelRequest| {
                if calls.fetch_add(1, Relaxed) == 0 {
                    std::thread::sleep(Duration::from_millis(40)); // let the others arrive mid-fill
                }
                signature(&r, 16)
            };
            let barrier = Barrier::new(THREADS);
            let before = c.stats().textures[0].levels[usize::from(level)];
            std::thread::scope(|s| {
                for t in 0..THREADS {
                    let (c, fill, barrier) = (&c, &fill, &barrier);
                    s.spawn(move || {
                        // Different points of the same tile (texels 0..15 of tile (round, -1)).
                        let d = 16.0 * (-f32::from(level)).exp2();
                        let ij = Vec2::new((16 * round + 2 * t) as f32, -16.0 + t as f32);
                        barrier.wait();
                        c.lookup(id, (ij + 0.5) / d, Mat2::ZERO, Filter::TRILINEAR.levels(level, level), fill);
                    });
                }
            });
            let l = c.stats().textures[0].levels[usize::from(level)];
            let (fills, waits, direct, hits) =
                (l.fills - before.fills, l.waits - before.waits, l.direct - before.direct, l.hits - before.hits);
            assert_eq!(fills, 1, "{in_flight:?} level {level}");
            assert_eq!(waits + direct + hits, THREADS as u64 - 1);
            let calls = calls.load(Relaxed) as u64;
            match in_flight {
                InFlight::Wait => {
                    assert_eq!(calls, 17 * 17, "each texel once");
                    assert_eq!(direct, 0);
                    assert!(waits >= 1);
                }
                InFlight::Evaluate => {
                    assert_eq!(calls, 17 * 17 + 4 * direct);
                    assert_eq!(waits, 0);
                    assert!(direct >= 1);
                }
            }
        }
    }
}

/// A fill that panics leaves no placeholder and no charged bytes; a thread waiting on it
/// evaluates directly and gets the right value; the tile can be filled afterwards.
#[test]
fn panicking_fill_leaves_the_cache_consistent() {
    let config = CacheConfig { tile_size: 16, in_flight: InFlight::Wait, ..CacheConfig::default() };
    let mut c = TileCache::new(config).unwrap();
    let id = c.add_texture(textures()[0]).unwrap();
    let good = |r: TexelRequest| signature(&r, 16);
    let uv = Vec2::new(0.5 / 16.0, 0.5 / 16.0);
    let point = Filter::TRILINEAR.levels(0, 0);
    let started = Barrier::new(2);
    std::thread::scope(|s| {
        let bad = s.spawn(|| {
            let bad = |r: TexelRequest| {
                if r.texel == [0, 0] {
                    started.wait();
                    std::thread::sleep(Duration::from_millis(40));
                    panic!("fill failed");
                }
                good(r)
            };
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| c.lookup(id, uv, Mat2::ZERO, point, &bad)))
        });
        started.wait();
        let v = c.lookup(id, uv, Mat2::ZERO, point, &good); // waits on the doomed fill
        assert_eq!(v, good(TexelRequest { texture: id, level: 0, texel: [0, 0], uv, texel_size: 0.0, place: None }));
        assert!(bad.join().unwrap().is_err());
    });
    let l0 = c.stats().textures[0].levels[0];
    assert_eq!((l0.fills, l0.direct, l0.waits), (0, 1, 0));
    assert_eq!(c.resident_bytes(), 0);
    let v = c.lookup(id, uv, Mat2::ZERO, point, &good);
    assert_eq!(v[2], 1.0);
    assert_eq!(c.stats().textures[0].levels[0].fills, 1);
    assert_eq!(c.resident_bytes(), c.tile_bytes(id));
}
