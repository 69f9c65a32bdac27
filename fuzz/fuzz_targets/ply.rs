//! The PLY reader (`render::mesh::load_ply`) as the scene loader calls it: the input is the
//! mesh file of a `ply` shape, loaded, validated, put in the BVH and rendered on a 4×4 film.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(init: tessera_fuzz::init(), |data: &[u8]| {
    tessera_fuzz::input_file("ply", data);
    let body = r#"<shape type="ply"><string name="filename" value="input.ply"/>
        <bsdf type="diffuse"/></shape>"#;
    let scene = tessera_fuzz::load_scene(body);
    tessera_fuzz::note("scene", &scene);
    if let Ok(scene) = scene {
        tessera_fuzz::render_tiny(&scene);
    }
});
