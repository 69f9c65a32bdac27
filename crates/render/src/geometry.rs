//! Shapes, the acceleration structure and surface interactions.
//!
//! Every shape is reduced to primitives (triangles, spheres, disks) in world space. A wide BVH
//! from the `obvhs` crate indexes them; [`Accel`] hides that crate behind the [`Intersector`]
//! queries (closest hit, any hit, closest hit on one shape), behind which Embree
//! ([`crate::embree`]) is the other backend.

use crate::math::Frame;
use crate::mesh::TriangleMesh;
use glam::{Affine3A, Mat3, Vec2, Vec3, Vec3A};
use obvhs::aabb::Aabb;
use std::f32::consts::PI;

/// A ray with its valid parameter interval.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub o: Vec3,
    /// Unit direction.
    pub d: Vec3,
    /// Smallest accepted distance.
    pub tmin: f32,
    /// Largest accepted distance.
    pub tmax: f32,
}

impl Ray {
    /// A ray over (0, ∞).
    pub fn new(o: Vec3, d: Vec3) -> Self {
        Ray { o, d, tmin: 0.0, tmax: f32::INFINITY }
    }

    /// The point at distance `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + self.d * t
    }

    /// Whether a backend may be given this ray: a finite origin and direction and a non-empty
    /// interval starting at or after 0. Embree's queries are undefined otherwise; Embree and the
    /// exhaustive backend both answer such a ray with no hit.
    #[inline]
    pub fn queryable(&self) -> bool {
        self.o.is_finite() && self.d.is_finite() && self.tmin >= 0.0 && self.tmin < self.tmax
    }
}

/// The geometric kinds of shape.
#[derive(Clone, Debug)]
pub enum ShapeGeometry {
    /// A triangle mesh in world space.
    Mesh {
        /// Vertices, normals, uvs and triangles, already transformed to world space.
        mesh: TriangleMesh,
        /// Cumulative triangle areas for sampling, and the total area.
        area: crate::sampling::Distribution1D,
        /// Per triangle, what every hit on it shares ([`ShapeGeometry::mesh`] computes them).
        frames: Vec<TriangleFrame>,
        /// Where the mesh is one flat parallelogram of two triangles (Mitsuba's `rectangle`, the
        /// usual area light): a corner and the two edges from it, along which
        /// [`Shape::sample_area`] maps the unit square directly.
        parallelogram: Option<[Vec3; 3]>,
    },
    /// A sphere; `rotation` maps object axes to world axes (for uv).
    Sphere {
        /// Centre in world space.
        center: Vec3,
        /// Radius in world units.
        radius: f32,
        /// Object-to-world rotation (orthonormal).
        rotation: Mat3,
    },
    /// Mitsuba's unit disk in the xy plane, placed by an affine transform.
    Disk {
        /// Object to world.
        to_world: Affine3A,
        /// World to object.
        to_object: Affine3A,
        /// World-space normal of the disk (before `flip_normals`).
        normal: Vec3,
        /// World-space area.
        area: f32,
    },
}

/// What every hit on one triangle shares, computed once per triangle when the shape is made
/// (a division, two square roots and a handful of cross products fewer per hit and per light
/// sample): ∂p/∂u and ∂p/∂v, and the frame of the face normal, whose tangent follows ∂p/∂u.
#[derive(Clone, Copy, Debug)]
pub struct TriangleFrame {
    /// ∂p/∂u (the first edge where the uvs are degenerate).
    pub dpdu: Vec3,
    /// ∂p/∂v (the second edge where the uvs are degenerate).
    pub dpdv: Vec3,
    /// `n` is the unit geometric normal (zero for a degenerate triangle); `s` follows `dpdu`.
    pub face: Frame,
}

impl ShapeGeometry {
    /// A mesh shape's geometry: the mesh, its area distribution and its triangles' frames.
    pub fn mesh(mesh: TriangleMesh, area: crate::sampling::Distribution1D) -> ShapeGeometry {
        let frames = mesh
            .indices
            .iter()
            .map(|idx| {
                let [p0, p1, p2] = idx.map(|i| mesh.positions[i as usize]);
                let ng = (p1 - p0).cross(p2 - p0).normalize_or_zero();
                let (uv0, uv1, uv2) = match &mesh.uvs {
                    Some(uv) => (uv[idx[0] as usize], uv[idx[1] as usize], uv[idx[2] as usize]),
                    None => (Vec2::ZERO, Vec2::X, Vec2::Y),
                };
                let (dpdu, dpdv) =
                    uv_derivatives(uv1 - uv0, uv2 - uv0, p1 - p0, p2 - p0).unwrap_or_else(|| (p1 - p0, p2 - p0));
                TriangleFrame { dpdu, dpdv, face: Frame::from_normal_tangent(ng, dpdu) }
            })
            .collect();
        let parallelogram = parallelogram_of(&mesh);
        ShapeGeometry::Mesh { mesh, area, frames, parallelogram }
    }
}

/// The corner `p₀` and edges `p₁ − p₀`, `p₃ − p₀` of a mesh of two triangles `[a, b, c]`,
/// `[a, c, d]` whose four corners form a parallelogram (`a + c = b + d` to within 1e-5 of the
/// edges' lengths) and that has no vertex normals to interpolate: uniform points on it are then
/// `p₀ + u (p₁ − p₀) + v (p₃ − p₀)` for uniform `(u, v)`, with no triangle to choose and no
/// square root. `None` for any other mesh.
fn parallelogram_of(mesh: &TriangleMesh) -> Option<[Vec3; 3]> {
    let [t0, t1] = mesh.indices.as_slice() else { return None };
    if mesh.normals.is_some() || t1[0] != t0[0] || t1[1] != t0[2] {
        return None;
    }
    let [a, b, c, d] = [t0[0], t0[1], t0[2], t1[2]].map(|i| mesh.positions[i as usize]);
    let (e1, e2) = (b - a, d - a);
    let scale = e1.length().max(e2.length());
    let gap = (a + c - b - d).length();
    (scale > 0.0 && scale.is_finite() && gap <= 1e-5 * scale && e1.cross(e2).length() > 0.0).then_some([a, e1, e2])
}

/// A shape: geometry plus what is bound to it.
#[derive(Clone, Debug)]
pub struct Shape {
    /// Its geometry.
    pub geometry: ShapeGeometry,
    /// Index into the scene's materials.
    pub material: u32,
    /// Index into the scene's emitters when the shape is an area light.
    pub emitter: Option<u32>,
    /// Mitsuba's `flip_normals`.
    pub flip_normals: bool,
    /// Mitsuba's `face_normals` (ignore vertex normals).
    pub face_normals: bool,
    /// Name for messages (the XML id or the plugin type).
    pub name: String,
}

/// The largest world coordinate a shape may reach (10^15): far beyond any scene, and far below
/// where the BVH builder's surface areas (squares of extents) overflow f32.
pub const MAX_EXTENT: f32 = 1e15;

impl Shape {
    /// The largest absolute world coordinate the shape reaches (NaN when one is not a number):
    /// a mesh's vertices, a sphere's centre plus radius, a disk's square corners.
    pub fn extent(&self) -> f32 {
        // A maximum that keeps a NaN once it meets one (`f32::max` would drop it).
        let max = |a: f32, b: f32| if a.is_nan() || b.is_nan() { f32::NAN } else { a.max(b) };
        let reach = |p: Vec3| p.abs().to_array().into_iter().fold(0.0, max);
        match &self.geometry {
            ShapeGeometry::Mesh { mesh, .. } => mesh.positions.iter().map(|&p| reach(p)).fold(0.0, max),
            ShapeGeometry::Sphere { center, radius, .. } => reach(*center) + radius,
            ShapeGeometry::Disk { to_world, .. } => [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                .into_iter()
                .map(|(x, y)| reach(to_world.transform_point3(Vec3::new(x, y, 0.0))))
                .fold(0.0, max),
        }
    }
}

/// Local differential geometry at a ray hit.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceInteraction {
    /// Hit distance along the ray.
    pub t: f32,
    /// Position.
    pub p: Vec3,
    /// Geometric normal (flipped when the shape says so).
    pub ng: Vec3,
    /// Shading frame; `sh.n` is the shading normal.
    pub sh: Frame,
    /// Texture coordinates.
    pub uv: Vec2,
    /// ∂p/∂u and ∂p/∂v.
    pub dpdu: Vec3,
    /// See `dpdu`.
    pub dpdv: Vec3,
    /// ∂n/∂u and ∂n/∂v of the shading normal.
    pub dndu: Vec3,
    /// See `dndu`.
    pub dndv: Vec3,
    /// Index of the shape hit.
    pub shape: u32,
}

impl SurfaceInteraction {
    /// The hit as the footprint crate sees a path vertex: position, shading frame (normal,
    /// tangent, bitangent), ∂p/∂u, ∂p/∂v, ∂n/∂u, ∂n/∂v and uv, in double precision.
    pub fn footprint_vertex(&self) -> footprint::Vertex {
        footprint::Vertex {
            p: self.p.as_dvec3(),
            n: self.sh.n.as_dvec3(),
            t: self.sh.s.as_dvec3(),
            b: self.sh.t.as_dvec3(),
            dpdu: self.dpdu.as_dvec3(),
            dpdv: self.dpdv.as_dvec3(),
            dndu: self.dndu.as_dvec3(),
            dndv: self.dndv.as_dvec3(),
            uv: glam::DVec2::new(self.uv.x as f64, self.uv.y as f64),
        }
    }

    /// The footprint a material's graphs are evaluated over at this hit: its uv centre and uv
    /// covariance `cov`, and the hit's geometry for nodes that read more than uv (`position`,
    /// `normal`, `tangent`, `bitangent`, 3D noises): world position, shading normal, the shading
    /// frame's tangent (∂p/∂u made orthogonal to the normal) and bitangent, ∂p/∂u, ∂p/∂v (so the
    /// position's footprint is `J Σ Jᵀ`) and ∂n/∂u, ∂n/∂v. World space is also MaterialX's
    /// object space here: shapes are transformed to world space at load.
    pub fn graph_footprint(&self, cov: glam::Mat2) -> graph::Footprint {
        let geom = graph::Geometry {
            p: self.p,
            n: self.sh.n,
            t: self.sh.s,
            b: self.sh.t,
            dpdu: self.dpdu,
            dpdv: self.dpdv,
            dndu: self.dndu,
            dndv: self.dndv,
        };
        graph::Footprint::with_geometry(self.uv, cov, geom)
    }
}

/// What kind of primitive a BVH leaf holds (kept beside the reference so that a triangle test
/// never has to load its shape).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PrimKind {
    Triangle,
    Sphere,
    Disk,
}

/// Which primitive a BVH leaf refers to.
#[derive(Clone, Copy, Debug)]
struct PrimRef {
    kind: PrimKind,
    shape: u32,
    /// Triangle index within a mesh; unused for spheres and disks.
    index: u32,
}

/// Precomputed triangle for intersection: v0 and two edges, as 16-byte SIMD vectors (one aligned
/// load each, where 12-byte vectors took two overlapping loads).
#[derive(Clone, Copy, Debug)]
struct TriPrim {
    v0: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
}

/// Ray queries against a scene's primitives: the seam behind which a backend sits, the built-in
/// [`Accel`] (the `obvhs` crate's compressed wide BVH), Embree ([`crate::embree::EmbreeAccel`])
/// or, for small scenes, a test of every primitive ([`crate::exhaustive::ExhaustiveAccel`]),
/// chosen by [`crate::accel::build_intersector`].
pub trait Intersector: Send + Sync {
    /// The closest hit along `ray`, if any.
    fn intersect(&self, shapes: &[Shape], ray: &Ray) -> Option<PreliminaryHit>;
    /// True when anything blocks `ray` within its interval.
    fn occluded(&self, shapes: &[Shape], ray: &Ray) -> bool;
    /// The closest hit along `ray` on shape `shape` alone, whatever lies in front of it. A
    /// backend without it answers `None` (the renderer then evaluates first-hit textures per
    /// sample).
    fn intersect_shape(&self, shapes: &[Shape], ray: &Ray, shape: u32) -> Option<PreliminaryHit> {
        let _ = (shapes, ray, shape);
        None
    }
    /// What answers the queries, for reports ("built-in BVH (N primitives)", say).
    fn describe(&self) -> String;
}

/// The acceleration structure over all primitives of a scene.
pub struct Accel {
    bvh: obvhs::cwbvh::CwBvh,
    prims: Vec<PrimRef>,
    tris: Vec<TriPrim>,
    /// Scene bounds (for directional and environment lights).
    pub bounds_min: Vec3,
    /// See `bounds_min`.
    pub bounds_max: Vec3,
}

/// What the BVH reports before the interaction is completed.
#[derive(Clone, Copy, Debug)]
pub struct PreliminaryHit {
    /// Distance.
    pub t: f32,
    /// Shape index.
    pub shape: u32,
    /// Triangle index for meshes.
    pub index: u32,
    /// Barycentrics (b1, b2) for triangles.
    pub bary: Vec2,
}

#[inline]
fn intersect_triangle(tri: &TriPrim, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> Option<(f32, Vec2)> {
    let pvec = d.cross(tri.e2);
    let det = tri.e1.dot(pvec);
    if det.abs() < 1e-20 {
        return None;
    }
    let inv_det = 1.0 / det;
    let tvec = o - tri.v0;
    let u = tvec.dot(pvec) * inv_det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let qvec = tvec.cross(tri.e1);
    let v = d.dot(qvec) * inv_det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = tri.e2.dot(qvec) * inv_det;
    if t > tmin && t < tmax {
        Some((t, Vec2::new(u, v)))
    } else {
        None
    }
}

#[inline]
pub(crate) fn intersect_sphere(center: Vec3, radius: f32, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<f32> {
    // Double precision keeps grazing and distant hits stable.
    let oc = (o - center).as_dvec3();
    let d = d.as_dvec3();
    // `d` is unit only to f32 precision: keep a = d·d, or the discriminant's error grows with
    // the squared distance to the sphere.
    let a = d.length_squared();
    let b = oc.dot(d);
    let c = oc.length_squared() - (radius as f64) * (radius as f64);
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    let t0 = ((-b - sq) / a) as f32;
    let t1 = ((-b + sq) / a) as f32;
    if t0 > tmin && t0 < tmax {
        Some(t0)
    } else if t1 > tmin && t1 < tmax {
        Some(t1)
    } else {
        None
    }
}

#[inline]
pub(crate) fn intersect_disk(to_object: &Affine3A, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<f32> {
    let lo = to_object.transform_point3(o);
    let ld = to_object.transform_vector3(d);
    if ld.z == 0.0 {
        return None;
    }
    let t = -lo.z / ld.z;
    if !(t > tmin && t < tmax) {
        return None;
    }
    let p = lo + ld * t;
    if p.x * p.x + p.y * p.y <= 1.0 {
        Some(t)
    } else {
        None
    }
}

/// The BVH crate's ray. Negative zeros in the direction become positive: the traversal picks
/// child order from the direction's sign bits but inverts components with a sign-blind guard,
/// so a −0.0 component (as in `-Vec3::Z`) made the two disagree and rays miss.
#[inline]
fn bvh_ray(ray: &Ray) -> obvhs::ray::Ray {
    let d = ray.d + Vec3::ZERO;
    obvhs::ray::Ray::new(ray.o.into(), d.into(), ray.tmin, ray.tmax)
}

/// Gives a disk's box a little thickness around its corners' bounds (a conservative margin for
/// the rounding of the transformed corners).
fn padded(bb: Aabb) -> Aabb {
    let pad = Vec3A::splat(1e-6 * (1.0 + bb.diagonal().length() + bb.center().abs().max_element()));
    Aabb::new(bb.min - pad, bb.max + pad)
}

/// The deepest BVH (levels below the root) the traversal walks: its stack holds 32 node groups
/// and, when full, overwrites its top, so a deeper tree loses nodes and rays miss what they hit.
pub const MAX_BVH_DEPTH: u32 = 31;

/// `obvhs::cwbvh::builder::build_cwbvh` (PLOC, reinsertion, the 8-wide conversion) without its
/// debug-build validation, which asserts on a tree deeper than [`MAX_BVH_DEPTH`] where
/// [`Accel::build`] returns an error.
fn build_cwbvh(aabbs: &[Aabb]) -> obvhs::cwbvh::CwBvh {
    let config = obvhs::BvhBuildParams::slow_build();
    let mut bvh2 = obvhs::ploc::PlocBuilder::with_capacity(aabbs.len()).build(
        config.ploc_search_distance,
        aabbs,
        (0..aabbs.len() as u32).collect::<Vec<_>>(),
        config.sort_precision,
        config.search_depth_threshold,
    );
    obvhs::bvh2::reinsertion::ReinsertionOptimizer::default().run(&mut bvh2, config.reinsertion_batch_ratio, None);
    obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh(&bvh2, config.max_prims_per_leaf.clamp(1, 3), true, false)
}

/// The levels below the root of `bvh`'s deepest node (a node's internal children are
/// `child_base_idx ..` in order, one per set bit of `imask`).
fn bvh_depth(bvh: &obvhs::cwbvh::CwBvh) -> u32 {
    let mut deepest = 0;
    let mut stack = if bvh.nodes.is_empty() { Vec::new() } else { vec![(0usize, 0u32)] };
    while let Some((i, depth)) = stack.pop() {
        deepest = deepest.max(depth);
        let node = &bvh.nodes[i];
        stack.extend((0..node.imask.count_ones() as usize).map(|k| (node.child_base_idx as usize + k, depth + 1)));
    }
    deepest
}

impl Accel {
    /// Builds the BVH over every primitive of `shapes`; an error (a message) when it is deeper
    /// than the traversal walks ([`MAX_BVH_DEPTH`]).
    pub fn build(shapes: &[Shape]) -> std::result::Result<Self, String> {
        Accel::build_where(shapes, |_| true)
    }

    /// [`Accel::build`] over the shapes `keep` accepts (their hits keep their indices in
    /// `shapes`).
    pub fn build_where(shapes: &[Shape], keep: impl Fn(&Shape) -> bool) -> std::result::Result<Self, String> {
        let mut aabbs = Vec::new();
        let mut prims = Vec::new();
        let mut tris_unordered = Vec::new();
        for (si, shape) in shapes.iter().enumerate().filter(|(_, s)| keep(s)) {
            match &shape.geometry {
                ShapeGeometry::Mesh { mesh, .. } => {
                    for (ti, idx) in mesh.indices.iter().enumerate() {
                        let [a, b, c] = idx.map(|i| mesh.positions[i as usize]);
                        let mut bb = Aabb::from_point(a.into());
                        bb.extend(b.into());
                        bb.extend(c.into());
                        aabbs.push(bb);
                        prims.push(PrimRef { kind: PrimKind::Triangle, shape: si as u32, index: ti as u32 });
                        tris_unordered.push(TriPrim { v0: a.into(), e1: (b - a).into(), e2: (c - a).into() });
                    }
                }
                ShapeGeometry::Sphere { center, radius, .. } => {
                    let r = Vec3::splat(*radius);
                    aabbs.push(Aabb::new((*center - r).into(), (*center + r).into()));
                    prims.push(PrimRef { kind: PrimKind::Sphere, shape: si as u32, index: 0 });
                    tris_unordered.push(TriPrim { v0: Vec3A::ZERO, e1: Vec3A::ZERO, e2: Vec3A::ZERO });
                }
                ShapeGeometry::Disk { to_world, .. } => {
                    // Bound the disk by its square's four corners.
                    let mut bb = Aabb::empty();
                    for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                        bb.extend(Vec3A::from(to_world.transform_point3(Vec3::new(x, y, 0.0))));
                    }
                    aabbs.push(padded(bb));
                    prims.push(PrimRef { kind: PrimKind::Disk, shape: si as u32, index: 0 });
                    tris_unordered.push(TriPrim { v0: Vec3A::ZERO, e1: Vec3A::ZERO, e2: Vec3A::ZERO });
                }
            }
        }
        let mut bounds = Aabb::empty();
        for bb in &aabbs {
            bounds = bounds.union(bb);
        }
        let bvh = if aabbs.is_empty() { obvhs::cwbvh::CwBvh::default() } else { build_cwbvh(&aabbs) };
        let depth = bvh_depth(&bvh);
        if depth > MAX_BVH_DEPTH {
            return Err(format!(
                "the scene's {} primitives make a BVH {depth} levels deep, more than the {MAX_BVH_DEPTH} its traversal walks; are many of them on top of one another (a mesh's faces repeated, say)?",
                aabbs.len()
            ));
        }
        // Reorder primitives to BVH leaf order so traversal reads them sequentially.
        let (prims, tris) = if aabbs.is_empty() {
            (prims, tris_unordered)
        } else {
            let order = &bvh.primitive_indices;
            (
                order.iter().map(|&i| prims[i as usize]).collect(),
                order.iter().map(|&i| tris_unordered[i as usize]).collect(),
            )
        };
        let (bounds_min, bounds_max) =
            if aabbs.is_empty() { (Vec3::ZERO, Vec3::ZERO) } else { (Vec3::from(bounds.min), Vec3::from(bounds.max)) };
        Ok(Accel { bvh, prims, tris, bounds_min, bounds_max })
    }

    #[inline]
    fn intersect_prim(
        &self,
        shapes: &[Shape],
        i: usize,
        o: Vec3A,
        d: Vec3A,
        tmin: f32,
        tmax: f32,
    ) -> Option<(f32, Vec2)> {
        let pr = self.prims[i];
        if pr.kind == PrimKind::Triangle {
            return intersect_triangle(&self.tris[i], o, d, tmin, tmax);
        }
        let (o, d) = (Vec3::from(o), Vec3::from(d));
        match &shapes[pr.shape as usize].geometry {
            ShapeGeometry::Sphere { center, radius, .. } => {
                intersect_sphere(*center, *radius, o, d, tmin, tmax).map(|t| (t, Vec2::ZERO))
            }
            ShapeGeometry::Disk { to_object, .. } => {
                intersect_disk(to_object, o, d, tmin, tmax).map(|t| (t, Vec2::ZERO))
            }
            ShapeGeometry::Mesh { .. } => None,
        }
    }

    /// The closest hit along `ray`, on shape `only` alone if given.
    #[inline]
    fn closest(&self, shapes: &[Shape], ray: &Ray, only: Option<u32>) -> Option<PreliminaryHit> {
        if self.prims.is_empty() {
            return None;
        }
        let bray = bvh_ray(ray);
        let mut hit = obvhs::ray::RayHit::none();
        let mut best_bary = Vec2::ZERO;
        let (o, d) = (Vec3A::from(ray.o), Vec3A::from(ray.d));
        let found = self.bvh.ray_traverse(bray, &mut hit, |r, id| {
            if only.is_some_and(|s| self.prims[id].shape != s) {
                return f32::INFINITY;
            }
            match self.intersect_prim(shapes, id, o, d, ray.tmin, r.tmax) {
                Some((t, bary)) => {
                    best_bary = bary;
                    t
                }
                None => f32::INFINITY,
            }
        });
        // `ray_traverse` records the last improving hit; barycentrics were stored with it.
        if !found {
            return None;
        }
        let pr = self.prims[hit.primitive_id as usize];
        Some(PreliminaryHit { t: hit.t, shape: pr.shape, index: pr.index, bary: best_bary })
    }
}

impl Intersector for Accel {
    fn intersect(&self, shapes: &[Shape], ray: &Ray) -> Option<PreliminaryHit> {
        self.closest(shapes, ray, None)
    }

    fn intersect_shape(&self, shapes: &[Shape], ray: &Ray, shape: u32) -> Option<PreliminaryHit> {
        self.closest(shapes, ray, Some(shape))
    }

    fn occluded(&self, shapes: &[Shape], ray: &Ray) -> bool {
        if self.prims.is_empty() {
            return false;
        }
        let bray = bvh_ray(ray);
        let (o, d) = (Vec3A::from(ray.o), Vec3A::from(ray.d));
        !self.bvh.ray_traverse_miss(bray, |r, id| {
            self.intersect_prim(shapes, id, o, d, ray.tmin, r.tmax).map_or(f32::INFINITY, |h| h.0)
        })
    }

    fn describe(&self) -> String {
        format!("built-in BVH ({} primitives)", self.prims.len())
    }
}

/// Completes a BVH hit into a full surface interaction.
pub fn interaction(shapes: &[Shape], ray: &Ray, hit: &PreliminaryHit) -> SurfaceInteraction {
    interaction_with(shapes, ray, hit, true)
}

/// [`interaction`], with the surface parametrisation only when `uv` asks for it: without it a
/// sphere's uv, ∂p/∂v, ∂n/∂u and ∂n/∂v are left zero (its position, normals, shading frame and
/// ∂p/∂u are the same as ever), which saves an `acos`, an `atan2` and two `sin_cos` per hit.
/// The path loop asks for them only where a texture, a footprint or an observer reads them
/// (Mitsuba's ray flags make the same choice). Meshes and disks are always complete.
#[inline]
pub fn interaction_with(shapes: &[Shape], ray: &Ray, hit: &PreliminaryHit, uv: bool) -> SurfaceInteraction {
    let shape = &shapes[hit.shape as usize];
    let p_ray = ray.at(hit.t);
    let mut si = match &shape.geometry {
        ShapeGeometry::Mesh { mesh, frames, .. } => mesh_interaction(mesh, frames, hit, shape.face_normals),
        ShapeGeometry::Sphere { center, radius, rotation } if !uv => sphere_frame(*center, *radius, rotation, p_ray),
        ShapeGeometry::Sphere { center, radius, rotation } => sphere_interaction(*center, *radius, rotation, p_ray),
        ShapeGeometry::Disk { to_world, to_object, normal, .. } => {
            disk_interaction(to_world, to_object, *normal, p_ray)
        }
    };
    si.t = hit.t;
    si.shape = hit.shape;
    if shape.flip_normals {
        si.ng = -si.ng;
        si.sh = Frame { s: si.sh.s, t: -si.sh.t, n: -si.sh.n };
        si.dndu = -si.dndu;
        si.dndv = -si.dndv;
    }
    si
}

fn empty_interaction(p: Vec3, n: Vec3) -> SurfaceInteraction {
    SurfaceInteraction {
        t: 0.0,
        p,
        ng: n,
        sh: Frame::from_normal(n),
        uv: Vec2::ZERO,
        dpdu: Vec3::ZERO,
        dpdv: Vec3::ZERO,
        dndu: Vec3::ZERO,
        dndv: Vec3::ZERO,
        shape: 0,
    }
}

/// Solves for (∂f/∂u, ∂f/∂v) given f's differences along two triangle edges and the uv deltas.
#[inline]
fn uv_derivatives(duv1: Vec2, duv2: Vec2, d1: Vec3, d2: Vec3) -> Option<(Vec3, Vec3)> {
    let det = duv1.x * duv2.y - duv1.y * duv2.x;
    if det.abs() < 1e-20 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    Some(((d1 * duv2.y - d2 * duv1.y) * inv, (d2 * duv1.x - d1 * duv2.x) * inv))
}

fn mesh_interaction(
    mesh: &TriangleMesh,
    frames: &[TriangleFrame],
    hit: &PreliminaryHit,
    face_normals: bool,
) -> SurfaceInteraction {
    let [i0, i1, i2] = mesh.indices[hit.index as usize].map(|i| i as usize);
    let frame = &frames[hit.index as usize];
    let (p0, p1, p2) = (mesh.positions[i0], mesh.positions[i1], mesh.positions[i2]);
    let (b1, b2) = (hit.bary.x, hit.bary.y);
    let b0 = 1.0 - b1 - b2;
    let p = p0 * b0 + p1 * b1 + p2 * b2;
    let ng = frame.face.n;
    let (uv0, uv1, uv2) = match &mesh.uvs {
        Some(uv) => (uv[i0], uv[i1], uv[i2]),
        None => (Vec2::ZERO, Vec2::X, Vec2::Y),
    };
    let uv = uv0 * b0 + uv1 * b1 + uv2 * b2;
    let (duv1, duv2) = (uv1 - uv0, uv2 - uv0);
    let (dpdu, dpdv) = (frame.dpdu, frame.dpdv);
    let mut si = empty_interaction(p, ng);
    si.uv = uv;
    si.dpdu = dpdu;
    si.dpdv = dpdv;
    si.sh = frame.face;
    if let (Some(normals), false) = (&mesh.normals, face_normals) {
        let (n0, n1, n2) = (normals[i0], normals[i1], normals[i2]);
        let nn = n0 * b0 + n1 * b1 + n2 * b2;
        let len = nn.length();
        if len > 1e-12 {
            let n = nn / len;
            if let Some((dndu_raw, dndv_raw)) = uv_derivatives(duv1, duv2, n1 - n0, n2 - n0) {
                // Derivative of the normalised interpolant.
                si.dndu = (dndu_raw - n * n.dot(dndu_raw)) / len;
                si.dndv = (dndv_raw - n * n.dot(dndv_raw)) / len;
            }
            si.sh = Frame::from_normal_tangent(n, dpdu);
        }
    }
    si
}

/// A sphere hit's position, normal, ∂p/∂u and shading frame, as [`sphere_interaction`] has them.
fn sphere_frame(center: Vec3, radius: f32, rotation: &Mat3, p_ray: Vec3) -> SurfaceInteraction {
    let n = (p_ray - center).normalize();
    let p = center + n * radius;
    let local = rotation.transpose() * n;
    let dpdu = *rotation * (Vec3::new(-local.y, local.x, 0.0) * (2.0 * PI * radius));
    let mut si = empty_interaction(p, n);
    si.dpdu = dpdu;
    si.sh = Frame::from_normal_tangent(n, dpdu);
    si
}

fn sphere_interaction(center: Vec3, radius: f32, rotation: &Mat3, p_ray: Vec3) -> SurfaceInteraction {
    let n = (p_ray - center).normalize();
    // Re-project onto the surface to remove the error of the ray parameter.
    let p = center + n * radius;
    let local = rotation.transpose() * n;
    let theta = local.z.clamp(-1.0, 1.0).acos();
    let mut phi = local.y.atan2(local.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    // The angles' sines and cosines from the point itself (its distance from the axis is
    // sin θ), not from the angles: two `sincosf` fewer per hit. At the poles φ is 0.
    let sin_theta = (local.x * local.x + local.y * local.y).sqrt();
    let cos_theta = local.z.clamp(-1.0, 1.0);
    let (sin_phi, cos_phi) = if sin_theta > 0.0 { (local.y / sin_theta, local.x / sin_theta) } else { (0.0, 1.0) };
    let dpdu_l = Vec3::new(-local.y, local.x, 0.0) * (2.0 * PI * radius);
    let dpdv_l = Vec3::new(cos_phi * cos_theta, sin_phi * cos_theta, -sin_theta) * (PI * radius);
    let dpdu = *rotation * dpdu_l;
    let dpdv = *rotation * dpdv_l;
    let mut si = empty_interaction(p, n);
    si.uv = Vec2::new(phi / (2.0 * PI), theta / PI);
    si.dpdu = dpdu;
    si.dpdv = dpdv;
    si.dndu = dpdu / radius;
    si.dndv = dpdv / radius;
    si.sh = Frame::from_normal_tangent(n, dpdu);
    si
}

fn disk_interaction(to_world: &Affine3A, to_object: &Affine3A, normal: Vec3, p_ray: Vec3) -> SurfaceInteraction {
    let local = to_object.transform_point3(p_ray);
    let local = Vec3::new(local.x, local.y, 0.0);
    let p = to_world.transform_point3(local);
    let r = (local.x * local.x + local.y * local.y).sqrt();
    let mut phi = local.y.atan2(local.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    // φ's sine and cosine from the point (no `sincosf`); at the centre φ is 0.
    let (sin_phi, cos_phi) = if r > 0.0 { (local.y / r, local.x / r) } else { (0.0, 1.0) };
    let dpdu = to_world.transform_vector3(Vec3::new(cos_phi, sin_phi, 0.0));
    let dpdv = to_world.transform_vector3(Vec3::new(-sin_phi, cos_phi, 0.0) * (2.0 * PI * r));
    let mut si = empty_interaction(p, normal);
    si.uv = Vec2::new(r, phi / (2.0 * PI));
    si.dpdu = dpdu;
    si.dpdv = dpdv;
    si.sh = Frame::from_normal_tangent(normal, dpdu);
    si
}

/// A point sampled on a shape's surface.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceSample {
    /// Position.
    pub p: Vec3,
    /// Normal (after `flip_normals`).
    pub n: Vec3,
    /// Density with respect to area.
    pub pdf_area: f32,
}

impl Shape {
    /// Total surface area.
    pub fn area(&self) -> f32 {
        match &self.geometry {
            ShapeGeometry::Mesh { area, .. } => area.total(),
            ShapeGeometry::Sphere { radius, .. } => 4.0 * PI * radius * radius,
            ShapeGeometry::Disk { area, .. } => *area,
        }
    }

    /// Samples a point uniformly by area.
    pub fn sample_area(&self, u: Vec2) -> SurfaceSample {
        let flip = if self.flip_normals { -1.0 } else { 1.0 };
        match &self.geometry {
            ShapeGeometry::Mesh { frames, parallelogram: Some([o, e1, e2]), area, .. } => {
                // Both triangles share the face normal.
                SurfaceSample {
                    p: *o + *e1 * u.x + *e2 * u.y,
                    n: frames[0].face.n * flip,
                    pdf_area: 1.0 / area.total(),
                }
            }
            ShapeGeometry::Mesh { mesh, area, frames, .. } => {
                let (ti, ux) = area.sample(u.x);
                let [a, b, c] = mesh.indices[ti].map(|i| mesh.positions[i as usize]);
                let bary = crate::sampling::square_to_triangle(Vec2::new(ux, u.y));
                let p = a * (1.0 - bary.x - bary.y) + b * bary.x + c * bary.y;
                let mut n = frames[ti].face.n;
                if let (Some(normals), false) = (&mesh.normals, self.face_normals) {
                    let [na, nb, nc] = mesh.indices[ti].map(|i| normals[i as usize]);
                    n = (na * (1.0 - bary.x - bary.y) + nb * bary.x + nc * bary.y).normalize_or(n);
                }
                SurfaceSample { p, n: n * flip, pdf_area: 1.0 / area.total() }
            }
            ShapeGeometry::Sphere { center, radius, .. } => {
                let n = crate::sampling::square_to_uniform_sphere(u);
                SurfaceSample { p: *center + n * *radius, n: n * flip, pdf_area: 1.0 / self.area() }
            }
            ShapeGeometry::Disk { to_world, normal, area, .. } => {
                let d = crate::sampling::square_to_disk_concentric(u);
                let p = to_world.transform_point3(Vec3::new(d.x, d.y, 0.0));
                SurfaceSample { p, n: *normal * flip, pdf_area: 1.0 / *area }
            }
        }
    }
}

/// Builds a mesh shape's area distribution; `None` when the mesh has no area.
pub fn mesh_area_distribution(mesh: &TriangleMesh) -> Option<crate::sampling::Distribution1D> {
    let areas: Vec<f32> = mesh
        .indices
        .iter()
        .map(|idx| {
            let [a, b, c] = idx.map(|i| mesh.positions[i as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .collect();
    crate::sampling::Distribution1D::new(&areas)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mitsuba's rectangle: [−1, 1]² at z = 0, uv = ((x+1)/2, (y+1)/2).
    fn quad() -> TriangleMesh {
        crate::mesh::rectangle_mesh()
    }

    fn mesh_shape(mesh: TriangleMesh) -> Shape {
        let area = mesh_area_distribution(&mesh).unwrap();
        Shape {
            geometry: ShapeGeometry::mesh(mesh, area),
            material: 0,
            emitter: None,
            flip_normals: false,
            face_normals: false,
            name: "test".into(),
        }
    }

    #[test]
    fn quad_hit_has_mitsuba_uv_and_derivatives() {
        let shapes = vec![mesh_shape(quad())];
        let accel = Accel::build(&shapes).unwrap();
        let ray = Ray::new(Vec3::new(0.5, -0.5, 3.0), -Vec3::Z);
        let hit = accel.intersect(&shapes, &ray).expect("hit");
        assert!((hit.t - 3.0).abs() < 1e-5);
        let si = interaction(&shapes, &ray, &hit);
        assert!((si.uv - Vec2::new(0.75, 0.25)).length() < 1e-5, "{:?}", si.uv);
        assert!((si.dpdu - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-5);
        assert!((si.dpdv - Vec3::new(0.0, 2.0, 0.0)).length() < 1e-5);
        assert!((si.ng - Vec3::Z).length() < 1e-6);
        assert!(accel.occluded(&shapes, &ray));
        let miss = Ray::new(Vec3::new(1.5, 0.0, 3.0), -Vec3::Z);
        assert!(accel.intersect(&shapes, &miss).is_none());
    }

    #[test]
    fn sphere_derivatives_match_finite_differences() {
        let rotation = Mat3::from_rotation_y(0.3) * Mat3::from_rotation_x(-0.7);
        let center = Vec3::new(0.2, -0.1, 0.4);
        let shapes = vec![Shape {
            geometry: ShapeGeometry::Sphere { center, radius: 0.8, rotation },
            material: 0,
            emitter: None,
            flip_normals: false,
            face_normals: false,
            name: "s".into(),
        }];
        let accel = Accel::build(&shapes).unwrap();
        let ray = Ray::new(Vec3::new(0.5, 0.3, 5.0), Vec3::new(-0.05, -0.05, -1.0).normalize());
        let hit = accel.intersect(&shapes, &ray).unwrap();
        let si = interaction(&shapes, &ray, &hit);
        assert!(((si.p - center).length() - 0.8).abs() < 1e-5);
        // Surface position as a function of uv, in object space rotated to world.
        let pos = |u: f32, v: f32| {
            let (phi, theta) = (u * 2.0 * PI, v * PI);
            center + rotation * Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()) * 0.8
        };
        assert!((pos(si.uv.x, si.uv.y) - si.p).length() < 1e-4);
        let h = 1e-3;
        let fd_u = (pos(si.uv.x + h, si.uv.y) - pos(si.uv.x - h, si.uv.y)) / (2.0 * h);
        let fd_v = (pos(si.uv.x, si.uv.y + h) - pos(si.uv.x, si.uv.y - h)) / (2.0 * h);
        assert!((fd_u - si.dpdu).length() < 2e-3 * si.dpdu.length(), "{fd_u} {}", si.dpdu);
        assert!((fd_v - si.dpdv).length() < 2e-3 * si.dpdv.length(), "{fd_v} {}", si.dpdv);
    }

    /// A sphere hit without its parametrisation has the very position, normals, ∂p/∂u and
    /// shading frame of the complete one (the path loop relies on it for bit-identical images),
    /// over hits all round a rotated, flipped sphere.
    #[test]
    fn sphere_hit_without_uv_keeps_the_frame() {
        let rotation = Mat3::from_rotation_z(1.1) * Mat3::from_rotation_x(0.4);
        let center = Vec3::new(-0.3, 0.2, 0.1);
        for flip_normals in [false, true] {
            let shapes = vec![Shape {
                geometry: ShapeGeometry::Sphere { center, radius: 0.6, rotation },
                material: 0,
                emitter: None,
                flip_normals,
                face_normals: false,
                name: "s".into(),
            }];
            let accel = Accel::build(&shapes).unwrap();
            let mut rng = crate::sampling::Rng::for_sample(7, 0, 0);
            let mut hits = 0;
            for _ in 0..500 {
                let o = center + crate::sampling::square_to_uniform_sphere(rng.next_2d()) * 3.0;
                let target = center + (rng.next_2d() - 0.5).extend(rng.next_f32() - 0.5);
                let ray = Ray::new(o, (target - o).normalize());
                let Some(hit) = accel.intersect(&shapes, &ray) else { continue };
                hits += 1;
                let (full, part) = (interaction(&shapes, &ray, &hit), interaction_with(&shapes, &ray, &hit, false));
                assert_eq!(
                    (full.p, full.ng, full.dpdu, full.t, full.shape),
                    (part.p, part.ng, part.dpdu, part.t, part.shape)
                );
                assert_eq!((full.sh.s, full.sh.t, full.sh.n), (part.sh.s, part.sh.t, part.sh.n));
                assert_eq!(
                    (part.uv, part.dpdv, part.dndu, part.dndv),
                    (Vec2::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO)
                );
            }
            assert!(hits > 400, "{hits} hits");
        }
    }

    #[test]
    fn interpolated_normal_derivatives_match_finite_differences() {
        let mut mesh = quad();
        mesh.normals = Some(vec![
            Vec3::new(-0.3, -0.2, 1.0).normalize(),
            Vec3::new(0.4, -0.1, 1.0).normalize(),
            Vec3::new(0.2, 0.3, 1.0).normalize(),
            Vec3::new(-0.2, 0.4, 1.0).normalize(),
        ]);
        let shapes = vec![mesh_shape(mesh)];
        let accel = Accel::build(&shapes).unwrap();
        let normal_at = |x: f32, y: f32| {
            let ray = Ray::new(Vec3::new(x, y, 2.0), -Vec3::Z);
            let hit = accel.intersect(&shapes, &ray).unwrap();
            interaction(&shapes, &ray, &hit)
        };
        let si = normal_at(0.3, -0.4);
        // u = (x+1)/2, so a step h in u is 2h in x.
        let h = 1e-3;
        let fd = (normal_at(0.3 + 2.0 * h, -0.4).sh.n - normal_at(0.3 - 2.0 * h, -0.4).sh.n) / (2.0 * h);
        assert!((fd - si.dndu).length() < 1e-2 * si.dndu.length().max(1e-3), "{fd} {}", si.dndu);
    }

    #[test]
    fn disk_uv_follows_mitsuba() {
        let to_world = Affine3A::from_scale(Vec3::splat(2.0));
        let shapes = vec![Shape {
            geometry: ShapeGeometry::Disk { to_world, to_object: to_world.inverse(), normal: Vec3::Z, area: 4.0 * PI },
            material: 0,
            emitter: None,
            flip_normals: false,
            face_normals: false,
            name: "d".into(),
        }];
        let accel = Accel::build(&shapes).unwrap();
        let ray = Ray::new(Vec3::new(0.0, 1.0, 1.0), -Vec3::Z);
        let si = interaction(&shapes, &ray, &accel.intersect(&shapes, &ray).unwrap());
        assert!((si.uv - Vec2::new(0.5, 0.25)).length() < 1e-5, "{:?}", si.uv);
        let outside = Ray::new(Vec3::new(1.5, 1.5, 1.0), -Vec3::Z);
        assert!(accel.intersect(&shapes, &outside).is_none());
    }

    /// A sheared, scaled rectangle is sampled as a parallelogram: every point on the surface,
    /// the normal and density the triangle path gives, and uniform over the area (cell counts
    /// of a 4 × 4 grid in the edges' coordinates within 5 standard errors of 1/16, as are the
    /// triangle path's). A trapezoid and a mesh with vertex normals keep the triangle path.
    #[test]
    fn rectangles_sample_as_parallelograms() {
        let m = glam::Mat4::from_cols_array(&[
            1.5, 0.2, 0.1, 0.0, 0.7, 0.9, -0.3, 0.0, 0.0, 0.0, 1.0, 0.0, 0.3, -0.2, 2.0, 1.0,
        ]);
        let mut mesh = quad();
        for p in &mut mesh.positions {
            *p = m.transform_point3(*p);
        }
        let shape = mesh_shape(mesh.clone());
        let ShapeGeometry::Mesh { parallelogram: Some([o, e1, e2]), ref frames, ref area, .. } = shape.geometry else {
            panic!("a transformed rectangle is a parallelogram")
        };
        let mut triangles = mesh_shape(mesh.clone());
        if let ShapeGeometry::Mesh { parallelogram, .. } = &mut triangles.geometry {
            *parallelogram = None;
        }
        // Coordinates along the edges by the dual basis.
        let n = e1.cross(e2);
        let coords = |p: Vec3| {
            let d = p - o;
            Vec2::new(d.cross(e2).dot(n), e1.cross(d).dot(n)) / n.length_squared()
        };
        let count = 64_000usize;
        for s in [&shape, &triangles] {
            let mut cells = [0usize; 16];
            let mut rng = crate::sampling::Rng::new(5, 1);
            for _ in 0..count {
                let smp = s.sample_area(rng.next_2d());
                let c = coords(smp.p);
                assert!(c.min_element() >= -1e-5 && c.max_element() <= 1.0 + 1e-5, "{c}");
                assert!((smp.p - o - e1 * c.x - e2 * c.y).length() < 1e-4, "off the plane");
                assert!((smp.n - frames[0].face.n).length() < 1e-6);
                assert!((smp.pdf_area - 1.0 / area.total()).abs() <= 1e-6 * smp.pdf_area);
                let cell = |x: f32| ((x * 4.0) as usize).min(3);
                cells[cell(c.y) * 4 + cell(c.x)] += 1;
            }
            let expect = count as f64 / 16.0;
            let sd = (expect * 15.0 / 16.0).sqrt();
            for k in cells {
                assert!((k as f64 - expect).abs() < 5.0 * sd, "{cells:?}");
            }
        }
        // Not parallelograms, or normals to interpolate.
        let mut trapezoid = quad();
        trapezoid.positions[2].x = 0.5;
        assert!(parallelogram_of(&trapezoid).is_none());
        let mut smooth = quad();
        smooth.normals = Some(vec![Vec3::Z; 4]);
        assert!(parallelogram_of(&smooth).is_none());
        assert!(parallelogram_of(&crate::mesh::cube_mesh()).is_none());
    }
}
