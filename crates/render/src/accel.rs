//! Which ray-query backend a scene's [`Intersector`] is: the built-in BVH ([`Accel`]), Embree
//! ([`crate::embree`]) or, for scenes of few primitives, a test of every one
//! ([`crate::exhaustive`]), chosen by `--accel` (auto by default).

use crate::embree::EmbreeAccel;
use crate::exhaustive::{small, ExhaustiveAccel};
use crate::geometry::{Accel, Intersector, PreliminaryHit, Ray, Shape};

/// Which ray-query backend scenes are built with ([`build_intersector`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Backend {
    /// Every primitive tested in small scenes ([`build_intersector`] says which), else Embree
    /// when its library loads, else the built-in BVH.
    #[default]
    Auto,
    /// The built-in BVH ([`Accel`]) always.
    Bvh,
    /// Embree ([`crate::embree`]); an error where it cannot be loaded.
    Embree,
    /// Every primitive tested ([`ExhaustiveAccel`]), whatever the scene's size.
    Exhaustive,
}

impl Backend {
    /// The name `--accel` takes.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Auto => "auto",
            Backend::Bvh => "bvh",
            Backend::Embree => "embree",
            Backend::Exhaustive => "exhaustive",
        }
    }
}

impl std::str::FromStr for Backend {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "auto" => Ok(Backend::Auto),
            "bvh" => Ok(Backend::Bvh),
            "embree" => Ok(Backend::Embree),
            "exhaustive" => Ok(Backend::Exhaustive),
            _ => Err(format!("unknown ray-query backend '{s}' (expected auto, bvh, embree or exhaustive)")),
        }
    }
}

/// The backend scenes loaded from now on are built with (0 auto, 1 bvh, 2 embree, 3 exhaustive); set once by
/// the command line's `--accel`, read by the loader.
static BACKEND: std::sync::atomic::AtomicU8 = std::sync::atomic::AtomicU8::new(0);

/// Sets the backend the loader builds scenes with.
pub fn set_backend(backend: Backend) {
    let code = match backend {
        Backend::Auto => 0,
        Backend::Bvh => 1,
        Backend::Embree => 2,
        Backend::Exhaustive => 3,
    };
    BACKEND.store(code, std::sync::atomic::Ordering::Relaxed);
}

/// The backend the loader builds scenes with ([`set_backend`]; `auto` by default).
pub fn backend() -> Backend {
    match BACKEND.load(std::sync::atomic::Ordering::Relaxed) {
        1 => Backend::Bvh,
        2 => Backend::Embree,
        3 => Backend::Exhaustive,
        _ => Backend::Auto,
    }
}

/// A scene's ray queries: one of the backends, called directly (not through a trait object),
/// so the backend's query wrapper inlines into the path loop and its hit is handed over in
/// registers rather than through memory (measured: a trait-object call's returned hit was
/// reloaded across the stores that wrote it, a store-forwarding stall at every bounce).
pub enum SceneAccel {
    /// The built-in BVH.
    Bvh(Accel),
    /// Embree.
    Embree(EmbreeAccel),
    /// Every primitive tested.
    Exhaustive(ExhaustiveAccel),
}

impl Intersector for SceneAccel {
    #[inline]
    fn intersect(&self, shapes: &[Shape], ray: &Ray) -> Option<PreliminaryHit> {
        match self {
            SceneAccel::Bvh(a) => a.intersect(shapes, ray),
            SceneAccel::Embree(a) => a.intersect(shapes, ray),
            SceneAccel::Exhaustive(a) => a.intersect(shapes, ray),
        }
    }

    #[inline]
    fn occluded(&self, shapes: &[Shape], ray: &Ray) -> bool {
        match self {
            SceneAccel::Bvh(a) => a.occluded(shapes, ray),
            SceneAccel::Embree(a) => a.occluded(shapes, ray),
            SceneAccel::Exhaustive(a) => a.occluded(shapes, ray),
        }
    }

    fn intersect_shape(&self, shapes: &[Shape], ray: &Ray, shape: u32) -> Option<PreliminaryHit> {
        match self {
            SceneAccel::Bvh(a) => a.intersect_shape(shapes, ray, shape),
            SceneAccel::Embree(a) => a.intersect_shape(shapes, ray, shape),
            SceneAccel::Exhaustive(a) => a.intersect_shape(shapes, ray, shape),
        }
    }

    fn describe(&self) -> String {
        match self {
            SceneAccel::Bvh(a) => a.describe(),
            SceneAccel::Embree(a) => a.describe(),
            SceneAccel::Exhaustive(a) => a.describe(),
        }
    }
}

/// The ray queries over `shapes` by `backend`. With [`Backend::Auto`]: a test of every
/// primitive for scenes of at most [`crate::exhaustive::SMALL_SCENE_TRIANGLES`] triangles and [`crate::exhaustive::SMALL_SCENE`]
/// primitives (faster there than either hierarchy, in renders), else Embree where its library loads (the faster
/// hierarchy on every scene measured: triangles alone, spheres alone, both), else the built-in
/// BVH (also when Embree fails, with a warning on stderr); an error when [`Backend::Embree`] is
/// asked for and cannot be had, or when the built-in BVH cannot hold the scene.
pub fn build_intersector(shapes: &[Shape], backend: Backend) -> std::result::Result<SceneAccel, String> {
    match backend {
        Backend::Bvh => Ok(SceneAccel::Bvh(Accel::build(shapes)?)),
        Backend::Embree => EmbreeAccel::build(shapes)
            .map(SceneAccel::Embree)
            .map_err(|e| format!("--accel embree: {e} (scripts/install-embree.sh installs it)")),
        Backend::Exhaustive => Ok(SceneAccel::Exhaustive(ExhaustiveAccel::build(shapes))),
        Backend::Auto if small(shapes) => Ok(SceneAccel::Exhaustive(ExhaustiveAccel::build(shapes))),
        Backend::Auto if crate::embree::available().is_ok() => match EmbreeAccel::build(shapes) {
            Ok(a) => Ok(SceneAccel::Embree(a)),
            Err(e) => {
                eprintln!("warning: {e}; tracing rays with the built-in BVH instead");
                Ok(SceneAccel::Bvh(Accel::build(shapes)?))
            }
        },
        Backend::Auto => Ok(SceneAccel::Bvh(Accel::build(shapes)?)),
    }
}
