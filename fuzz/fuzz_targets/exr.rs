//! The EXR loader (`render::texture::Bitmap::load`) as the scene loader calls it: the input is
//! the image of an `envmap` emitter and of a `bitmap` texture, rendered on a 4×4 film.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(init: tessera_fuzz::init(), |data: &[u8]| {
    tessera_fuzz::input_file("exr", data);
    let body = r#"<emitter type="envmap"><string name="filename" value="input.exr"/></emitter>
        <shape type="rectangle"><bsdf type="diffuse">
            <texture type="bitmap" name="reflectance"><string name="filename" value="input.exr"/></texture>
        </bsdf></shape>"#;
    let scene = tessera_fuzz::load_scene(body);
    tessera_fuzz::note("scene", &scene);
    if let Ok(scene) = scene {
        tessera_fuzz::render_tiny(&scene);
    }
});
