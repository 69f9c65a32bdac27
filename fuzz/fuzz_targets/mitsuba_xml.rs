//! The Mitsuba XML reader and scene builder (`render::loader`), as `tessera render` calls them,
//! with the repository's MaterialX documents supplied in memory by the names its scenes use and
//! tiny meshes and textures under the names they use; a scene with a small film is rendered at
//! one sample per pixel.
#![no_main]

use libfuzzer_sys::fuzz_target;

const DOCUMENTS: &[(&str, &str)] = &[
    ("small_graph.mtlx", include_str!("../../scenes/small/small_graph.mtlx")),
    ("library.mtlx", include_str!("../../scenes/library/library.mtlx")),
    ("plane_ramp.mtlx", include_str!("../../scenes/plane_ramp.mtlx")),
    ("wood_floor.mtlx", include_str!("../../scenes/wood_floor.mtlx")),
    ("rusted_metal.mtlx", include_str!("../../scenes/rusted_metal.mtlx")),
    ("marble.mtlx", include_str!("../../scenes/marble.mtlx")),
    ("brick_moss.mtlx", include_str!("../../scenes/brick_moss.mtlx")),
    ("tiles_planks.mtlx", include_str!("../../scenes/tiles_planks.mtlx")),
    ("checker.mtlx", include_str!("../../crates/render/tests/data/checker.mtlx")),
    ("gltf_mask.mtlx", include_str!("../../crates/render/tests/data/gltf_mask.mtlx")),
    ("shading_models.mtlx", include_str!("../../crates/render/tests/data/shading_models.mtlx")),
    ("tilted_normal.mtlx", include_str!("../../crates/render/tests/data/tilted_normal.mtlx")),
];

fuzz_target!(init: tessera_fuzz::init(), |data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let dir = tessera_fuzz::scratch_dir();
    let scene = render::loader::load_str_with_files(text, &dir.join("scene.xml"), dir, &[], DOCUMENTS);
    tessera_fuzz::note("scene", &scene);
    if let Ok(scene) = scene {
        tessera_fuzz::render_tiny(&scene);
    }
});
