//! Embree against the built-in BVH and against brute force: the same closest hits, occlusion
//! answers and single-shape queries on every reference scene and on random triangle soups with
//! spheres and disks among them. Without the library (`scripts/install-embree.sh`) each test
//! says it was skipped; `.ci/run` installs it. The helpers serve the other backends' tests too
//! (`exhaustive.rs`).

use glam::{Affine3A, Mat3, Quat, Vec3};
use render::embree::{available, EmbreeAccel};
use render::geometry::{Accel, Intersector, PreliminaryHit, Ray, Shape, ShapeGeometry};
use render::mesh::TriangleMesh;
use render::sampling::Rng;
use std::path::PathBuf;

fn embree_or_skip(test: &str) -> bool {
    match available() {
        Ok(_) => true,
        Err(e) => {
            eprintln!("{test}: skipped: {e}");
            false
        }
    }
}

pub(crate) fn unit(rng: &mut Rng) -> Vec3 {
    loop {
        let v = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
        let l = v.length_squared();
        if l > 1e-4 && l <= 1.0 {
            return v / l.sqrt();
        }
    }
}

/// Random rays through the scene's bounds (origins in a box 1.5× as large), some with a finite
/// far end.
pub(crate) fn rays(min: Vec3, max: Vec3, n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed, 0);
    let (c, h) = ((min + max) * 0.5, (max - min) * 0.75 + 1e-3);
    (0..n)
        .map(|k| {
            let o = c + h * (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0);
            let mut r = Ray::new(o, unit(&mut rng));
            if k % 3 == 0 {
                r.tmax = rng.next_f32() * 2.0 * h.length();
            }
            r
        })
        .collect()
}

/// Counts the rays on which two backends disagree beyond rounding: one hits and the other not,
/// or their nearest distances differ by more than 1e-4 relative. Neither test is watertight: a
/// ray exactly through a shared edge (a pixel-centre ray on a square's diagonal in a symmetric
/// view, say) can slip between the two triangles in either, so a few in a thousand are allowed;
/// a wrong convention (barycentrics, ids, the interval) disagrees on many.
pub(crate) fn disagreements(
    shapes: &[Shape],
    a: &dyn Intersector,
    b: &dyn Intersector,
    rays: &[Ray],
) -> (usize, usize, usize) {
    let close = |x: &PreliminaryHit, y: &PreliminaryHit| (x.t - y.t).abs() <= 1e-4 * (1.0 + x.t.abs());
    let (mut hits, mut occl, mut hit_count) = (0, 0, 0);
    for r in rays {
        let (x, y) = (a.intersect(shapes, r), b.intersect(shapes, r));
        match (&x, &y) {
            (Some(x), Some(y)) => {
                hit_count += 1;
                // At a seam two shapes may be hit at the same distance: either is right.
                if !close(x, y) {
                    hits += 1;
                }
            }
            (None, None) => {}
            _ => hits += 1,
        }
        if a.occluded(shapes, r) != b.occluded(shapes, r) {
            occl += 1;
        }
    }
    (hits, occl, hit_count)
}

#[test]
fn embree_agrees_with_the_built_in_bvh_on_every_reference_scene() {
    if !embree_or_skip("embree_agrees_with_the_built_in_bvh_on_every_reference_scene") {
        return;
    }
    let refs = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/refs/scenes");
    for name in ["cbox", "dielectrics", "roughconductors", "textured_mesh"] {
        let scene = render::loader::load_file(&refs.join(format!("{name}.xml")), &[]).expect("scene loads");
        let bvh = Accel::build(&scene.shapes).unwrap();
        let embree = EmbreeAccel::build(&scene.shapes).unwrap();
        let mut all = rays(bvh.bounds_min, bvh.bounds_max, 20_000, 7);
        let (w, h) = (scene.camera.width, scene.camera.height);
        all.extend(
            (0..h)
                .step_by(4)
                .flat_map(|y| (0..w).step_by(4).map(move |x| (x, y)))
                .map(|(x, y)| scene.camera.generate_ray(glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5)).ray),
        );
        let (hits, occl, hit_count) = disagreements(&scene.shapes, &bvh, &embree, &all);
        eprintln!(
            "{name}: {hit_count} of {} rays hit; {hits} closest-hit and {occl} occlusion disagreements",
            all.len()
        );
        assert!(hit_count > all.len() / 10, "{name}: too few rays hit anything to compare");
        assert!(hits * 1000 <= all.len(), "{name}: {hits} closest hits differ");
        assert!(occl * 1000 <= all.len(), "{name}: {occl} occlusion answers differ");
        // The pixel-centre query: the closest hit on one shape, whatever is in front.
        for (k, r) in all.iter().enumerate().step_by(7) {
            let s = (k % scene.shapes.len()) as u32;
            let (x, y) = (bvh.intersect_shape(&scene.shapes, r, s), embree.intersect_shape(&scene.shapes, r, s));
            assert_eq!(x.is_some(), y.is_some(), "{name}: shape {s} ray {k}: {x:?} vs {y:?}");
            if let (Some(x), Some(y)) = (x, y) {
                assert_eq!(x.shape, s);
                assert_eq!(y.shape, s);
                assert!((x.t - y.t).abs() <= 1e-4 * (1.0 + x.t), "{name}: shape {s} ray {k}: {x:?} vs {y:?}");
            }
        }
    }
}

pub(crate) fn mesh_shape(mesh: TriangleMesh) -> Shape {
    let area = render::geometry::mesh_area_distribution(&mesh).unwrap();
    Shape {
        geometry: ShapeGeometry::mesh(mesh, area),
        material: 0,
        emitter: None,
        flip_normals: false,
        face_normals: false,
        name: "soup".into(),
    }
}

/// The nearest triangle hit by plain enumeration, in double precision (independent of both
/// backends' tests): (t, shape, triangle, barycentrics).
pub(crate) fn brute_force(shapes: &[Shape], r: &Ray) -> Option<(f64, u32, u32, f64, f64)> {
    let (o, d) = (r.o.as_dvec3(), r.d.as_dvec3());
    let mut best: Option<(f64, u32, u32, f64, f64)> = None;
    for (si, s) in shapes.iter().enumerate() {
        let ShapeGeometry::Mesh { mesh, .. } = &s.geometry else { continue };
        for (ti, idx) in mesh.indices.iter().enumerate() {
            let [a, b, c] = idx.map(|i| mesh.positions[i as usize].as_dvec3());
            // Solve o + t d = a + u (b − a) + v (c − a) by Cramer's rule.
            let (e1, e2) = (b - a, c - a);
            let det = -d.dot(e1.cross(e2));
            if det.abs() < 1e-300 {
                continue;
            }
            let q = o - a;
            let t = q.dot(e1.cross(e2)) / det;
            let u = -d.dot(q.cross(e2)) / det;
            let v = -d.dot(e1.cross(q)) / det;
            if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > r.tmin as f64 && t < r.tmax as f64 {
                if best.is_none_or(|b| t < b.0) {
                    best = Some((t, si as u32, ti as u32, u, v));
                }
            }
        }
    }
    best
}

/// The rays on which `accel` does not find the triangle [`brute_force`] enumerates, at the same
/// point: the soups' triangles share no edges, so a right backend misses none but rays within
/// rounding of an edge.
pub(crate) fn enumeration_mismatches(accel: &dyn Intersector, meshes: &[Shape], rays: &[Ray]) -> usize {
    let mut wrong = 0;
    for r in rays {
        match (accel.intersect(meshes, r), brute_force(meshes, r)) {
            (Some(e), Some(b)) => {
                let ok = (e.t as f64 - b.0).abs() <= 1e-4 * (1.0 + b.0)
                    && (e.shape, e.index) == (b.1, b.2)
                    && (e.bary.x as f64 - b.3).abs() < 1e-3
                    && (e.bary.y as f64 - b.4).abs() < 1e-3;
                wrong += usize::from(!ok);
            }
            (None, None) => {}
            _ => wrong += 1,
        }
    }
    wrong
}

/// Rays a backend cannot take (a NaN or infinite origin or direction, an empty or NaN interval,
/// one that starts below 0) hit nothing and are not occluded; a good one hits the unit square; an empty scene hits nothing.
pub(crate) fn rays_it_cannot_take_hit_nothing(build: &dyn Fn(&[Shape]) -> Box<dyn Intersector>) {
    let shapes = vec![mesh_shape(render::mesh::rectangle_mesh())];
    let accel = build(&shapes);
    let good = Ray::new(Vec3::new(0.2, 0.1, 3.0), -Vec3::Z);
    assert!(accel.intersect(&shapes, &good).is_some() && accel.occluded(&shapes, &good));
    for bad in [
        Ray { o: Vec3::new(f32::NAN, 0.0, 3.0), ..good },
        Ray { d: Vec3::new(0.0, f32::INFINITY, -1.0), ..good },
        Ray { tmin: 2.0, tmax: 1.0, ..good },
        Ray { tmin: f32::NAN, ..good },
        // Would hit at t = 3, but an interval from below 0 is not taken.
        Ray { tmin: -1.0, ..good },
    ] {
        assert!(accel.intersect(&shapes, &bad).is_none(), "{bad:?}");
        assert!(!accel.occluded(&shapes, &bad), "{bad:?}");
    }
    let empty = build(&[]);
    assert!(empty.intersect(&[], &good).is_none() && !empty.occluded(&[], &good));
}

/// Soup number `soup`: two meshes of `lo..lo + spread` random triangles of mixed sizes in
/// [−2, 2]³, and a sphere and a disk among them.
pub(crate) fn soup_shapes(rng: &mut Rng, soup: u64, lo: usize, spread: usize) -> Vec<Shape> {
    let mut shapes = Vec::new();
    for _ in 0..2 {
        let n = lo + (rng.next_f32() * spread as f32) as usize;
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        for k in 0..n {
            let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
            let size = 0.05 + rng.next_f32().powi(2);
            for _ in 0..3 {
                positions.push(c + unit(rng) * size);
            }
            let b = 3 * k as u32;
            indices.push([b, b + 1, b + 2]);
        }
        shapes.push(mesh_shape(TriangleMesh { positions, normals: None, uvs: None, indices }));
    }
    shapes.push(Shape {
        geometry: ShapeGeometry::Sphere { center: Vec3::new(0.3, -0.2, 0.1), radius: 0.7, rotation: Mat3::IDENTITY },
        ..mesh_shape(render::mesh::rectangle_mesh())
    });
    let to_world = Affine3A::from_scale_rotation_translation(
        Vec3::splat(0.8),
        Quat::from_rotation_x(0.7 * soup as f32),
        Vec3::new(-0.5, 0.4, 0.2),
    );
    shapes.push(Shape {
        geometry: ShapeGeometry::Disk {
            to_world,
            to_object: to_world.inverse(),
            normal: to_world.transform_vector3(Vec3::Z).normalize(),
            area: 0.64 * std::f32::consts::PI,
        },
        ..mesh_shape(render::mesh::rectangle_mesh())
    });
    shapes
}

#[test]
fn embree_finds_the_brute_force_nearest_triangle_in_random_soups() {
    if !embree_or_skip("embree_finds_the_brute_force_nearest_triangle_in_random_soups") {
        return;
    }
    let mut rng = Rng::new(11, 3);
    for soup in 0..6 {
        let shapes = soup_shapes(&mut rng, soup, 50, 300);
        let bvh = Accel::build(&shapes).unwrap();
        let embree = EmbreeAccel::build(&shapes).unwrap();
        let all = rays(Vec3::splat(-2.0), Vec3::splat(2.0), 4000, 100 + soup);
        let (hits, occl, hit_count) = disagreements(&shapes, &bvh, &embree, &all);
        assert!(hit_count > 400, "soup {soup}: only {hit_count} hits");
        assert!(
            hits * 1000 <= all.len() && occl * 1000 <= all.len(),
            "soup {soup}: {hits} hits, {occl} occlusions differ"
        );
        // Triangle hits against enumeration, with the spheres and disks left out.
        let meshes = &shapes[..2];
        let embree_meshes = EmbreeAccel::build(meshes).unwrap();
        let wrong = enumeration_mismatches(&embree_meshes, meshes, &all);
        assert!(wrong * 1000 <= all.len(), "soup {soup}: {wrong} of {} rays differ from enumeration", all.len());
    }
}

#[test]
fn rays_embree_cannot_take_hit_nothing() {
    if !embree_or_skip("rays_embree_cannot_take_hit_nothing") {
        return;
    }
    rays_it_cannot_take_hit_nothing(&|shapes| Box::new(EmbreeAccel::build(shapes).unwrap()));
}
