//! Partial opacity (Mitsuba's `mask`, MaterialX's `opacity`, glTF's `alpha`) against closed
//! forms: a mix of surface and background, shadows halved by a half-opaque occluder (point,
//! directional and area lights, the last with MIS on both strategies), opacity 1 and 0 against
//! the scene with the bare surface and without it, footprints that do not see a surface the path
//! passed through, glTF MASK cut-outs filtered over the camera footprint, `open_pbr_surface` and
//! `gltf_pbr` documents rendering as their `standard_surface` equivalent, and determinism
//! across thread counts.

use glam::{Vec2, Vec3};
use render::film::Image;
use render::geometry::SurfaceInteraction;
use render::integrator::{radiance, render, FilterScale, PathObserver, RenderCounts, RenderSettings, MAX_PASS_THROUGH};
use render::scene::Scene;
use render::shading::{Direct, TextureEvaluator};
use std::path::{Path, PathBuf};

fn data() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

fn load(xml: &str) -> Scene {
    render::loader::load_str(xml, Path::new("opacity.xml"), &data(), &[]).unwrap_or_else(|e| panic!("{e}"))
}

/// Loads a scene with MaterialX documents given in memory, by the names the scene uses.
fn load_with(xml: &str, files: &[(&str, &str)]) -> Scene {
    render::loader::load_str_with_files(xml, Path::new("opacity.xml"), &data(), &[], files)
        .unwrap_or_else(|e| panic!("{e}"))
}

fn load_err(xml: &str) -> String {
    match render::loader::load_str(xml, Path::new("opacity.xml"), &data(), &[]) {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

fn run(scene: &Scene, spp: u32, seed: u64) -> Image {
    render(scene, RenderSettings::new(spp, seed), &|_| {}).image
}

/// A camera at z = 5 looking at the origin, a box pixel filter.
fn front_camera(width: u32, height: u32) -> String {
    format!(
        r#"<sensor type="perspective"><float name="fov" value="30"/>
            <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="{width}"/><integer name="height" value="{height}"/><rfilter type="box"/></film>
        </sensor>"#
    )
}

/// Per channel: the mean over all pixels and its standard error. All pixels must be independent
/// estimates of one expectation (each pixel draws its own random streams).
fn mean_and_standard_error(img: &Image) -> (Vec3, Vec3) {
    let n = img.pixels.len() as f32;
    let mean = img.pixels.iter().copied().sum::<Vec3>() / n;
    let var = img.pixels.iter().map(|p| (*p - mean) * (*p - mean)).sum::<Vec3>() / (n - 1.0);
    (mean, (var / n).powf(0.5))
}

/// A quad filling the view in a constant environment of radiance 1, its front Lambertian of
/// albedo ρ: the lit surface has radiance exactly ρ (it sees only the environment), what is
/// behind it has radiance 1, so an opacity `o` gives `o ρ + (1 − o)` per channel.
fn quad_in_environment(bsdf: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
        {}
        <shape type="rectangle"><transform name="to_world"><scale value="2"/></transform>{bsdf}</shape>
        <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
    </scene>"#,
        front_camera(16, 16)
    )
}

fn assert_closed_form(img: &Image, expected: Vec3, what: &str) {
    // Every pixel sees the quad only, so the pixels are independent, identically distributed
    // estimates of the closed form; their spread estimates the estimator's variance. The mean of
    // N = 256 pixels is within 5 standard errors of the expectation except with probability
    // below 1e-6 (central limit theorem; each pixel already averages 256 samples). The seed is
    // fixed, so the outcome is deterministic. The standard error is also checked to be small, so
    // the test has the power to see a wrong weight (a 0.3 vs 0.5 opacity moves the mean by 0.1).
    let (mean, se) = mean_and_standard_error(img);
    for c in 0..3 {
        assert!(se[c] < 0.01, "{what}: standard error {se} too large for a meaningful test");
        assert!(
            (mean[c] - expected[c]).abs() < 5.0 * se[c] + 1e-6,
            "{what}: channel {c}: {mean} vs {expected} (±{se})"
        );
    }
}

#[test]
fn constant_opacity_mixes_surface_and_background_in_closed_form() {
    // Mitsuba's mask (a scalar opacity) around a diffuse BSDF.
    let rho = Vec3::new(0.2, 0.5, 0.8);
    let scene = load(&quad_in_environment(
        r#"<bsdf type="mask"><float name="opacity" value="0.3"/>
             <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.5, 0.8"/></bsdf></bsdf>"#,
    ));
    assert!(scene.masked);
    let img = run(&scene, 256, 11);
    assert_closed_form(&img, 0.3 * rho + Vec3::splat(0.7), "mask 0.3");

    // MaterialX's colour opacity: a different opacity per channel (the path weights o/p and
    // (1 − o)/(1 − p) are per channel, p the mean). With `specular` 0 the BSDF is Lambertian.
    let doc = r#"<?xml version="1.0"?>
<materialx version="1.39">
  <standard_surface name="SR" type="surfaceshader">
    <input name="base" type="float" value="1"/>
    <input name="base_color" type="color3" value="0.2, 0.5, 0.8"/>
    <input name="specular" type="float" value="0"/>
    <input name="opacity" type="color3" value="0.1, 0.5, 0.9"/>
  </standard_surface>
</materialx>"#;
    let scene = load_with(
        &quad_in_environment(
            r#"<bsdf type="mtlx"><string name="filename" value="op.mtlx"/><string name="material" value="SR"/></bsdf>"#,
        ),
        &[("op.mtlx", doc)],
    );
    let o = Vec3::new(0.1, 0.5, 0.9);
    let img = run(&scene, 256, 12);
    assert_closed_form(&img, o * rho + (Vec3::ONE - o), "standard_surface opacity (0.1, 0.5, 0.9)");
}

/// A diffuse floor (albedo 0.5) at z = 0 seen obliquely from below a half-opaque, black
/// occluder at z = 1.5 (outside the camera's view), direct lighting only.
fn shadow_scene(occluder: bool, emitter: &str) -> Scene {
    let occluder = if occluder {
        r#"<shape type="rectangle"><transform name="to_world"><scale value="4"/><translate z="1.5"/></transform>
             <bsdf type="mask"><float name="opacity" value="0.5"/>
               <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf></bsdf></shape>"#
    } else {
        ""
    };
    load(&format!(
        r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="2"/></integrator>
        <sensor type="perspective"><float name="fov" value="20"/>
            <transform name="to_world"><lookat origin="0, -3, 1" target="0, 0, 0" up="0, 0, 1"/></transform>
            <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/><rfilter type="box"/></film>
        </sensor>
        <shape type="rectangle"><transform name="to_world"><scale value="10"/></transform>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf></shape>
        {occluder}
        {emitter}
    </scene>"#
    ))
}

/// The floor point a film position sees.
fn floor_point(scene: &Scene, film: Vec2) -> Vec3 {
    let r = scene.camera.generate_ray(film).ray;
    r.at(-r.o.z / r.d.z)
}

#[test]
fn half_opaque_occluder_halves_point_and_directional_light() {
    let light = Vec3::new(0.3, 0.2, 3.0);
    let point = format!(
        r#"<emitter type="point"><point name="position" x="{}" y="{}" z="{}"/><rgb name="intensity" value="4"/></emitter>"#,
        light.x, light.y, light.z
    );
    let scene = shadow_scene(true, &point);
    let spp = 256;
    let img = run(&scene, spp, 21);
    let mut worst = 0.0f64;
    for y in 0..img.height {
        for x in 0..img.width {
            // L(f) = ρ/π · I cos θ / r² · (1 − 0.5) at film position f. The shadow ray is
            // attenuated deterministically, so a pixel is the mean of L at `spp` uniform positions
            // in it (the box filter): its expectation is the pixel average of L and its standard
            // error √(var_pixel(L)/spp). Both from a 16×16 midpoint grid over the pixel (the
            // quadrature error of a smooth L is far below the 0.2 % slack added).
            let n = 16;
            let values: Vec<f64> = (0..n * n)
                .map(|k| {
                    let f = Vec2::new(
                        x as f32 + ((k % n) as f32 + 0.5) / n as f32,
                        y as f32 + ((k / n) as f32 + 0.5) / n as f32,
                    );
                    let p = floor_point(&scene, f);
                    let to = light - p;
                    let cos = (to.z / to.length()) as f64;
                    0.5 / std::f64::consts::PI * 4.0 * cos / to.length_squared() as f64 * 0.5
                })
                .collect();
            let expected = values.iter().sum::<f64>() / values.len() as f64;
            let var = values.iter().map(|v| (v - expected).powi(2)).sum::<f64>() / values.len() as f64;
            let tolerance = 5.0 * (var / spp as f64).sqrt() + 2e-3 * expected;
            let got = img.get(x, y);
            assert!(got.x == got.y && got.y == got.z);
            let err = (got.x as f64 - expected).abs();
            assert!(err < tolerance, "pixel ({x}, {y}): {} vs {expected} ± {tolerance}", got.x);
            worst = worst.max(err / tolerance);
        }
    }
    eprintln!("point light: worst error {worst:.2} of the tolerance");

    // A directional light: E cos θ ρ/π · ½, the same everywhere on the floor, without noise.
    let d = Vec3::new(0.3, 0.2, -1.0).normalize();
    let scene = shadow_scene(
        true,
        &format!(
            r#"<emitter type="directional"><vector name="direction" x="{}" y="{}" z="{}"/><rgb name="irradiance" value="2"/></emitter>"#,
            d.x, d.y, d.z
        ),
    );
    let img = run(&scene, 4, 22);
    let expected = 0.5 / std::f32::consts::PI * 2.0 * (-d.z) * 0.5;
    for p in &img.pixels {
        assert!((p.x - expected).abs() < 1e-4 * expected, "directional: {} vs {expected}", p.x);
    }
}

#[test]
fn area_light_through_a_half_opaque_occluder_gives_half_the_light_with_mis() {
    // A large area light above the occluder: the floor's direct light comes from both next-event
    // estimation (shadow rays attenuated by ½) and BSDF samples that pass through the occluder
    // (probability ½, weight 1) before hitting the light, combined by MIS. The occluder is
    // black, so with direct lighting only the image must be exactly half the unoccluded one in
    // expectation, whatever the MIS weights — unless the two strategies disagree on the
    // occluder's effect.
    let light = r#"<shape type="rectangle"><transform name="to_world"><scale value="1.5"/><rotate x="1" angle="180"/><translate z="3"/></transform>
        <emitter type="area"><rgb name="radiance" value="5"/></emitter></shape>"#;
    let with = shadow_scene(true, light);
    let without = shadow_scene(false, light);
    let mean = |img: &Image| img.pixels.iter().map(|p| p.x).sum::<f32>() as f64 / img.pixels.len() as f64;
    // The variance of each image's mean: its pixels are independent but not identically
    // distributed, so estimate Σ var(pixel) from two renders with different seeds,
    // E[(a − b)²] = 2 var.
    let var_of_mean = |a: &Image, b: &Image| {
        let n = a.pixels.len() as f64;
        a.pixels.iter().zip(&b.pixels).map(|(x, y)| ((x.x - y.x) as f64).powi(2) / 2.0).sum::<f64>() / (n * n)
    };
    let (w1, w2) = (run(&with, 64, 31), run(&with, 64, 32));
    let (o1, o2) = (run(&without, 64, 33), run(&without, 64, 34));
    let got = (mean(&w1) + mean(&w2)) / 2.0;
    let unoccluded = (mean(&o1) + mean(&o2)) / 2.0;
    // Variance of the difference got − ½ unoccluded (averages of two renders each).
    let var = var_of_mean(&w1, &w2) / 2.0 + 0.25 * var_of_mean(&o1, &o2) / 2.0;
    let diff = got - 0.5 * unoccluded;
    assert!(unoccluded > 0.05, "{unoccluded}");
    assert!(diff.abs() < 5.0 * var.sqrt(), "{got} vs ½ × {unoccluded} (σ {})", var.sqrt());
    assert!(var.sqrt() < 0.01 * unoccluded, "too noisy to test: σ {} for {unoccluded}", var.sqrt());
}

/// A small scene: floor, glossy sphere, area light, and whatever `extra` adds (declared last,
/// inside the scene's bounds, so that it changes neither the other shapes' indices nor the
/// bounds).
fn room(extra: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
        <sensor type="perspective"><float name="fov" value="40"/>
            <transform name="to_world"><lookat origin="0, -4, 2" target="0, 0, 0.5" up="0, 0, 1"/></transform>
            <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="20"/><rfilter type="gaussian"/></film>
        </sensor>
        <shape type="rectangle"><transform name="to_world"><scale value="4"/></transform>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.5, 0.4"/></bsdf></shape>
        <shape type="sphere"><point name="center" x="0.3" y="0.2" z="0.6"/><float name="radius" value="0.6"/>
            <bsdf type="roughconductor"><string name="material" value="Cu"/><float name="alpha" value="0.2"/></bsdf></shape>
        <shape type="rectangle"><transform name="to_world"><scale value="0.6"/><rotate x="1" angle="180"/><translate z="3"/></transform>
            <emitter type="area"><rgb name="radiance" value="8"/></emitter></shape>
        {extra}
    </scene>"#
    )
}

/// A quad between the camera and the sphere (the camera looks through it) with `bsdf`.
fn veil(bsdf: &str) -> String {
    format!(
        r#"<shape type="rectangle"><transform name="to_world"><scale value="1.2"/><rotate x="1" angle="80"/><translate y="-1.5" z="0.8"/></transform>{bsdf}</shape>"#
    )
}

const CONSTANTS_DOC: &str = r#"<?xml version="1.0"?>
<materialx version="1.39">
  <nodegraph name="NG">
    <constant name="c_one" type="color3"><input name="value" type="color3" value="1, 1, 1"/></constant>
    <constant name="c_zero" type="float"><input name="value" type="float" value="0"/></constant>
    <output name="one" type="color3" nodename="c_one"/>
    <output name="zero" type="float" nodename="c_zero"/>
  </nodegraph>
  <standard_surface name="SR_plain" type="surfaceshader">
    <input name="base_color" type="color3" value="0.7, 0.5, 0.3"/>
    <input name="specular_roughness" type="float" value="0.4"/>
  </standard_surface>
  <standard_surface name="SR_opaque" type="surfaceshader">
    <input name="base_color" type="color3" value="0.7, 0.5, 0.3"/>
    <input name="specular_roughness" type="float" value="0.4"/>
    <input name="opacity" type="color3" value="1, 1, 1"/>
  </standard_surface>
  <standard_surface name="SR_graph_opaque" type="surfaceshader">
    <input name="base_color" type="color3" value="0.7, 0.5, 0.3"/>
    <input name="specular_roughness" type="float" value="0.4"/>
    <input name="opacity" type="color3" nodegraph="NG" output="one"/>
  </standard_surface>
  <gltf_pbr name="SR_gltf_clear" type="surfaceshader">
    <input name="base_color" type="color3" value="0.7, 0.5, 0.3"/>
    <input name="alpha" type="float" value="0"/>
    <input name="alpha_mode" type="integer" value="2"/>
  </gltf_pbr>
</materialx>"#;

fn mtlx(material: &str) -> String {
    format!(
        r#"<bsdf type="mtlx"><string name="filename" value="c.mtlx"/><string name="material" value="{material}"/></bsdf>"#
    )
}

#[test]
fn opacity_one_renders_exactly_the_opaque_surface() {
    let files = [("c.mtlx", CONSTANTS_DOC)];
    let render_veil = |bsdf: &str| run(&load_with(&room(&veil(bsdf)), &files), 4, 41);
    // MaterialX: no opacity, a constant 1, and a graph output that is 1 everywhere (the last
    // goes through the integrator's opacity path: a mask whose p = 1 draws no random number and
    // weighs nothing, and shadow rays gather transmittance instead of testing occlusion).
    let plain = render_veil(&mtlx("SR_plain"));
    let graph_scene = load_with(&room(&veil(&mtlx("SR_graph_opaque"))), &files);
    assert!(graph_scene.masked);
    assert!(render_veil(&mtlx("SR_opaque")) == plain, "opacity (1, 1, 1) changed the image");
    assert!(run(&graph_scene, 4, 41) == plain, "an opacity graph of 1 changed the image");
    // Mitsuba: a mask of constant 1, and one whose MaterialX texture is 1 everywhere.
    let diffuse = r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.6, 0.2"/></bsdf>"#;
    let bare = render_veil(diffuse);
    let mask_one = format!(r#"<bsdf type="mask"><float name="opacity" value="1"/>{diffuse}</bsdf>"#);
    let mask_graph = format!(
        r#"<bsdf type="mask"><texture type="mtlx" name="opacity"><string name="filename" value="c.mtlx"/>
             <string name="output" value="NG/one"/></texture>{diffuse}</bsdf>"#
    );
    assert!(render_veil(&mask_one) == bare, "mask opacity 1 changed the image");
    assert!(render_veil(&mask_graph) == bare, "mask with a texture of 1 changed the image");
    assert!(bare != plain);
}

#[test]
fn opacity_zero_renders_exactly_the_scene_without_the_surface() {
    // A surface of opacity 0 is always passed through, without a random number; the ray keeps
    // its origin and direction (only its start moves past the hit), so what lies behind is hit
    // at bit-identical distances, and shadow rays cross it with transmittance exactly 1. The
    // image is therefore bit-identical to the scene without it.
    let files = [("c.mtlx", CONSTANTS_DOC)];
    let without = render(&load(&room("")), RenderSettings::new(16, 51), &|_| {});
    let diffuse = r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.9"/></bsdf>"#;
    for bsdf in [
        format!(r#"<bsdf type="mask"><float name="opacity" value="0"/>{diffuse}</bsdf>"#),
        format!(
            r#"<bsdf type="mask"><texture type="mtlx" name="opacity"><string name="filename" value="c.mtlx"/>
                 <string name="output" value="NG/zero"/></texture>{diffuse}</bsdf>"#
        ),
        mtlx("SR_gltf_clear"),
    ] {
        let scene = load_with(&room(&veil(&bsdf)), &files);
        assert!(scene.masked);
        let with = render(&scene, RenderSettings::new(16, 51), &|_| {});
        assert!(with.image == without.image, "{bsdf}: an invisible surface changed the image");
        // It was there: rays crossed it, one more closest-hit query each time.
        assert!(with.counts.rays > without.counts.rays, "{:?} vs {:?}", with.counts, without.counts);
        assert_eq!(with.counts.shadow_rays, without.counts.shadow_rays);
    }
}

/// Records each scattering vertex's depth, position and footprint.
#[derive(Default)]
struct Footprints(Vec<(u32, Vec3, [f64; 4])>);

impl PathObserver for Footprints {
    const WANTS_FOOTPRINTS: bool = true;
    fn hit(&mut self, depth: u32, si: &SurfaceInteraction, _: Option<&footprint::Vertex>, var: glam::DMat2) {
        self.0.push((depth, si.p, var.to_cols_array()));
    }
}

fn trace(scene: &Scene, x: u32, y: u32, sample: u32) -> Footprints {
    let (cam, mut rng) = render::integrator::camera_sample(scene, 7, x, y, sample);
    let mut shade = TextureEvaluator::new(&scene.graphs, &scene.materials, Direct);
    let mut obs = Footprints::default();
    radiance(scene, RenderSettings::new(1, 7), &cam, &mut rng, &mut RenderCounts::default(), &mut shade, &mut obs);
    obs
}

#[test]
fn passing_through_leaves_the_path_footprint_as_if_the_surface_were_absent() {
    let without = load(&room(""));
    let clear =
        load(&room(&veil(r#"<bsdf type="mask"><float name="opacity" value="0"/><bsdf type="diffuse"/></bsdf>"#)));
    let half =
        load(&room(&veil(r#"<bsdf type="mask"><float name="opacity" value="0.5"/><bsdf type="diffuse"/></bsdf>"#)));
    let (mut compared, mut through) = (0, 0);
    for y in (0..20).step_by(3) {
        for x in (0..24).step_by(3) {
            for s in 0..8 {
                let reference = trace(&without, x, y, s);
                // Opacity 0: every vertex of every path, footprints included, is unchanged.
                let c = trace(&clear, x, y, s);
                assert_eq!(c.0, reference.0, "pixel ({x}, {y}) sample {s}");
                compared += reference.0.len();
                // Opacity ½: where the camera ray passed through, the first scattering vertex
                // (reached before any random number is drawn there) has the unveiled footprint.
                let h = trace(&half, x, y, s);
                if let (Some(first), Some(r)) = (h.0.first(), reference.0.first()) {
                    if first.1 == r.1 {
                        assert_eq!(first, r, "pixel ({x}, {y}) sample {s}");
                        through += 1;
                    }
                }
            }
        }
    }
    assert!(compared > 300 && through > 40, "{compared} vertices, {through} pass-throughs");
}

/// Standard normal CDF (Abramowitz–Stegun 7.1.26 erf, |error| < 1.5e-7).
fn phi(z: f64) -> f64 {
    let x = z.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.3275911 * x);
    let poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
    let erf = 1.0 - poly * (-x * x).exp();
    0.5 * (1.0 + erf.copysign(z))
}

#[test]
fn gltf_mask_cuts_out_where_alpha_is_below_the_cutoff_filtered_by_the_camera_footprint() {
    // A black glTF quad (scale 2: u = x/4 + ½) cut by MASK with alpha = 2u mod 1: opaque for
    // u ∈ [¼, ½) ∪ [¾, 1), in front of a constant environment of 1. Pixels show 1 − opacity.
    let (w, h) = (48u32, 16u32);
    let xml = format!(
        r#"<scene version="3.0.0">
        {}
        <shape type="rectangle"><transform name="to_world"><scale value="2"/></transform>
            <bsdf type="mtlx"><string name="filename" value="gltf_mask.mtlx"/><string name="material" value="M_mask"/></bsdf></shape>
        <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
    </scene>"#,
        front_camera(w, h)
    );
    let scene = load(&xml);
    assert!(scene.masked && scene.footprints_needed);
    let u_at = |film: Vec2| {
        let r = scene.camera.generate_ray(film).ray;
        r.at(-r.o.z / r.d.z).x / 4.0 + 0.5
    };
    // The camera sees the plane z = 0 head-on, so film → plane is affine: one pixel is `du` in u,
    // and the first hit's footprint (a Gaussian of ½ pixel per axis, projected) has σ_u = du/2.
    let du = (u_at(Vec2::new(w as f32 / 2.0 + 1.0, 8.0)) - u_at(Vec2::new(w as f32 / 2.0, 8.0))) as f64;
    assert!(du > 0.0);

    // Point-sampled footprint (filter scale 0): a hard cutout. Pixels whose box lies wholly on
    // one side of an edge are exactly 0 (opaque black) or 1 (background): no random number is
    // drawn where the opacity is 0 or 1.
    let settings = RenderSettings { filter_scale: FilterScale::Fixed(0.0), ..RenderSettings::new(4, 61) };
    let img = render(&scene, settings, &|_| {}).image;
    let (mut opaque, mut clear) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let (u0, u1) = (u_at(Vec2::new(x as f32, 8.0)) as f64, u_at(Vec2::new(x as f32 + 1.0, 8.0)) as f64);
            let inside = |u: f64| (0.25..0.5).contains(&u) || (0.75..1.0).contains(&u);
            let edges = [0.25, 0.5, 0.75];
            if edges.iter().any(|e| (u0.min(u1) - 1e-4..=u0.max(u1) + 1e-4).contains(e)) {
                continue;
            }
            let p = img.get(x, y).x;
            if inside(0.5 * (u0 + u1)) {
                assert_eq!(p, 0.0, "pixel ({x}, {y}) at u ≈ {u0:.3} should be opaque");
                opaque += 1;
            } else {
                assert_eq!(p, 1.0, "pixel ({x}, {y}) at u ≈ {u0:.3} should be cut out");
                clear += 1;
            }
        }
    }
    assert!(opaque > 100 && clear > 100, "{opaque} opaque, {clear} clear pixels");

    // Filtered (scale s): the opacity at a hit is the probability that alpha = 2u reaches ½ over
    // the footprint, Φ((u − ¼)/(s σ_u)) near the edge at u = ¼; a pixel shows the box-filter
    // average of 1 − Φ. Averaged over the h rows of each column near that edge and checked
    // against this closed form. Each sample is 0 or 1 (pass through or hit the black surface),
    // so a column mean of N = spp·h samples has a standard error of at most ½/√N; the
    // tolerance is 5 of them. A point-sampled opacity would be off by up to 0.3 here.
    let (scale, spp) = (4.0f64, 256u32);
    let settings = RenderSettings { filter_scale: FilterScale::Fixed(scale as f32), ..RenderSettings::new(spp, 62) };
    let img = render(&scene, settings, &|_| {}).image;
    let sigma = scale * du / 2.0;
    let tolerance = 5.0 * 0.5 / ((spp * h) as f64).sqrt();
    let mut checked = 0;
    for x in 0..w {
        let u0 = u_at(Vec2::new(x as f32, 8.0)) as f64;
        if (u0 - 0.25).abs() > 5.0 * du {
            continue;
        }
        let expected =
            (0..256).map(|k| 1.0 - phi((u0 + (k as f64 + 0.5) / 256.0 * du - 0.25) / sigma)).sum::<f64>() / 256.0;
        let got = (0..h).map(|y| img.get(x, y).x as f64).sum::<f64>() / h as f64;
        assert!(
            (got - expected).abs() < tolerance,
            "column {x} (u ≈ {u0:.4}): {got:.4} vs {expected:.4} ± {tolerance:.4}"
        );
        checked += 1;
    }
    assert!(checked >= 8, "{checked} columns");
}

fn models_scene(material: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
        <sensor type="perspective"><float name="fov" value="35"/>
            <transform name="to_world"><lookat origin="0, -4, 2.5" target="0, 0, 0.4" up="0, 0, 1"/></transform>
            <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="20"/></film>
        </sensor>
        <shape type="rectangle"><transform name="to_world"><scale value="4"/></transform>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf></shape>
        <shape type="sphere"><point name="center" x="0" y="0" z="0.8"/><float name="radius" value="0.8"/>
            <bsdf type="mtlx"><string name="filename" value="shading_models.mtlx"/><string name="material" value="{material}"/></bsdf></shape>
        <shape type="rectangle"><transform name="to_world"><scale value="0.8"/><rotate x="1" angle="180"/><translate x="1" z="3"/></transform>
            <emitter type="area"><rgb name="radiance" value="6"/></emitter></shape>
        <emitter type="constant"><rgb name="radiance" value="0.2"/></emitter>
    </scene>"#
    )
}

#[test]
fn open_pbr_and_gltf_documents_render_as_their_standard_surface_equivalent() {
    // The three materials of shading_models.mtlx map onto the same standard_surface inputs
    // (graph-driven colour, roughness and normal; constant metalness, specular, IOR,
    // transmission and a 0.6 opacity): the images are bit-identical.
    let std = load(&models_scene("M_std"));
    assert!(std.masked);
    let reference = run(&std, 4, 71);
    assert!(reference.pixels.iter().all(|p| p.is_finite()));
    for m in ["M_openpbr", "M_gltf"] {
        assert!(run(&load(&models_scene(m)), 4, 71) == reference, "{m} differs from M_std");
    }
    // A model whose unsupported inputs are set still loads (with one warning) and renders.
    let coated = run(&load(&models_scene("M_coated")), 2, 72);
    assert!(coated.pixels.iter().all(|p| p.is_finite()) && coated != reference);
    let doc = graph::Document::load(data().join("shading_models.mtlx")).unwrap();
    let warnings = doc.material("M_coated").unwrap().warnings;
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(warnings[0].contains("`coat_weight`") && warnings[0].contains("`fuzz_weight`"), "{}", warnings[0]);
    for m in ["M_std", "M_openpbr", "M_gltf"] {
        assert!(doc.material(m).unwrap().warnings.is_empty(), "{m}");
    }
}

#[test]
fn opacity_images_do_not_depend_on_the_thread_count() {
    // Graph-driven opacities (a glTF MASK, a Mitsuba mask with a MaterialX texture, a
    // checkerboard mask) in front of each other, so pass-throughs, random choices and
    // shadow-ray transmittance all occur.
    let stripes = r#"<bsdf type="mask"><texture type="mtlx" name="opacity"><string name="filename" value="gltf_mask.mtlx"/>
             <string name="output" value="NG_stripes/alpha"/></texture>
             <bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.3, 0.3"/></bsdf></bsdf>"#;
    let checker = r#"<bsdf type="twosided"><bsdf type="mask"><texture type="checkerboard" name="opacity">
             <rgb name="color0" value="0.9"/><rgb name="color1" value="0.2"/></texture>
             <bsdf type="diffuse"/></bsdf></bsdf>"#;
    let extra = format!(
        r#"{}
        <shape type="rectangle"><transform name="to_world"><scale value="1"/><rotate x="1" angle="70"/><translate y="-1" z="0.6"/></transform>{stripes}</shape>
        <shape type="disk"><transform name="to_world"><scale value="0.7"/><translate x="-0.6" z="1.6"/></transform>{checker}</shape>"#,
        veil(
            r#"<bsdf type="mtlx"><string name="filename" value="gltf_mask.mtlx"/><string name="material" value="M_mask"/></bsdf>"#
        )
    );
    let scene = load(&room(&extra));
    let with_threads = |n: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
        pool.install(|| run(&scene, 4, 81))
    };
    let one = with_threads(1);
    assert!(one.pixels.iter().all(|p| p.is_finite()));
    assert!(with_threads(2) == one, "2 threads differ from 1");
    assert!(with_threads(3) == one, "3 threads differ from 1");
}

#[test]
fn mask_needs_one_nested_bsdf() {
    let scene = |bsdf: &str| quad_in_environment(bsdf);
    let e = load_err(&scene(r#"<bsdf type="mask"><float name="opacity" value="0.5"/></bsdf>"#));
    assert!(e.contains("mask needs one nested <bsdf>"), "{e}");
    let e = load_err(&scene(r#"<bsdf type="mask"><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>"#));
    assert!(e.contains("mask takes one nested <bsdf>"), "{e}");
    let e = load_err(&scene(r#"<bsdf type="mask"><float name="opacitty" value="0.5"/><bsdf type="diffuse"/></bsdf>"#));
    assert!(e.contains("opacitty"), "{e}");
    let e = load_err(&scene(r#"<bsdf type="nope"/>"#));
    assert!(e.contains("mask"), "{e}");
    // Mitsuba's default opacity is ½.
    let s = load(&scene(r#"<bsdf type="mask"><bsdf type="diffuse"/></bsdf>"#));
    assert!(s.masked);
}

#[test]
fn rays_pass_through_at_most_max_pass_through_surfaces_in_a_row() {
    // Stacks of fully transparent (opacity 0) quads: a camera ray crosses MAX_PASS_THROUGH of
    // them and sees the environment; one more ends the path (the documented cap). The same for
    // a shadow ray from the floor to a directional light.
    let n = MAX_PASS_THROUGH as usize;
    let layers = |count: usize, z0: f32, z1: f32, scale: f32| {
        (0..count)
            .map(|k| {
                let z = z0 + (z1 - z0) * k as f32 / count as f32;
                format!(
                    r#"<shape type="rectangle"><transform name="to_world"><scale value="{scale}"/><translate z="{z}"/></transform>
                         <bsdf type="mask"><float name="opacity" value="0"/><bsdf type="diffuse"/></bsdf></shape>"#
                )
            })
            .collect::<String>()
    };
    let camera_stack = |count: usize| {
        load(&format!(
            r#"<scene version="3.0.0">{}{}<emitter type="constant"><rgb name="radiance" value="1"/></emitter></scene>"#,
            front_camera(4, 4),
            layers(count, -1.0, 1.0, 2.0)
        ))
    };
    assert!(run(&camera_stack(n), 1, 91).pixels.iter().all(|p| *p == Vec3::ONE));
    assert!(run(&camera_stack(n + 1), 1, 91).pixels.iter().all(|p| *p == Vec3::ZERO));
    let d = Vec3::new(0.0, 0.0, -1.0);
    let light = format!(
        r#"<emitter type="directional"><vector name="direction" x="{}" y="{}" z="{}"/><rgb name="irradiance" value="2"/></emitter>"#,
        d.x, d.y, d.z
    );
    let lit = 0.5 / std::f32::consts::PI * 2.0;
    let floor_stack = |count: usize| shadow_scene(false, &(layers(count, 1.1, 1.9, 4.0) + &light));
    assert!(run(&floor_stack(n), 1, 92).pixels.iter().all(|p| (p.x - lit).abs() < 1e-5 * lit));
    assert!(run(&floor_stack(n + 1), 1, 92).pixels.iter().all(|p| p.x == 0.0));
}
