//! A hit allocates nothing: a counting global allocator watches lookups on resident tiles, the
//! cache's own and a reader's.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use cache::{CacheConfig, Filter, TexelFormat, TexelRequest, TextureDesc, TileCache};
use glam::{Mat2, Vec2};

struct Counting;

thread_local! {
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCS.try_with(|a| a.set(a.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCS.try_with(|a| a.set(a.get() + 1));
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocs() -> u64 {
    ALLOCS.with(Cell::get)
}

#[test]
fn hits_allocate_nothing() {
    for micro_cache in [0, 4] {
        for format in [TexelFormat::F32, TexelFormat::F16] {
            let config = CacheConfig { micro_cache, ..CacheConfig::default() };
            let mut c = TileCache::new(config).unwrap();
            let id = c.add_texture(TextureDesc { channels: 3, format, texels_per_uv: 64.0, max_level: 8 }).unwrap();
            let fill = |r: TexelRequest| [r.uv.x, r.uv.y, 1.0];
            let points: Vec<(Vec2, Mat2)> = (0..64)
                .map(|k| {
                    let uv = Vec2::new(0.3 + 0.01 * k as f32, 0.7 - 0.005 * k as f32);
                    let cov = Mat2::from_diagonal(Vec2::new(1e-4 * (1 + k % 5) as f32, 2e-5));
                    (uv, cov)
                })
                .collect();
            let filters = [Filter::TRILINEAR, Filter::anisotropic(8.0), Filter::TRILINEAR.levels(2, 3)];
            let reader = c.reader();
            let run = || {
                let mut acc = 0.0;
                for &(uv, cov) in &points {
                    for f in filters {
                        acc += c.lookup(id, uv, cov, f, &fill)[0];
                        acc += reader.lookup(id, uv, cov, f, &fill)[1];
                    }
                }
                acc
            };
            let cold = allocs();
            let warm = run(); // fills: allocates tiles (and shows the counter works)
            assert!(allocs() > cold);
            let fills = c.stats().total().fills;
            let before = allocs();
            let again = run();
            let after = allocs();
            assert_eq!(c.stats().total().fills, fills, "the second pass must be all hits");
            assert_eq!(warm, again);
            assert_eq!(after - before, 0, "micro {micro_cache} {format:?}: hits allocated");
        }
    }
}
