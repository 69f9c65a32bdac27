//! Scenes whose images are known in closed form: white furnaces (constant and image-based
//! environments) and a diffuse plane under point and directional lights.

use glam::{Vec2, Vec3};
use render::film::Image;
use render::integrator::{render, RenderSettings};
use render::scene::Scene;
use std::path::Path;

fn load(xml: &str) -> Scene {
    render::loader::load_str(xml, Path::new("analytic.xml"), &std::env::temp_dir(), &[])
        .unwrap_or_else(|e| panic!("{e}"))
}

fn furnace_scene(emitter: &str, bsdf: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
        <integrator type="path"/>
        <sensor type="perspective"><float name="fov" value="30"/>
            <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/><rfilter type="box"/></film>
        </sensor>
        <shape type="sphere">{bsdf}</shape>
        {emitter}
    </scene>"#
    )
}

/// Mean over pixels whose centre ray hits the unit sphere at the origin (seen from z = 5), and
/// the mean over the pixels that see only the background.
fn sphere_and_background(scene: &Scene, img: &Image) -> (f32, f32) {
    let (mut s, mut ns, mut b, mut nb) = (0.0, 0, 0.0, 0);
    for y in 0..img.height {
        for x in 0..img.width {
            // Classify by the pixel's four corners so edge pixels are left out.
            let corners = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)].map(|(dx, dy)| {
                let r = scene.camera.generate_ray(Vec2::new(x as f32 + dx, y as f32 + dy)).ray;
                let b = r.o.dot(r.d);
                b * b - (r.o.length_squared() - 1.0) > 0.0
            });
            let p = img.get(x, y);
            if corners.iter().all(|&h| h) {
                s += p.x + p.y + p.z;
                ns += 3;
            } else if corners.iter().all(|&h| !h) {
                b += p.x + p.y + p.z;
                nb += 3;
            }
        }
    }
    assert!(ns > 50 && nb > 50);
    (s / ns as f32, b / nb as f32)
}

#[test]
fn diffuse_sphere_in_a_constant_environment_reflects_its_albedo() {
    // A convex object's reflections all escape: L = ρ L_env exactly.
    let scene = load(&furnace_scene(
        r#"<emitter type="constant"><rgb name="radiance" value="1"/></emitter>"#,
        r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf>"#,
    ));
    let img = render(&scene, RenderSettings::new(64, 1), &|_| {}).image;
    let (sphere, background) = sphere_and_background(&scene, &img);
    assert!((background - 1.0).abs() < 1e-6, "{background}");
    assert!((sphere - 0.6).abs() < 0.006, "{sphere}");
}

#[test]
fn constant_image_environment_map_gives_the_same_furnace() {
    // An envmap whose image is 0.8 everywhere is a constant environment of 0.8; importance
    // sampling and MIS must not change the expectation.
    let path = std::env::temp_dir().join(format!("tessera-env-{}.exr", std::process::id()));
    let mut env = Image::new(16, 8);
    env.pixels.fill(Vec3::splat(0.8));
    env.save(&path).unwrap();
    let scene = load(&furnace_scene(
        &format!(r#"<emitter type="envmap"><string name="filename" value="{}"/></emitter>"#, path.display()),
        r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>"#,
    ));
    let img = render(&scene, RenderSettings::new(64, 2), &|_| {}).image;
    let (sphere, background) = sphere_and_background(&scene, &img);
    assert!((background - 0.8).abs() < 1e-4, "{background}");
    assert!((sphere - 0.4).abs() < 0.004, "{sphere}");
}

#[test]
fn mirror_sphere_without_fresnel_reflects_the_environment_exactly() {
    let scene = load(&furnace_scene(
        r#"<emitter type="constant"><rgb name="radiance" value="0.7"/></emitter>"#,
        r#"<bsdf type="conductor"/>"#,
    ));
    let img = render(&scene, RenderSettings::new(4, 3), &|_| {}).image;
    let (sphere, _) = sphere_and_background(&scene, &img);
    assert!((sphere - 0.7).abs() < 1e-4, "{sphere}");
}

fn plane_scene(emitter: &str) -> Scene {
    load(&format!(
        r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="2"/></integrator>
        <sensor type="perspective"><float name="fov" value="40"/>
            <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/><rfilter type="box"/></film>
        </sensor>
        <shape type="rectangle"><transform name="to_world"><scale value="10"/></transform>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf></shape>
        {emitter}
    </scene>"#
    ))
}

#[test]
fn point_light_on_a_diffuse_plane_follows_the_inverse_square_law() {
    let light = Vec3::new(0.7, -0.4, 1.5);
    let scene = plane_scene(&format!(
        r#"<emitter type="point"><point name="position" x="{}" y="{}" z="{}"/><rgb name="intensity" value="3"/></emitter>"#,
        light.x, light.y, light.z
    ));
    let img = render(&scene, RenderSettings::new(256, 4), &|_| {}).image;
    let mut worst = 0.0f32;
    for y in 0..img.height {
        for x in 0..img.width {
            // Analytic radiance averaged over the pixel (the box filter): an 8×8 grid inside it.
            let mut expected = 0.0;
            for i in 0..8 {
                for j in 0..8 {
                    let f = Vec2::new(x as f32 + (i as f32 + 0.5) / 8.0, y as f32 + (j as f32 + 0.5) / 8.0);
                    let r = scene.camera.generate_ray(f).ray;
                    let p = r.at(-r.o.z / r.d.z);
                    let to = light - p;
                    let cos = to.z / to.length();
                    expected += 0.5 / std::f32::consts::PI * 3.0 * cos / to.length_squared() / 64.0;
                }
            }
            let got = img.get(x, y).x;
            worst = worst.max(((got - expected) / expected).abs());
        }
    }
    assert!(worst < 0.01, "worst relative error {worst}");
}

#[test]
fn directional_light_gives_lambertian_radiance() {
    let d = Vec3::new(0.3, 0.2, -1.0).normalize();
    let scene = plane_scene(&format!(
        r#"<emitter type="directional"><vector name="direction" x="{}" y="{}" z="{}"/><rgb name="irradiance" value="2"/></emitter>"#,
        d.x, d.y, d.z
    ));
    let img = render(&scene, RenderSettings::new(4, 5), &|_| {}).image;
    let expected = 0.5 / std::f32::consts::PI * 2.0 * (-d.z);
    for p in &img.pixels {
        assert!((p.x - expected).abs() < 1e-4 * expected, "{} vs {expected}", p.x);
    }
}
