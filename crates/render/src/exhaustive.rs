//! Ray queries over a scene of few primitives by testing every one: triangles eight at a time in
//! structure-of-arrays blocks, then the spheres and disks one by one.
//!
//! A hierarchy pays for itself by skipping most primitives; a scene of a few dozen has little to
//! skip, and a traversal's fixed costs (Embree's call, context and ray records, its node visits)
//! then outweigh the tests it saves. `cargo bench -p render --bench bvh` measures the three
//! backends side by side; [`crate::accel::Backend::Auto`] takes this one for scenes of at most
//! [`SMALL_SCENE_TRIANGLES`] triangles and [`SMALL_SCENE`] primitives in all.
//!
//! The triangle test is the built-in BVH's (Möller–Trumbore on the same precomputed edges, the
//! same operations in the same order), so a primitive both report is hit at the same distance,
//! bit for bit. Where they report different primitives, within rounding of each other, this one
//! has the nearer (the BVH's rounded boxes can pass over a hit an ulp nearer than another), and
//! ties go to triangles before spheres and disks, and within each kind to the first in scene
//! order. Rays
//! Embree could not take (a NaN or infinite origin or direction, an interval that is empty or
//! starts below 0) hit nothing, as with Embree. Lanes are
//! written as plain loops over arrays, which the compiler turns into vector instructions; where
//! the processor has AVX2 (detected once, at build) the same loops are compiled for it as well.
//! The arithmetic is identical either way, so the images are.

use crate::geometry::{intersect_disk, intersect_sphere, Intersector, PreliminaryHit, Ray, Shape, ShapeGeometry};
use glam::Vec2;

/// Triangles per block.
const LANES: usize = 8;

/// Most triangles a scene may have for [`crate::accel::Backend::Auto`] to test them all instead
/// of building a hierarchy (six blocks), and most primitives of any kind ([`SMALL_SCENE`]).
/// Measured against Embree, the backends of one binary in round robin: the Cornell box (36
/// triangles) renders 10–12 % faster, the same box with one more small cube (48) 4 % faster,
/// with two (60) 4 % slower and with four (84) 10 % slower; the free-texture renders of
/// brick_moss (26 triangles and a sphere) 8–15 % faster, marble (6 and 4) 10–12 %, dielectrics
/// (2 and 3) 10–14 %, roughconductors (6 and 3) 9 %. A sphere or disk costs Embree a callback
/// into our own test, which here is called directly.
pub const SMALL_SCENE_TRIANGLES: usize = 48;

/// Most primitives (triangles, spheres and disks) a scene may have for
/// [`crate::accel::Backend::Auto`] to test them all ([`SMALL_SCENE_TRIANGLES`]).
pub const SMALL_SCENE: usize = 56;

/// Triangles and primitives of every kind (triangles, spheres, disks) in `shapes`, counted
/// without building anything.
pub fn counts(shapes: &[Shape]) -> (usize, usize) {
    shapes.iter().fold((0, 0), |(triangles, all), s| match &s.geometry {
        ShapeGeometry::Mesh { mesh, .. } => (triangles + mesh.indices.len(), all + mesh.indices.len()),
        _ => (triangles, all + 1),
    })
}

/// Whether `shapes` are few enough for [`crate::accel::Backend::Auto`] to test them all: at most
/// [`SMALL_SCENE_TRIANGLES`] triangles and [`SMALL_SCENE`] primitives.
pub fn small(shapes: &[Shape]) -> bool {
    let (triangles, all) = counts(shapes);
    triangles <= SMALL_SCENE_TRIANGLES && all <= SMALL_SCENE
}

/// Eight triangles: a corner and the two edges from it, one array per coordinate. Lanes past the
/// scene's last triangle have zero edges, which the test rejects (zero determinant).
#[derive(Clone, Copy, Default)]
#[repr(C, align(32))]
struct Block {
    v0: [[f32; LANES]; 3],
    e1: [[f32; LANES]; 3],
    e2: [[f32; LANES]; 3],
    /// Shape and triangle index per lane.
    shape: [u32; LANES],
    index: [u32; LANES],
}

/// Every primitive of a small scene, tested in turn ([`Intersector`]).
pub struct ExhaustiveAccel {
    blocks: Vec<Block>,
    /// The spheres' and disks' shape indices (their geometry is read from the shapes at query
    /// time).
    analytic: Vec<u32>,
    triangles: usize,
    avx2: bool,
}

impl ExhaustiveAccel {
    /// Gathers the primitives of `shapes`.
    pub fn build(shapes: &[Shape]) -> ExhaustiveAccel {
        let mut blocks: Vec<Block> = Vec::new();
        let mut analytic = Vec::new();
        let mut triangles = 0;
        for (si, shape) in shapes.iter().enumerate() {
            match &shape.geometry {
                ShapeGeometry::Mesh { mesh, .. } => {
                    for (ti, idx) in mesh.indices.iter().enumerate() {
                        let [a, b, c] = idx.map(|i| mesh.positions[i as usize]);
                        let lane = triangles % LANES;
                        if lane == 0 {
                            blocks.push(Block::default());
                        }
                        let blk = blocks.last_mut().expect("a block was just pushed");
                        let (e1, e2) = (b - a, c - a);
                        for k in 0..3 {
                            blk.v0[k][lane] = a[k];
                            blk.e1[k][lane] = e1[k];
                            blk.e2[k][lane] = e2[k];
                        }
                        blk.shape[lane] = si as u32;
                        blk.index[lane] = ti as u32;
                        triangles += 1;
                    }
                }
                ShapeGeometry::Sphere { .. } | ShapeGeometry::Disk { .. } => analytic.push(si as u32),
            }
        }
        ExhaustiveAccel { blocks, analytic, triangles, avx2: avx2() }
    }

    /// The same queries without the AVX2 code path, whatever the processor (for tests that
    /// compare the two).
    pub fn portable(mut self) -> ExhaustiveAccel {
        self.avx2 = false;
        self
    }

    /// Whether the queries run the AVX2 code path.
    pub fn uses_avx2(&self) -> bool {
        self.avx2
    }

    /// The closest hit, on shape `only` alone if given.
    #[inline]
    fn closest(&self, shapes: &[Shape], ray: &Ray, only: Option<u32>) -> Option<PreliminaryHit> {
        let mut best = self.closest_triangle(ray, only);
        let mut tmax = best.map_or(ray.tmax, |h| h.t);
        for &shape in &self.analytic {
            if only.is_some_and(|s| s != shape) {
                continue;
            }
            if let Some(t) = analytic_hit(shapes, shape, ray, tmax) {
                tmax = t;
                best = Some(PreliminaryHit { t, shape, index: 0, bary: Vec2::ZERO });
            }
        }
        best
    }

    #[inline]
    fn closest_triangle(&self, ray: &Ray, only: Option<u32>) -> Option<PreliminaryHit> {
        if self.blocks.is_empty() {
            return None;
        }
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: AVX2 was detected on this processor when the scene was built.
            return unsafe { closest_avx2(&self.blocks, ray, only) };
        }
        closest_in(&self.blocks, ray, only)
    }

    #[inline]
    fn any_triangle(&self, ray: &Ray) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: as in `closest_triangle`.
            return unsafe { any_avx2(&self.blocks, ray) };
        }
        any_in(&self.blocks, ray)
    }
}

fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// A sphere's or disk's hit distance within `(ray.tmin, tmax)`.
#[inline]
fn analytic_hit(shapes: &[Shape], shape: u32, ray: &Ray, tmax: f32) -> Option<f32> {
    match &shapes[shape as usize].geometry {
        ShapeGeometry::Sphere { center, radius, .. } => {
            intersect_sphere(*center, *radius, ray.o, ray.d, ray.tmin, tmax)
        }
        ShapeGeometry::Disk { to_object, .. } => intersect_disk(to_object, ray.o, ray.d, ray.tmin, tmax),
        ShapeGeometry::Mesh { .. } => None,
    }
}

/// One block's test against a ray: per lane the hit distance (∞ where none within `(tmin,
/// tmax)`) and the barycentrics. The built-in BVH's Möller–Trumbore, lane by lane.
#[inline(always)]
#[allow(clippy::manual_range_contains)] // `RangeInclusive::contains` is a call of its own (see below)
fn block_hits(b: &Block, o: [f32; 3], d: [f32; 3], tmin: f32, tmax: f32) -> ([f32; LANES], [f32; LANES], [f32; LANES]) {
    let (mut t, mut u, mut v) = ([f32::INFINITY; LANES], [0.0; LANES], [0.0; LANES]);
    for k in 0..LANES {
        let (e1, e2) = ([b.e1[0][k], b.e1[1][k], b.e1[2][k]], [b.e2[0][k], b.e2[1][k], b.e2[2][k]]);
        // pvec = d × e2, det = e1 · pvec.
        let p = [d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0]];
        let det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
        let inv = 1.0 / det;
        let s = [o[0] - b.v0[0][k], o[1] - b.v0[1][k], o[2] - b.v0[2][k]];
        let uu = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) * inv;
        // qvec = s × e1.
        let q = [s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0]];
        let vv = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) * inv;
        let tt = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv;
        // `&`, not `&&`: every condition is computed, so the lanes vectorise without branches.
        let hit = (det.abs() >= 1e-20)
            & (uu >= 0.0)
            & (uu <= 1.0)
            & (vv >= 0.0)
            & (uu + vv <= 1.0)
            & (tt > tmin)
            & (tt < tmax);
        t[k] = if hit { tt } else { f32::INFINITY };
        u[k] = uu;
        v[k] = vv;
    }
    (t, u, v)
}

// The loops below index instead of using iterator adapters: an adapter is a generic function
// of its own, which the compiler may leave out of line, and then it is not compiled for AVX2.

/// The smallest of a block's distances, by halving (a chain of eight `f32::min` was a quarter of
/// a query: each waits for the one before, and NaN-aware minima take a blend each). The
/// distances are never NaN ([`block_hits`] writes ∞ for every lane that does not hit).
#[inline(always)]
fn nearest_of(t: &[f32; LANES]) -> f32 {
    let mut m = *t;
    let mut half = LANES / 2;
    while half > 0 {
        for k in 0..half {
            m[k] = if m[k + half] < m[k] { m[k + half] } else { m[k] };
        }
        half /= 2;
    }
    m[0]
}

#[inline(always)]
#[allow(clippy::needless_range_loop)]
fn closest_in(blocks: &[Block], ray: &Ray, only: Option<u32>) -> Option<PreliminaryHit> {
    let (o, d) = (ray.o.to_array(), ray.d.to_array());
    let mut tmax = ray.tmax;
    // The winner so far: its block, lane and barycentrics (the hit is assembled once, at the end).
    let mut best: Option<(usize, usize, f32, f32)> = None;
    for i in 0..blocks.len() {
        let b = &blocks[i];
        let (mut t, u, v) = block_hits(b, o, d, ray.tmin, tmax);
        if let Some(s) = only {
            for k in 0..LANES {
                if b.shape[k] != s {
                    t[k] = f32::INFINITY;
                }
            }
        }
        let nearest = nearest_of(&t);
        if nearest == f32::INFINITY {
            continue;
        }
        // The first lane at the nearest distance (`block_hits` kept only lanes nearer than the
        // winner of earlier blocks: ties go to the first primitive in scene order).
        let mut k = 0;
        while k + 1 < LANES && t[k] != nearest {
            k += 1;
        }
        tmax = nearest;
        best = Some((i, k, u[k], v[k]));
    }
    best.map(|(i, k, u, v)| PreliminaryHit {
        t: tmax,
        shape: blocks[i].shape[k],
        index: blocks[i].index[k],
        bary: Vec2::new(u, v),
    })
}

#[inline(always)]
#[allow(clippy::needless_range_loop)]
fn any_in(blocks: &[Block], ray: &Ray) -> bool {
    let (o, d) = (ray.o.to_array(), ray.d.to_array());
    for i in 0..blocks.len() {
        let (t, _, _) = block_hits(&blocks[i], o, d, ray.tmin, ray.tmax);
        let mut any = 0u32;
        for k in 0..LANES {
            any |= u32::from(t[k] < f32::INFINITY);
        }
        if any != 0 {
            return true;
        }
    }
    false
}

/// [`closest_in`] compiled for AVX2.
///
/// # Safety
/// The processor has AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn closest_avx2(blocks: &[Block], ray: &Ray, only: Option<u32>) -> Option<PreliminaryHit> {
    closest_in(blocks, ray, only)
}

/// [`any_in`] compiled for AVX2.
///
/// # Safety
/// The processor has AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn any_avx2(blocks: &[Block], ray: &Ray) -> bool {
    any_in(blocks, ray)
}

impl Intersector for ExhaustiveAccel {
    #[inline]
    fn intersect(&self, shapes: &[Shape], ray: &Ray) -> Option<PreliminaryHit> {
        if !ray.queryable() {
            return None;
        }
        self.closest(shapes, ray, None)
    }

    #[inline]
    fn occluded(&self, shapes: &[Shape], ray: &Ray) -> bool {
        if !ray.queryable() {
            return false;
        }
        self.any_triangle(ray) || self.analytic.iter().any(|&a| analytic_hit(shapes, a, ray, ray.tmax).is_some())
    }

    fn intersect_shape(&self, shapes: &[Shape], ray: &Ray, shape: u32) -> Option<PreliminaryHit> {
        if !ray.queryable() {
            return None;
        }
        self.closest(shapes, ray, Some(shape))
    }

    fn describe(&self) -> String {
        format!("every primitive tested ({} triangles, {} spheres and disks)", self.triangles, self.analytic.len())
    }
}
