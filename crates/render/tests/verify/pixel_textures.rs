//! First-hit textures shared by a pixel's samples: the image is the per-sample image up to
//! rounding (and the Monte Carlo decisions that rounding flips), no further from a converged
//! reference, for a small share of the evaluations; at silhouettes, where the pixel centre's
//! ray misses a sample's surface, a fixed point of the pixel on that surface stands in for it.

use render::film::{relative_mse, Image};
use render::integrator::{render, FilterScale, RenderOutput, RenderSettings};
use std::path::{Path, PathBuf};

/// A checkered floor to a grazing horizon and a checkered ball standing on it (its silhouette
/// against the floor and the sky), lit by a sun and a dim sky; one bounce, so every texture
/// evaluation is a camera ray's first hit.
fn scene() -> render::scene::Scene {
    let texture = CHECKER;
    let xml = format!(
        r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="2"/></integrator>
        <sensor type="perspective"><float name="fov" value="50"/>
            <transform name="to_world"><lookat origin="0, 0.5, 3" target="0, 0.2, -4" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="48"/><integer name="height" value="36"/><rfilter type="gaussian"/></film>
        </sensor>
        <shape type="rectangle">
            <transform name="to_world"><scale value="8"/><rotate x="1" angle="-90"/></transform>
            <bsdf type="diffuse">{texture}</bsdf>
        </shape>
        <shape type="sphere"><point name="center" x="0.3" y="0.5" z="0"/><float name="radius" value="0.5"/>
            <bsdf type="diffuse">{texture}</bsdf>
        </shape>
        <emitter type="directional"><vector name="direction" x="0.2" y="-1" z="-0.3"/><rgb name="irradiance" value="3"/></emitter>
        <emitter type="constant"><rgb name="radiance" value="0.2"/></emitter>
    </scene>"#
    );
    load(&xml, "pixel_textures.xml")
}

/// The checkerboard texture both scenes' floors read.
const CHECKER: &str = r#"<texture type="mtlx" name="reflectance"><string name="filename" value="checker.mtlx"/><string name="output" value="NG_checker/out"/></texture>"#;

/// Loads a scene written in `xml` as the file `name` of the render tests' data folder.
fn load(xml: &str, name: &str) -> render::scene::Scene {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    render::loader::load_str(xml, Path::new(name), &data, &[]).unwrap_or_else(|e| panic!("{e}"))
}

/// The image at another thread count, and the sums of two sample passes merged, are bit for
/// bit the whole render's (`spp` samples, seed `seed`).
fn assert_order_free(scene: &render::scene::Scene, spp: u32, seed: u64) {
    let whole = run(scene, spp, seed, false);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
    let threaded = pool.install(|| run(scene, spp, seed, false));
    assert_eq!(whole.image.pixels, threaded.image.pixels);
    let sums = |range| {
        let s = RenderSettings { sample_range: range, keep_sums: true, ..RenderSettings::new(spp, seed) };
        render(scene, s, &|_| {}).sums.unwrap()
    };
    let (all, p, q) = (sums(None), sums(Some((0, spp / 3))), sums(Some((spp / 3, spp))));
    for ((a, b), c) in p.iter().zip(&q).zip(&all) {
        let mut m = *a;
        m.merge(b);
        assert_eq!(m, *c);
    }
}

fn run(scene: &render::scene::Scene, spp: u32, seed: u64, per_sample: bool) -> RenderOutput {
    render(scene, RenderSettings { per_sample_textures: per_sample, ..RenderSettings::new(spp, seed) }, &|_| {})
}

fn evaluations(out: &RenderOutput) -> u64 {
    out.graph_stats.iter().flat_map(|g| g.evaluations.iter()).sum()
}

#[test]
fn shared_first_hit_textures_match_per_sample_ones_for_a_fraction_of_the_work() {
    let scene = scene();
    let spp = 8;
    let shared = run(&scene, spp, 5, false);
    let own = run(&scene, spp, 5, true);
    let reference: Image = run(&scene, 512, 99, true).image;
    let (e_shared, e_own) = (relative_mse(&shared.image, &reference), relative_mse(&own.image, &reference));
    let apart = relative_mse(&shared.image, &own.image);
    let (n_shared, n_own) = (evaluations(&shared), evaluations(&own));
    eprintln!(
        "error vs reference: shared {e_shared:.4e}, per sample {e_own:.4e}; shared vs per sample {apart:.3e}; evaluations {n_shared} vs {n_own}"
    );
    // Nearly the same image: far closer to each other than either is to the reference (they
    // differ where a sample's own footprint, extrapolated from its hit, was not the pixel's).
    assert!(apart < 1e-2 * e_own, "shared and per-sample images differ by {apart:.3e} (8-spp error {e_own:.3e})");
    assert!(e_shared <= 1.02 * e_own, "sharing moved the image away from the reference: {e_shared:.4e} vs {e_own:.4e}");
    // One evaluation per pixel and surface, and per sample only at silhouettes.
    assert!(n_shared * 4 < n_own, "evaluations: shared {n_shared}, per sample {n_own}");
    assert!(n_shared * 8 > n_own, "every pixel still evaluates once: shared {n_shared}, per sample {n_own}");
    assert!(shared.image.pixels.iter().all(|p| p.is_finite()));
}

/// At silhouettes (the ball's against the floor, the floor's far edge against the sky) the
/// pixel centre's ray misses the surface some of its samples reach; a ray through a fixed point
/// of the pixel that reaches it stands in, so those samples share one evaluation as well. Left
/// to evaluate their own, a silhouette pixel's samples had made one each: at 32 spp 585 of them
/// beside 1044 shared evaluations, now 121 beside 1140. What they read still depends on the pixel and
/// the surface alone (bit for bit across threads and sample passes, at a sample count whose
/// silhouettes need the stand-in).
#[test]
fn silhouette_pixels_share_through_a_point_of_the_pixel_on_the_surface() {
    let scene = scene();
    let out = run(&scene, 32, 4, false);
    let c = &out.counts;
    eprintln!(
        "pixel evaluations {}, reads {}, samples evaluating their own {}",
        c.pixel_texture_evaluations, c.pixel_texture_reads, c.pixel_texture_misses
    );
    assert!(c.pixel_texture_reads > 20 * c.pixel_texture_evaluations, "{c:?}");
    assert!(c.pixel_texture_misses * 5 < c.pixel_texture_evaluations, "{c:?}");
    assert_order_free(&scene, 12, 2);
}

/// Where footprints are not centred on the pixel (a narrower texture filter), every sample
/// reads its own: the setting changes nothing there.
#[test]
fn narrower_filters_evaluate_per_sample() {
    let scene = scene();
    let settings = |per_sample| RenderSettings {
        per_sample_textures: per_sample,
        filter_scale: FilterScale::Fixed(0.5),
        ..RenderSettings::new(4, 3)
    };
    let a = render(&scene, settings(false), &|_| {});
    let b = render(&scene, settings(true), &|_| {});
    assert_eq!(a.image.pixels, b.image.pixels);
    assert_eq!(evaluations(&a), evaluations(&b));
}

/// Split into sample passes and rendered on other thread counts, a render with shared
/// textures is the same image bit for bit: what a pixel shares depends on the pixel and the
/// surface alone, not on which of its samples came first.
#[test]
fn shared_textures_do_not_depend_on_sample_order_or_threads() {
    assert_order_free(&scene(), 6, 8);
}

/// The checkered floor seen only through a tilted flat mirror and a glass ball (camera rays meet
/// the floor after one or more perfectly specular surfaces), under a dim sky.
fn scene_through_specular() -> render::scene::Scene {
    let texture = CHECKER;
    let xml = format!(
        r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="6"/></integrator>
        <sensor type="perspective"><float name="fov" value="40"/>
            <transform name="to_world"><lookat origin="0, 1.3, 2.2" target="0, 1.2, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="40"/><integer name="height" value="32"/><rfilter type="gaussian"/></film>
        </sensor>
        <shape type="rectangle">
            <transform name="to_world"><scale value="8"/><rotate x="1" angle="-90"/></transform>
            <bsdf type="diffuse">{texture}</bsdf>
        </shape>
        <shape type="rectangle">
            <transform name="to_world"><scale x="0.5" y="0.7"/><rotate x="1" angle="30"/><translate x="-0.5" y="1.2" z="0"/></transform>
            <bsdf type="conductor"><string name="material" value="none"/></bsdf>
        </shape>
        <shape type="sphere"><point name="center" x="0.5" y="1.2" z="0"/><float name="radius" value="0.45"/>
            <bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf>
        </shape>
        <emitter type="directional"><vector name="direction" x="0.2" y="-1" z="-0.3"/><rgb name="irradiance" value="3"/></emitter>
        <emitter type="constant"><rgb name="radiance" value="0.2"/></emitter>
    </scene>"#
    );
    load(&xml, "specular.xml")
}

/// Behind perfect mirrors and smooth glass, the samples of a pixel that take the same way to a
/// textured surface read one evaluation at the footprint the pixel centre's ray takes that way.
/// Such a sample's own hit is its film offset carried through the specular surfaces, a draw from
/// the footprint: reading the centre's textures blurs the texture by the pixel filter once, as
/// at a first hit, where each sample filtering around its own hit blurred it twice. So the
/// image is no further from a converged point-sampled reference than per-sample evaluation's,
/// for a fraction of the evaluations, and as independent of sample order and threads.
#[test]
fn textures_behind_mirrors_and_glass_are_shared_by_the_pixel() {
    let scene = scene_through_specular();
    let spp = 8;
    let shared = run(&scene, spp, 5, false);
    let own = run(&scene, spp, 5, true);
    let point = RenderSettings { filter_scale: FilterScale::Fixed(0.0), ..RenderSettings::new(1024, 99) };
    let reference = render(&scene, point, &|_| {}).image;
    let (e_shared, e_own) = (relative_mse(&shared.image, &reference), relative_mse(&own.image, &reference));
    let (n_shared, n_own) = (evaluations(&shared), evaluations(&own));
    let c = &shared.counts;
    eprintln!(
        "error vs point-sampled reference: shared {e_shared:.4e}, per sample {e_own:.4e}; evaluations {n_shared} vs {n_own}; \
         {} reads of {} samples, {} misses",
        c.pixel_texture_reads, c.samples, c.pixel_texture_misses
    );
    // Blurred once instead of twice, the checks behind the mirror and the ball are sharper:
    // measured 7.2e-2 against 1.24e-1.
    assert!(
        e_shared < 0.85 * e_own,
        "sharing should bring the image nearer the reference: {e_shared:.4e} vs {e_own:.4e}"
    );
    // Most samples read a shared evaluation: the floor fills the mirror and the ball.
    assert!(c.pixel_texture_reads > c.samples / 2, "{} reads of {} samples", c.pixel_texture_reads, c.samples);
    assert!(n_shared * 3 < n_own, "evaluations: shared {n_shared}, per sample {n_own}");
    assert!(shared.image.pixels.iter().all(|p| p.is_finite()));
    assert_order_free(&scene, spp, 5);
}

/// One mesh of two quads with the same texture coordinates, one half a unit behind the other
/// and reaching past its edge: along that edge a pixel's samples hit the back quad where the
/// pixel centre's ray hits the front one, at nearly the texture coordinates of the centre's hit
/// but half a unit away. They evaluate their own textures: sharing is decided in space too, not
/// by texture coordinates alone.
#[test]
fn samples_far_from_the_pixel_centre_in_space_evaluate_their_own() {
    let dir = std::env::temp_dir().join(format!("tessera-stacked-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // uv = ((x + 1) / 2, (y + 1) / 2) on both quads: front x ∈ [−1, 0] at z = 0, back x ∈ [−1, 1]
    // at z = −0.5.
    let obj = "v -1 -1 0\nv 0 -1 0\nv 0 1 0\nv -1 1 0\nvt 0 0\nvt 0.5 0\nvt 0.5 1\nvt 0 1\n\
               v -1 -1 -0.5\nv 1 -1 -0.5\nv 1 1 -0.5\nv -1 1 -0.5\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
               f 1/1 2/2 3/3\nf 1/1 3/3 4/4\nf 5/5 6/6 7/7\nf 5/5 7/7 8/8\n";
    std::fs::write(dir.join("stacked.obj"), obj).unwrap();
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let xml = format!(
        r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="2"/></integrator>
        <sensor type="perspective"><float name="fov" value="30"/>
            <transform name="to_world"><lookat origin="0, 0, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="8"/><rfilter type="gaussian"/></film>
        </sensor>
        <shape type="obj"><string name="filename" value="{}"/><bsdf type="diffuse">{CHECKER}</bsdf></shape>
        <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
    </scene>"#,
        dir.join("stacked.obj").display()
    );
    let scene = render::loader::load_str(&xml, Path::new("stacked.xml"), &data, &[]).unwrap_or_else(|e| panic!("{e}"));
    let out = run(&scene, 16, 3, false);
    let c = &out.counts;
    eprintln!("{} reads, {} misses of {} samples", c.pixel_texture_reads, c.pixel_texture_misses, c.samples);
    // The edge runs down one column of 8 pixels: of each such pixel's samples, those on the
    // other side of the edge from its centre's (about half) hit the other quad.
    assert!(c.pixel_texture_misses >= 8 * 4, "{} misses", c.pixel_texture_misses);
    assert!(c.pixel_texture_misses <= 8 * 3 * 16, "{} misses", c.pixel_texture_misses);
    std::fs::remove_dir_all(&dir).ok();
}
