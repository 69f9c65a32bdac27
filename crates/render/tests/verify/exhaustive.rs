//! The exhaustive backend (every primitive tested) against the built-in BVH, whose triangle test
//! it shares, and against enumeration in double precision: the same closest hits, occlusion
//! answers and single-shape queries on every reference scene and on random soups; its AVX2 and
//! portable code paths bit for bit; and rays it cannot take hit nothing.

use super::embree::{disagreements, enumeration_mismatches, rays, rays_it_cannot_take_hit_nothing, soup_shapes};
use glam::Vec3;
use render::exhaustive::ExhaustiveAccel;
use render::geometry::{Accel, Intersector};
use render::sampling::Rng;
use std::path::PathBuf;

#[test]
fn exhaustive_agrees_with_the_built_in_bvh_on_every_reference_scene() {
    let refs = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/refs/scenes");
    for name in ["cbox", "dielectrics", "roughconductors", "textured_mesh"] {
        let scene = render::loader::load_file(&refs.join(format!("{name}.xml")), &[]).expect("scene loads");
        let bvh = Accel::build(&scene.shapes).unwrap();
        let all_of = ExhaustiveAccel::build(&scene.shapes);
        let mut all = rays(bvh.bounds_min, bvh.bounds_max, 6000, 17);
        let (w, h) = (scene.camera.width, scene.camera.height);
        all.extend(
            (0..h)
                .step_by(8)
                .flat_map(|y| (0..w).step_by(8).map(move |x| (x, y)))
                .map(|(x, y)| scene.camera.generate_ray(glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5)).ray),
        );
        let (hits, occl, hit_count) = disagreements(&scene.shapes, &bvh, &all_of, &all);
        eprintln!(
            "{name}: {hit_count} of {} rays hit; {hits} closest-hit and {occl} occlusion disagreements",
            all.len()
        );
        assert!(hit_count > all.len() / 10, "{name}: too few rays hit anything to compare");
        // The same triangle test: only ties between primitives may resolve differently, and
        // those agree in distance, which is all `disagreements` compares.
        assert_eq!((hits, occl), (0, 0), "{name}");
        // Bit for bit on the same primitive: the same distance and barycentrics. The exhaustive
        // test computes every primitive's distance as the BVH does and keeps the least, so where
        // they differ it is never the farther (the BVH's boxes, rounded, can pass over a hit
        // within an ulp of another: seen where a box stands on the floor).
        for r in &all {
            if let (Some(x), Some(y)) = (bvh.intersect(&scene.shapes, r), all_of.intersect(&scene.shapes, r)) {
                if (x.shape, x.index) == (y.shape, y.index) {
                    assert_eq!((x.t.to_bits(), x.bary), (y.t.to_bits(), y.bary), "{name}: {r:?}");
                } else {
                    assert!(y.t <= x.t, "{name}: {r:?}: {x:?} vs {y:?}");
                }
            }
        }
        for (k, r) in all.iter().enumerate().step_by(5) {
            let s = (k % scene.shapes.len()) as u32;
            let (x, y) = (bvh.intersect_shape(&scene.shapes, r, s), all_of.intersect_shape(&scene.shapes, r, s));
            assert_eq!(x.is_some(), y.is_some(), "{name}: shape {s} ray {k}: {x:?} vs {y:?}");
            if let (Some(x), Some(y)) = (x, y) {
                assert_eq!((x.shape, y.shape), (s, s));
                assert_eq!(x.t, y.t, "{name}: shape {s} ray {k}");
            }
        }
    }
}

#[test]
fn exhaustive_finds_the_enumerated_nearest_triangle_in_random_soups() {
    let mut rng = Rng::new(23, 5);
    for soup in 0..6 {
        // Soups of 10 to 70 triangles per mesh: the sizes the backend is chosen for, and beyond.
        let shapes = soup_shapes(&mut rng, soup, 10, 60);
        let all_of = ExhaustiveAccel::build(&shapes);
        let bvh = Accel::build(&shapes).unwrap();
        let all = rays(Vec3::splat(-2.0), Vec3::splat(2.0), 6000, 200 + soup);
        let (hits, occl, hit_count) = disagreements(&shapes, &bvh, &all_of, &all);
        // Enough hits to compare (the sparser soups are missed by most rays).
        assert!(hit_count > 250, "soup {soup}: only {hit_count} hits");
        assert_eq!((hits, occl), (0, 0), "soup {soup}");
        // Triangle hits against enumeration in double precision, the spheres and disks left out.
        let meshes = &shapes[..2];
        let wrong = enumeration_mismatches(&ExhaustiveAccel::build(meshes), meshes, &all);
        assert!(wrong * 1000 <= all.len(), "soup {soup}: {wrong} of {} rays differ from enumeration", all.len());
    }
}

/// The AVX2 path and the portable one give the same hits, bit for bit (the same operations in
/// the same order, only wider): images do not depend on the processor. Where the processor has
/// no AVX2 both are the portable path and the test says so.
#[test]
fn avx2_and_portable_paths_agree_bit_for_bit() {
    let mut rng = Rng::new(31, 1);
    let shapes = soup_shapes(&mut rng, 3, 20, 20);
    let fast = ExhaustiveAccel::build(&shapes);
    if !fast.uses_avx2() {
        eprintln!("avx2_and_portable_paths_agree_bit_for_bit: no AVX2 here; only the portable path ran");
    }
    let portable = ExhaustiveAccel::build(&shapes).portable();
    for r in rays(Vec3::splat(-2.0), Vec3::splat(2.0), 3000, 5) {
        let (a, b) = (fast.intersect(&shapes, &r), portable.intersect(&shapes, &r));
        assert_eq!(
            a.map(|h| (h.t.to_bits(), h.shape, h.index, h.bary.x.to_bits(), h.bary.y.to_bits())),
            b.map(|h| (h.t.to_bits(), h.shape, h.index, h.bary.x.to_bits(), h.bary.y.to_bits())),
            "{r:?}"
        );
        assert_eq!(fast.occluded(&shapes, &r), portable.occluded(&shapes, &r), "{r:?}");
    }
}

#[test]
fn rays_the_exhaustive_backend_cannot_take_hit_nothing() {
    rays_it_cannot_take_hit_nothing(&|shapes| Box::new(ExhaustiveAccel::build(shapes)));
}
