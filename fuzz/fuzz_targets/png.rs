//! The PNG loader (`render::texture::Bitmap::load`) as the scene loader calls it: the input is
//! the image of two `bitmap` textures, one sRGB-decoded and one raw, rendered on a 4×4 film.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(init: tessera_fuzz::init(), |data: &[u8]| {
    tessera_fuzz::input_file("png", data);
    let body = r#"<shape type="rectangle"><bsdf type="diffuse">
            <texture type="bitmap" name="reflectance"><string name="filename" value="input.png"/></texture>
        </bsdf></shape>
        <shape type="cube"><bsdf type="roughconductor">
            <texture type="bitmap" name="alpha"><string name="filename" value="input.png"/>
                <boolean name="raw" value="true"/></texture>
        </bsdf></shape>"#;
    let scene = tessera_fuzz::load_scene(body);
    tessera_fuzz::note("scene", &scene);
    if let Ok(scene) = scene {
        tessera_fuzz::render_tiny(&scene);
    }
});
