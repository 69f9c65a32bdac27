//! Procedural MaterialX graphs bound to Mitsuba BSDF slots, filtered by the path footprint.

use render::film::{relative_mse, Image};
use render::integrator::{render, RenderSettings};
use render::pathfootprint::FootprintMode;
use std::path::{Path, PathBuf};

fn data() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

/// A checkerboard floor seen from a low camera, receding to a grazing horizon.
fn grazing_scene(texture: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="2"/></integrator>
        <sensor type="perspective"><float name="fov" value="50"/>
            <transform name="to_world"><lookat origin="0, 0.4, 3" target="0, 0, -4" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="48"/><rfilter type="gaussian"/></film>
        </sensor>
        <shape type="rectangle">
            <transform name="to_world"><scale value="8"/><rotate x="1" angle="-90"/></transform>
            <bsdf type="diffuse">{texture}</bsdf>
        </shape>
        <emitter type="directional"><vector name="direction" x="0.2" y="-1" z="-0.3"/><rgb name="irradiance" value="3"/></emitter>
    </scene>"#
    )
}

fn checker_texture() -> String {
    r#"<texture type="mtlx" name="reflectance"><string name="filename" value="checker.mtlx"/><string name="output" value="NG_checker/out"/></texture>"#.into()
}

fn load(xml: &str) -> render::scene::Scene {
    render::loader::load_str(xml, Path::new("mtlx_test.xml"), &data(), &[]).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn graph_texture_renders_and_counts_evaluations() {
    let scene = load(&grazing_scene(&checker_texture()));
    assert!(scene.footprints_needed);
    assert_eq!(scene.graphs.len(), 1);
    let out = render(&scene, RenderSettings::new(2, 1), &|_| {});
    assert!(out.image.pixels.iter().all(|p| p.is_finite()));
    let g = scene.graphs[0].graph();
    let checker = g.node_id("NG_checker/checker").expect("node");
    let evals = out.graph_stats[0].evaluations[checker.0 as usize];
    // One evaluation per floor hit: the floor covers the lower part of the image.
    assert!(evals > 64 * 20 * 2 && evals <= 64 * 48 * 2, "{evals}");
    // The noise output is not bound, so never evaluated.
    let noise = g.node_id("NG_checker/noise").unwrap();
    assert_eq!(out.graph_stats[0].evaluations[noise.0 as usize], 0);
}

#[test]
fn filtered_graph_at_four_spp_beats_point_sampling() {
    let scene = load(&grazing_scene(&checker_texture()));
    let run = |spp, seed, footprint| {
        render(&scene, RenderSettings { footprint, ..RenderSettings::new(spp, seed) }, &|_| {}).image
    };
    let reference: Image = run(1024, 7, FootprintMode::None);
    let filtered = run(4, 1, FootprintMode::Covariance);
    let point = run(4, 1, FootprintMode::None);
    // A checkerboard is the hardest case for prefiltering: hard edges at every scale. Where
    // checks are near the pixel size, the footprint (σ = ½ px, the paper's pixel filter) blurs on
    // top of the pixel filter, a bias the point-sampled reference does not have; far away the
    // filtered value is exact while point sampling aliases. Both errors are reported.
    let mse = |a: &Image| {
        a.pixels.iter().zip(&reference.pixels).map(|(p, r)| (*p - *r).length_squared() as f64).sum::<f64>()
            / a.pixels.len() as f64
    };
    let (m_filtered, m_point) = (mse(&filtered), mse(&point));
    let e_filtered = relative_mse(&filtered, &reference);
    let e_point = relative_mse(&point, &reference);
    eprintln!(
        "grazing checkerboard, 4 spp vs 1024-spp point-sampled reference: MSE filtered {m_filtered:.3e} point {m_point:.3e} (ratio {:.2}); relMSE filtered {e_filtered:.3e} point {e_point:.3e} (ratio {:.2})",
        m_filtered / m_point,
        e_filtered / e_point
    );
    assert!(m_filtered < 0.5 * m_point, "MSE filtered {m_filtered:.4e} vs point {m_point:.4e}");
    assert!(e_filtered < 0.65 * e_point, "relMSE filtered {e_filtered:.4e} vs point {e_point:.4e}");
}

#[test]
fn bad_graph_bindings_are_clear_errors() {
    let err = |tex: &str| {
        render::loader::load_str(&grazing_scene(tex), Path::new("bad.xml"), &data(), &[]).err().unwrap().to_string()
    };
    let e = err(
        r#"<texture type="mtlx" name="reflectance"><string name="filename" value="nope.mtlx"/><string name="output" value="a/b"/></texture>"#,
    );
    assert!(e.contains("bad.xml:") && e.contains("nope.mtlx") && e.contains("not found"), "{e}");
    let e = err(
        r#"<texture type="mtlx" name="reflectance"><string name="filename" value="checker.mtlx"/><string name="output" value="NG_checker/missing"/></texture>"#,
    );
    assert!(e.contains("NG_checker/missing") && e.contains("NG_checker/out"), "{e}");
    let e = err(r#"<texture type="mtlx" name="reflectance"><string name="filename" value="checker.mtlx"/></texture>"#);
    assert!(e.contains("output"), "{e}");
}

#[test]
fn free_textures_evaluate_no_node_and_keep_the_mean() {
    let scene = load(&grazing_scene(&checker_texture()));
    let free = render(&scene, RenderSettings { free_textures: true, ..RenderSettings::new(2, 1) }, &|_| {});
    assert!(free.graph_stats.iter().all(|g| g.evaluations.iter().all(|&e| e == 0)));
    // The constant is the checkerboard's mean reflectance: in the far field, where the filtered
    // render has converged to that mean, the two agree.
    let filtered = render(&scene, RenderSettings::new(16, 1), &|_| {}).image;
    let (mut a, mut b) = (0.0, 0.0);
    for x in 0..64 {
        for y in 24..27 {
            a += free.image.get(x, y).x;
            b += filtered.get(x, y).x;
        }
    }
    assert!(a > 0.0 && (a - b).abs() < 0.05 * a, "free {a} filtered {b}");
}

/// The wood-floor demo scene, reduced to what the aliasing test needs: its graph material on the
/// receding floor under a directional light with direct lighting only (so that all noise left in
/// a render is texture aliasing, not light transport), at 64×64.
fn wood_floor_direct() -> render::scene::Scene {
    let scenes = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let text = std::fs::read_to_string(scenes.join("wood_floor.xml")).unwrap();
    let start = text.find("<shape type=\"rectangle\" id=\"sun\">").expect("sun");
    let lights = r#"<emitter type="directional"><vector name="direction" x="0.4" y="-0.6" z="-0.5"/><rgb name="irradiance" value="3"/></emitter>"#;
    let text = format!("{}{lights}\n</scene>\n", &text[..start])
        .replace("<integer name=\"max_depth\" value=\"8\"/>", "<integer name=\"max_depth\" value=\"2\"/>");
    let defines = [("res".to_string(), "64".to_string())];
    render::loader::load_str(&text, Path::new("wood_floor.xml"), &scenes, &defines).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn demo_wood_floor_at_four_spp_beats_point_sampling() {
    let scene = wood_floor_direct();
    let run = |spp, seed, footprint| {
        render(&scene, RenderSettings { footprint, ..RenderSettings::new(spp, seed) }, &|_| {}).image
    };
    let reference = run(512, 11, FootprintMode::None);
    let filtered = run(4, 3, FootprintMode::Covariance);
    let point = run(4, 3, FootprintMode::None);
    let mse = |a: &Image| {
        a.pixels.iter().zip(&reference.pixels).map(|(p, r)| (*p - *r).length_squared() as f64).sum::<f64>()
            / a.pixels.len() as f64
    };
    let auto = render(
        &scene,
        RenderSettings { filter_scale: render::integrator::FilterScale::Auto, ..RenderSettings::new(4, 3) },
        &|_| {},
    )
    .image;
    // What the filtered render converges to: its bias against point sampling.
    let converged = run(64, 5, FootprintMode::Covariance);
    let (m_filtered, m_point, m_auto) = (mse(&filtered), mse(&point), mse(&auto));
    let (e_filtered, e_point) = (relative_mse(&filtered, &reference), relative_mse(&point, &reference));
    eprintln!(
        "wood floor, 4 spp vs 512-spp point-sampled reference: MSE filtered {m_filtered:.3e} (auto scale {m_auto:.3e}) point {m_point:.3e} (ratio {:.3}, auto {:.3}); relMSE filtered {e_filtered:.3e} point {e_point:.3e} (ratio {:.3}); filtered at 64 spp {:.3e}",
        m_filtered / m_point,
        m_auto / m_point,
        e_filtered / e_point,
        mse(&converged)
    );
    // Documented bounds: the footprint filter halves the error of point sampling at 4 spp; what
    // is left is mostly the blur of filtering on top of the pixel filter (the 64-spp filtered
    // render keeps most of it), which the auto scale reduces.
    assert!(m_filtered < 0.6 * m_point && e_filtered < 0.6 * e_point);
    assert!(m_auto < 0.5 * m_point);
}

#[test]
fn graph_normal_bends_the_shading_frame() {
    // A white Lambertian plane (standard_surface with specular 0) whose `normal` comes from a
    // constant normalmap, under a directional light: every pixel is E/π · max(0, n'·l), with n'
    // the graph's normal in the plane's shading frame (tangent +x, bitangent +y, normal +z).
    let l = glam::Vec3::new(-0.5, 0.2, 1.0).normalize();
    let xml = format!(
        r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="2"/></integrator>
        <sensor type="perspective"><float name="fov" value="30"/>
            <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/><rfilter type="box"/></film>
        </sensor>
        <shape type="rectangle"><transform name="to_world"><scale value="10"/></transform>
            <bsdf type="mtlx"><string name="filename" value="tilted_normal.mtlx"/><string name="material" value="M_tilted"/></bsdf>
        </shape>
        <emitter type="directional"><vector name="direction" x="{}" y="{}" z="{}"/><rgb name="irradiance" value="2"/></emitter>
    </scene>"#,
        -l.x, -l.y, -l.z
    );
    let scene = load(&xml);
    let doc = graph::Document::load(data().join("tilted_normal.mtlx")).unwrap();
    let g = doc.graph();
    let out = g.output_id("NG_n/out_normal").unwrap();
    let n = g.eval_output(out, &graph::Footprint::point(glam::Vec2::splat(0.5)), &mut graph::EvalScratch::new(g));
    let n = glam::Vec3::new(n.ch[0].mean, n.ch[1].mean, n.ch[2].mean).normalize();
    assert!(n.z < 0.99, "the test needs a tilted normal, got {n}");
    let expected = 2.0 / std::f32::consts::PI * n.dot(l).max(0.0);
    let flat = 2.0 / std::f32::consts::PI * l.z;
    let img = render(&scene, RenderSettings::new(4, 1), &|_| {}).image;
    for p in &img.pixels {
        assert!((p.x - expected).abs() < 2e-3 * expected, "{} vs {expected} (unbent: {flat})", p.x);
    }
}

/// The library-style materials (scenes/library): a solid marble from fractal3d of the position
/// and a brick wall from a custom nodedef render; `all` caches only uv-only nodes (none of the
/// marble's), and the cached render agrees with the uncached one.
#[test]
fn library_materials_render_and_only_uv_nodes_are_cached() {
    use render::caching::{NodeCache, Strategy};
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/library");
    let defines = [("res".to_string(), "32".to_string())];
    let scene = render::loader::load_file(&dir.join("library.xml"), &defines).unwrap_or_else(|e| panic!("{e}"));
    let nc = NodeCache::new(&scene, &Strategy::All, 1 << 28).unwrap().expect("brick nodes are cacheable");
    let names = nc.cached_node_names(&scene.graphs);
    assert!(names.iter().any(|n| n.starts_with("NG_brick/wall/")), "{names:?}");
    assert!(!names.iter().any(|n| n.starts_with("NG_solid_marble/")), "position-dependent nodes cached: {names:?}");
    let settings = render::integrator::RenderSettings::new(4, 3);
    let plain = render::integrator::render(&scene, settings, &|_| {}).image;
    let cached = render::integrator::render_cached(&scene, settings, Some(&nc), &|_| {}).image;
    let mean: f32 = plain.pixels.iter().map(|p| p.x + p.y + p.z).sum::<f32>() / plain.pixels.len() as f32;
    assert!(mean.is_finite() && mean > 0.05, "mean {mean}");
    let e = render::film::relative_mse(&cached, &plain);
    assert!(e < 0.05, "cached against direct: relMSE {e}");
}
