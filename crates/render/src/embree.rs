//! Intel Embree 3 behind the [`Intersector`] seam, loaded at run time.
//!
//! The library is opened with `dlopen` when a scene is built (`libembree3.so.3`, or the file
//! named by `TESSERA_EMBREE`), so the same binary runs with or without it: where it is missing
//! the renderer keeps its own BVH ([`Accel`]). Debian's `libembree3-3` package provides it
//! (`scripts/install-embree.sh`).
//!
//! Embree holds every shape, one geometry per shape whose id is the shape's index: meshes as
//! triangle geometries (primitive ids are the mesh's triangle indices), spheres and disks as
//! user geometries whose callbacks run the renderer's own tests (the sphere's in double
//! precision), so one traversal answers each closest-hit and occlusion query; the closest hit on
//! one sphere or disk alone is asked of a small built-in BVH of them. Only the types and
//! functions this file uses are declared, checked against Embree 3.13's `rtcore*.h`; the library
//! must be a default build (one instance level, no minimum curve width, filter functions on),
//! which Debian's is: the first two change the ray and context layouts and cannot be queried.

use crate::geometry::{
    intersect_disk, intersect_sphere, Accel, Intersector, PreliminaryHit, Ray, Shape, ShapeGeometry,
};
use glam::{Affine3A, Vec2, Vec3};
use std::ffi::{c_char, c_void};
use std::sync::OnceLock;

type Device = *mut c_void;
type Scene = *mut c_void;
type Geometry = *mut c_void;

/// `RTCRay` (16-byte aligned, 48 bytes).
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct RtcRay {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: u32,
    id: u32,
    flags: u32,
}

/// `RTCHit` (16-byte aligned, 32 bytes, one instance level).
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct RtcHit {
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: u32,
    geom_id: u32,
    inst_id: [u32; 1],
}

/// `RTCRayHit`.
#[repr(C)]
#[derive(Clone, Copy)]
struct RtcRayHit {
    ray: RtcRay,
    hit: RtcHit,
}

/// `RTCFilterFunctionNArguments`.
#[repr(C)]
struct FilterArgs {
    valid: *mut i32,
    geometry_user_ptr: *mut c_void,
    context: *mut IntersectContext,
    ray: *mut c_void,
    hit: *mut c_void,
    n: u32,
}

type FilterFn = unsafe extern "C" fn(*const FilterArgs);

/// `RTCBounds`.
#[repr(C, align(16))]
struct Bounds {
    lower: [f32; 3],
    _align0: f32,
    upper: [f32; 3],
    _align1: f32,
}

/// `RTCBoundsFunctionArguments`.
#[repr(C)]
struct BoundsArgs {
    geometry_user_ptr: *mut c_void,
    prim_id: u32,
    time_step: u32,
    bounds: *mut Bounds,
}

/// `RTCIntersectFunctionNArguments` and `RTCOccludedFunctionNArguments` (the same layout: the
/// intersect callback's `rayhit` is the occluded callback's `ray`).
#[repr(C)]
struct UserArgs {
    valid: *mut i32,
    geometry_user_ptr: *mut c_void,
    prim_id: u32,
    context: *mut IntersectContext,
    rays: *mut f32,
    n: u32,
    geom_id: u32,
}

type BoundsFn = unsafe extern "C" fn(*const BoundsArgs);
type UserFn = unsafe extern "C" fn(*const UserArgs);

/// `RTCIntersectContext` (one instance level, no minimum width).
#[repr(C)]
struct IntersectContext {
    flags: u32,
    filter: Option<FilterFn>,
    inst_id: [u32; 1],
}

/// An intersection context followed by the one shape whose hits a query keeps (Embree hands
/// its context filter the context's address, so the shape is read just past it).
#[repr(C)]
struct ShapeContext {
    context: IntersectContext,
    shape: u32,
}

const INVALID_ID: u32 = u32::MAX;
const GEOMETRY_TYPE_TRIANGLE: u32 = 0;
const GEOMETRY_TYPE_USER: u32 = 120;
const BUFFER_TYPE_INDEX: u32 = 0;
const BUFFER_TYPE_VERTEX: u32 = 1;
const FORMAT_UINT3: u32 = 0x5003;
const FORMAT_FLOAT3: u32 = 0x9003;
const BUILD_QUALITY_HIGH: u32 = 2;
const SCENE_FLAG_CONTEXT_FILTER_FUNCTION: u32 = 1 << 3;
/// `RTC_DEVICE_PROPERTY_FILTER_FUNCTION_SUPPORTED`.
const DEVICE_PROPERTY_FILTER_FUNCTION_SUPPORTED: u32 = 66;

impl IntersectContext {
    /// `rtcInitIntersectContext`: incoherent rays, no filter.
    fn new(filter: Option<FilterFn>) -> Self {
        IntersectContext { flags: 0, filter, inst_id: [INVALID_ID] }
    }
}

/// The functions of the library this file calls.
struct Api {
    version: String,
    new_device: unsafe extern "C" fn(*const c_char) -> Device,
    release_device: unsafe extern "C" fn(Device),
    device_error: unsafe extern "C" fn(Device) -> u32,
    new_scene: unsafe extern "C" fn(Device) -> Scene,
    release_scene: unsafe extern "C" fn(Scene),
    set_scene_flags: unsafe extern "C" fn(Scene, u32),
    set_scene_build_quality: unsafe extern "C" fn(Scene, u32),
    new_geometry: unsafe extern "C" fn(Device, u32) -> Geometry,
    release_geometry: unsafe extern "C" fn(Geometry),
    set_new_geometry_buffer: unsafe extern "C" fn(Geometry, u32, u32, u32, usize, usize) -> *mut c_void,
    set_geometry_build_quality: unsafe extern "C" fn(Geometry, u32),
    commit_geometry: unsafe extern "C" fn(Geometry),
    set_geometry_user_data: unsafe extern "C" fn(Geometry, *mut c_void),
    set_geometry_user_primitive_count: unsafe extern "C" fn(Geometry, u32),
    set_geometry_bounds_function: unsafe extern "C" fn(Geometry, BoundsFn, *mut c_void),
    set_geometry_intersect_function: unsafe extern "C" fn(Geometry, UserFn),
    set_geometry_occluded_function: unsafe extern "C" fn(Geometry, UserFn),
    attach_geometry_by_id: unsafe extern "C" fn(Scene, Geometry, u32),
    commit_scene: unsafe extern "C" fn(Scene),
    intersect1: unsafe extern "C" fn(Scene, *mut IntersectContext, *mut RtcRayHit),
    occluded1: unsafe extern "C" fn(Scene, *mut IntersectContext, *mut RtcRay),
    /// Keeps the library mapped for as long as the function pointers above are used (the
    /// process's lifetime: the API is loaded once).
    _library: libloading::Library,
}

/// The library's file names tried in turn: the one `TESSERA_EMBREE` names alone when it is set
/// (a path given on purpose is not silently replaced by another copy), else Debian's names.
fn candidates() -> Vec<String> {
    match std::env::var("TESSERA_EMBREE") {
        Ok(path) if !path.is_empty() => vec![path],
        _ => vec!["libembree3.so.3".to_string(), "libembree3.so".to_string()],
    }
}

impl Api {
    fn load() -> Result<Api, String> {
        let mut tried = Vec::new();
        for name in candidates() {
            // SAFETY: loading Embree runs its initialisers, which only set up its own state.
            match unsafe { libloading::Library::new(&name) } {
                Ok(library) => return Api::bind(library).map_err(|e| format!("{name}: {e}")),
                Err(e) => tried.push(e.to_string()),
            }
        }
        Err(format!("Embree 3 is not installed ({})", tried.join("; ")))
    }

    fn bind(library: libloading::Library) -> Result<Api, String> {
        /// One function of the library, as the pointer type it is declared with above.
        macro_rules! sym {
            ($name:literal) => {
                // SAFETY: each name is declared with the signature of Embree 3's header.
                *unsafe { library.get(concat!($name, "\0").as_bytes()) }.map_err(|e| format!("{}: {e}", $name))?
            };
        }
        let get_device_property: unsafe extern "C" fn(Device, u32) -> isize = sym!("rtcGetDeviceProperty");
        let mut api = Api {
            version: String::new(),
            new_device: sym!("rtcNewDevice"),
            release_device: sym!("rtcReleaseDevice"),
            device_error: sym!("rtcGetDeviceError"),
            new_scene: sym!("rtcNewScene"),
            release_scene: sym!("rtcReleaseScene"),
            set_scene_flags: sym!("rtcSetSceneFlags"),
            set_scene_build_quality: sym!("rtcSetSceneBuildQuality"),
            new_geometry: sym!("rtcNewGeometry"),
            release_geometry: sym!("rtcReleaseGeometry"),
            set_new_geometry_buffer: sym!("rtcSetNewGeometryBuffer"),
            set_geometry_build_quality: sym!("rtcSetGeometryBuildQuality"),
            commit_geometry: sym!("rtcCommitGeometry"),
            set_geometry_user_data: sym!("rtcSetGeometryUserData"),
            set_geometry_user_primitive_count: sym!("rtcSetGeometryUserPrimitiveCount"),
            set_geometry_bounds_function: sym!("rtcSetGeometryBoundsFunction"),
            set_geometry_intersect_function: sym!("rtcSetGeometryIntersectFunction"),
            set_geometry_occluded_function: sym!("rtcSetGeometryOccludedFunction"),
            attach_geometry_by_id: sym!("rtcAttachGeometryByID"),
            commit_scene: sym!("rtcCommitScene"),
            intersect1: sym!("rtcIntersect1"),
            occluded1: sym!("rtcOccluded1"),
            _library: library,
        };
        // RTC_DEVICE_PROPERTY_VERSION_{MAJOR,MINOR,PATCH} = 1, 2, 3, on a throwaway device.
        // SAFETY: a null configuration string is the documented default.
        let device = unsafe { (api.new_device)(std::ptr::null()) };
        if device.is_null() {
            return Err("rtcNewDevice failed".into());
        }
        // SAFETY: `device` is a live device.
        let [major, minor, patch, filters] =
            [1, 2, 3, DEVICE_PROPERTY_FILTER_FUNCTION_SUPPORTED].map(|p| unsafe { get_device_property(device, p) });
        unsafe { (api.release_device)(device) };
        if major != 3 {
            return Err(format!("Embree {major}.{minor}.{patch} found where version 3 is expected"));
        }
        if filters == 0 {
            // `intersect_shape` keeps one shape's hits by a context filter.
            return Err(format!("Embree {major}.{minor}.{patch} was built without filter functions"));
        }
        api.version = format!("{major}.{minor}.{patch}");
        Ok(api)
    }
}

static API: OnceLock<Result<Api, String>> = OnceLock::new();

fn api() -> Result<&'static Api, String> {
    API.get_or_init(Api::load).as_ref().map_err(Clone::clone)
}

/// Whether Embree can be loaded, and its version (or why not).
pub fn available() -> Result<String, String> {
    api().map(|a| a.version.clone())
}

/// Context filter of [`EmbreeAccel::intersect_shape`]: rejects every hit on another geometry
/// than the query's shape.
unsafe extern "C" fn keep_one_shape(args: *const FilterArgs) {
    // SAFETY: Embree passes live arguments; the context is the first field of a
    // `ShapeContext` (only queries made by `intersect_shape` carry this filter), and the hits
    // are N structure-of-arrays lanes whose geometry ids are the seventh array of N words.
    unsafe {
        let args = &*args;
        let wanted = (*(args.context as *const ShapeContext)).shape;
        let n = args.n as usize;
        let geom_ids = (args.hit as *const u32).add(6 * n);
        for i in 0..n {
            if *geom_ids.add(i) != wanted {
                *args.valid.add(i) = 0;
            }
        }
    }
}

/// A sphere or disk as an Embree user geometry sees it (the callbacks' user pointer).
enum Analytic {
    Sphere { center: Vec3, radius: f32 },
    Disk { to_object: Affine3A, to_world: Affine3A },
}

impl Analytic {
    /// The renderer's own test ([`intersect_sphere`], [`intersect_disk`]).
    #[inline]
    fn intersect(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<f32> {
        match self {
            Analytic::Sphere { center, radius } => intersect_sphere(*center, *radius, o, d, tmin, tmax),
            Analytic::Disk { to_object, .. } => intersect_disk(to_object, o, d, tmin, tmax),
        }
    }
}

/// Bounds callback of a sphere or disk: the box the built-in BVH gives it ([`Accel::build`]).
unsafe extern "C" fn analytic_bounds(args: *const BoundsArgs) {
    // SAFETY: Embree passes the user pointer set at build (a live `Analytic` owned by the
    // accelerator) and a bounds record to write.
    unsafe {
        let args = &*args;
        let (lo, hi) = match &*(args.geometry_user_ptr as *const Analytic) {
            Analytic::Sphere { center, radius } => (*center - *radius, *center + *radius),
            Analytic::Disk { to_world, .. } => {
                let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                    .map(|(x, y)| to_world.transform_point3(Vec3::new(x, y, 0.0)));
                let (lo, hi) =
                    corners.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), c| (l.min(*c), h.max(*c)));
                // The rounding of the transformed corners, as `geometry::padded` allows.
                let pad = 1e-6 * (1.0 + (hi - lo).length() + ((lo + hi) * 0.5).abs().max_element());
                (lo - pad, hi + pad)
            }
        };
        args.bounds.write(Bounds { lower: lo.to_array(), _align0: 0.0, upper: hi.to_array(), _align1: 0.0 });
    }
}

/// The query's one shape when it carries a filter (only `intersect_shape` sets one, always
/// [`keep_one_shape`]), else `None`.
///
/// # Safety
/// `context` is a live context passed by Embree to a query of this module.
#[inline]
unsafe fn only_shape(context: *const IntersectContext) -> Option<u32> {
    // SAFETY: contexts with a filter are the first field of a `ShapeContext`, passed by a
    // pointer to the whole of it.
    unsafe { (*context).filter.map(|_| (*(context as *const ShapeContext)).shape) }
}

/// Field `k` of lane `i` of a callback's N structure-of-arrays rays: the ray's 12 fields
/// (origin, near end, direction, time, far end at 8, mask, id, flags), then the hit's (normal,
/// u, v, primitive id at 17, geometry id, instance id).
///
/// # Safety
/// `args` comes from Embree, `k` < 20 for an intersect callback (< 12 for occluded), `i` < N.
#[inline]
unsafe fn field(args: &UserArgs, k: usize, i: usize) -> *mut f32 {
    // SAFETY: within the N-lane arrays Embree passed.
    unsafe { args.rays.add(k * args.n as usize + i) }
}

/// The distance at which valid lane `i` meets the callback's shape within its interval.
///
/// # Safety
/// As [`field`]; the user pointer is the `Analytic` set at build.
#[inline]
unsafe fn lane_hit(args: &UserArgs, i: usize) -> Option<f32> {
    // SAFETY: as documented.
    unsafe {
        if *args.valid.add(i) == 0 {
            return None;
        }
        let shape = &*(args.geometry_user_ptr as *const Analytic);
        let f = |k| *field(args, k, i);
        shape.intersect(Vec3::new(f(0), f(1), f(2)), Vec3::new(f(4), f(5), f(6)), f(3), f(8))
    }
}

/// Intersect callback of a sphere or disk: a valid lane that meets it nearer than its far end
/// takes it as its hit. A query restricted to another shape ignores it (Embree applies a
/// context filter to its own geometry types; a user geometry must apply it itself).
unsafe extern "C" fn analytic_intersect(args: *const UserArgs) {
    // SAFETY: Embree passes live arguments with N lanes of ray and hit fields.
    unsafe {
        let args = &*args;
        if only_shape(args.context).is_some_and(|s| s != args.geom_id) {
            return;
        }
        for i in 0..args.n as usize {
            let Some(t) = lane_hit(args, i) else { continue };
            *field(args, 8, i) = t;
            for k in 12..17 {
                *field(args, k, i) = 0.0;
            }
            *(field(args, 17, i) as *mut u32) = args.prim_id;
            *(field(args, 18, i) as *mut u32) = args.geom_id;
            *(field(args, 19, i) as *mut u32) = (*args.context).inst_id[0];
        }
    }
}

/// Occluded callback of a sphere or disk: a blocked lane's far end becomes −∞.
unsafe extern "C" fn analytic_occluded(args: *const UserArgs) {
    // SAFETY: Embree passes live arguments with N lanes of ray fields.
    unsafe {
        let args = &*args;
        for i in 0..args.n as usize {
            if lane_hit(args, i).is_some() {
                *field(args, 8, i) = f32::NEG_INFINITY;
            }
        }
    }
}

/// The whole scene in Embree (spheres and disks through callbacks).
pub struct EmbreeAccel {
    api: &'static Api,
    device: Device,
    scene: Scene,
    /// What the user geometries' callbacks read (boxed: Embree keeps their addresses).
    #[allow(clippy::vec_box)]
    _analytic: Vec<Box<Analytic>>,
    /// The spheres and disks again, for [`Intersector::intersect_shape`] on one of them (`None`
    /// when the scene has none).
    analytic_bvh: Option<Accel>,
    triangles: usize,
}

// SAFETY: a committed Embree scene is read-only and Embree documents its queries as safe to
// make from any number of threads at once; the handles are released only on drop.
unsafe impl Send for EmbreeAccel {}
unsafe impl Sync for EmbreeAccel {}

impl Drop for EmbreeAccel {
    fn drop(&mut self) {
        // SAFETY: both handles were created by this value and are released once, the scene
        // before the user data its geometries point at (the fields drop after this).
        unsafe {
            if !self.scene.is_null() {
                (self.api.release_scene)(self.scene);
            }
            (self.api.release_device)(self.device);
        }
    }
}

impl EmbreeAccel {
    /// Builds the scene's structures; an error when Embree cannot be loaded or fails.
    pub fn build(shapes: &[Shape]) -> Result<EmbreeAccel, String> {
        let api = api()?;
        // SAFETY: every call below follows Embree's documented order (device, scene,
        // geometries with their buffers filled to the sizes asked for, commit); handles are
        // checked before use and the errors read back from the device.
        unsafe {
            let device = (api.new_device)(c"verbose=0".as_ptr());
            if device.is_null() {
                return Err("Embree: rtcNewDevice failed".into());
            }
            let scene = (api.new_scene)(device);
            let accel = EmbreeAccel { api, device, scene, _analytic: Vec::new(), analytic_bvh: None, triangles: 0 };
            if scene.is_null() {
                return Err(accel.error("rtcNewScene"));
            }
            // Not RTC_SCENE_FLAG_ROBUST: its watertight test closes the cracks that rays through a
            // shared edge exactly can fall into (the built-in BVH has them too), at 10 % of an
            // untextured render (cbox, measured).
            (api.set_scene_flags)(scene, SCENE_FLAG_CONTEXT_FILTER_FUNCTION);
            (api.set_scene_build_quality)(scene, BUILD_QUALITY_HIGH);
            let mut accel = accel;
            for (si, shape) in shapes.iter().enumerate() {
                let mesh = match &shape.geometry {
                    ShapeGeometry::Mesh { mesh, .. } => mesh,
                    ShapeGeometry::Sphere { center, radius, .. } => {
                        accel.add_analytic(si, Analytic::Sphere { center: *center, radius: *radius })?;
                        continue;
                    }
                    ShapeGeometry::Disk { to_object, to_world, .. } => {
                        accel.add_analytic(si, Analytic::Disk { to_object: *to_object, to_world: *to_world })?;
                        continue;
                    }
                };
                if mesh.indices.is_empty() {
                    // Nothing to hit (loaded meshes always have triangles; shapes made in code
                    // may not), and Embree refuses a buffer of no items.
                    continue;
                }
                let geom = (api.new_geometry)(device, GEOMETRY_TYPE_TRIANGLE);
                if geom.is_null() {
                    return Err(accel.error("rtcNewGeometry"));
                }
                (api.set_geometry_build_quality)(geom, BUILD_QUALITY_HIGH);
                let nv = mesh.positions.len();
                let vertices =
                    (api.set_new_geometry_buffer)(geom, BUFFER_TYPE_VERTEX, 0, FORMAT_FLOAT3, 12, nv) as *mut [f32; 3];
                let nt = mesh.indices.len();
                let indices =
                    (api.set_new_geometry_buffer)(geom, BUFFER_TYPE_INDEX, 0, FORMAT_UINT3, 12, nt) as *mut [u32; 3];
                if vertices.is_null() || indices.is_null() {
                    (api.release_geometry)(geom);
                    return Err(accel.error(&format!("buffers of shape '{}'", shape.name)));
                }
                for (k, p) in mesh.positions.iter().enumerate() {
                    vertices.add(k).write(p.to_array());
                }
                for (k, t) in mesh.indices.iter().enumerate() {
                    indices.add(k).write(*t);
                }
                (api.commit_geometry)(geom);
                (api.attach_geometry_by_id)(scene, geom, si as u32);
                (api.release_geometry)(geom);
                accel.triangles += nt;
            }
            (api.commit_scene)(scene);
            // Reading the error clears it: format the message from this one reading.
            let code = (api.device_error)(device);
            if code != 0 {
                return Err(format!("Embree {}: rtcCommitScene failed (error code {code})", api.version));
            }
            if !accel._analytic.is_empty() {
                accel.analytic_bvh =
                    Some(Accel::build_where(shapes, |s| !matches!(s.geometry, ShapeGeometry::Mesh { .. }))?);
            }
            Ok(accel)
        }
    }

    /// Attaches shape `si` as a user geometry of one primitive.
    ///
    /// # Safety
    /// The scene is not committed yet.
    unsafe fn add_analytic(&mut self, si: usize, shape: Analytic) -> Result<(), String> {
        let api = self.api;
        // SAFETY: as in `build`; the boxed shape outlives the scene (dropped after it).
        unsafe {
            let geom = (api.new_geometry)(self.device, GEOMETRY_TYPE_USER);
            if geom.is_null() {
                return Err(self.error("rtcNewGeometry (user)"));
            }
            self._analytic.push(Box::new(shape));
            // The pointer is taken after the box has moved into place (moving a box asserts it
            // is the only pointer to its value); boxes keep their address as the vector grows.
            let user = &mut **self._analytic.last_mut().expect("just pushed") as *mut Analytic as *mut c_void;
            (api.set_geometry_user_primitive_count)(geom, 1);
            (api.set_geometry_user_data)(geom, user);
            (api.set_geometry_bounds_function)(geom, analytic_bounds, std::ptr::null_mut());
            (api.set_geometry_intersect_function)(geom, analytic_intersect);
            (api.set_geometry_occluded_function)(geom, analytic_occluded);
            (api.commit_geometry)(geom);
            (api.attach_geometry_by_id)(self.scene, geom, si as u32);
            (api.release_geometry)(geom);
        }
        Ok(())
    }

    fn error(&self, what: &str) -> String {
        // SAFETY: the device is live.
        let code = unsafe { (self.api.device_error)(self.device) };
        format!("Embree {}: {what} failed (error code {code})", self.api.version)
    }

    /// The closest hit of `ray` (on mesh shape `only` alone when given).
    #[inline]
    fn closest(&self, ray: &Ray, only: Option<u32>) -> Option<PreliminaryHit> {
        if !ray.queryable() {
            return None;
        }
        let mut rh = RtcRayHit {
            ray: rtc_ray(ray),
            hit: RtcHit {
                ng: [0.0; 3],
                u: 0.0,
                v: 0.0,
                prim_id: INVALID_ID,
                geom_id: INVALID_ID,
                inst_id: [INVALID_ID],
            },
        };
        let mut context = ShapeContext {
            context: IntersectContext::new(only.map(|_| keep_one_shape as FilterFn)),
            shape: only.unwrap_or(INVALID_ID),
        };
        // SAFETY: the scene is committed; the ray-hit and context live across the call. The
        // context is passed by a pointer to the whole `ShapeContext` (the filter reads past it).
        let context = &mut context as *mut ShapeContext as *mut IntersectContext;
        unsafe { (self.api.intersect1)(self.scene, context, &mut rh) };
        (rh.hit.geom_id != INVALID_ID).then(|| PreliminaryHit {
            t: rh.ray.tfar,
            shape: rh.hit.geom_id,
            index: rh.hit.prim_id,
            bary: Vec2::new(rh.hit.u, rh.hit.v),
        })
    }
}

#[inline]
fn rtc_ray(ray: &Ray) -> RtcRay {
    RtcRay {
        org: ray.o.to_array(),
        tnear: ray.tmin,
        dir: ray.d.to_array(),
        time: 0.0,
        // Embree's triangle test keeps t ≤ tfar; the renderer's intervals are open (t < tmax),
        // as the built-in BVH and the sphere and disk tests take them.
        tfar: ray.tmax.next_down(),
        mask: u32::MAX,
        id: 0,
        flags: 0,
    }
}

impl Intersector for EmbreeAccel {
    #[inline]
    fn intersect(&self, _shapes: &[Shape], ray: &Ray) -> Option<PreliminaryHit> {
        self.closest(ray, None)
    }

    fn intersect_shape(&self, shapes: &[Shape], ray: &Ray, shape: u32) -> Option<PreliminaryHit> {
        match shapes.get(shape as usize).map(|s| &s.geometry) {
            Some(ShapeGeometry::Mesh { .. }) => self.closest(ray, Some(shape)),
            Some(_) => self.analytic_bvh.as_ref()?.intersect_shape(shapes, ray, shape),
            None => None,
        }
    }

    #[inline]
    fn occluded(&self, _shapes: &[Shape], ray: &Ray) -> bool {
        if !ray.queryable() {
            return false;
        }
        let mut r = rtc_ray(ray);
        let mut context = IntersectContext::new(None);
        // SAFETY: as in `closest`.
        unsafe { (self.api.occluded1)(self.scene, &mut context, &mut r) };
        // Embree marks an occluded ray by setting its far end to −∞.
        r.tfar == f32::NEG_INFINITY
    }

    fn describe(&self) -> String {
        format!("Embree {} ({} triangles)", self.api.version, self.triangles)
    }
}
