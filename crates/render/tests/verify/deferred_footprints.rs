//! Footprints deferred at hits without textures or that read their pixel's shared textures: the
//! estimator advances through such a hit only when a later hit's textures read their footprint. Images must be bit for bit those of
//! computing every footprint as the path reaches it, at any thread count; only the work differs.

use render::integrator::{render, RenderOutput, RenderSettings};
use render::scene::Scene;
use std::path::{Path, PathBuf};

fn scenes() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

fn demo(name: &str) -> Scene {
    let defines = [("res".to_string(), "40".to_string())];
    render::loader::load_file(&scenes().join(format!("{name}.xml")), &defines).unwrap_or_else(|e| panic!("{e}"))
}

/// A small textured patch on the floor of a closed box of plain diffuse walls and a mirror:
/// paths bounce many times between untextured surfaces before they meet the texture again, so
/// more vertices are deferred in a row than a path holds at once.
fn box_with_patch() -> Scene {
    let wall = |t: &str, c: &str| {
        format!(
            r#"<shape type="rectangle"><transform name="to_world">{t}</transform>
               <bsdf type="diffuse"><rgb name="reflectance" value="{c}"/></bsdf></shape>"#
        )
    };
    let xml = format!(
        r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="24"/><integer name="rr_depth" value="20"/></integrator>
        <sensor type="perspective"><float name="fov" value="60"/>
            <transform name="to_world"><lookat origin="0, 0, 0.9" target="0, 0, -1" up="0, 1, 0"/></transform>
            <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
            <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/></film>
        </sensor>
        {floor}{ceiling}{back}{left}{right}{front}
        <shape type="rectangle"><transform name="to_world"><scale value="0.3"/><rotate x="1" angle="-90"/><translate y="-0.99"/></transform>
            <bsdf type="diffuse"><texture type="mtlx" name="reflectance">
                <string name="filename" value="marble.mtlx"/><string name="output" value="NG_marble_tiles/out_color"/>
            </texture></bsdf></shape>
        <shape type="sphere"><float name="radius" value="0.25"/><transform name="to_world"><translate x="0.4" y="-0.5" z="-0.4"/></transform>
            <bsdf type="conductor"/></shape>
        <shape type="rectangle"><transform name="to_world"><scale value="0.2"/><rotate x="1" angle="90"/><translate y="0.99"/></transform>
            <emitter type="area"><rgb name="radiance" value="20"/></emitter></shape>
    </scene>"#,
        floor = wall(r#"<rotate x="1" angle="-90"/><translate y="-1"/>"#, "0.9"),
        ceiling = wall(r#"<rotate x="1" angle="90"/><translate y="1"/>"#, "0.9"),
        back = wall(r#"<translate z="-1"/>"#, "0.9, 0.8, 0.7"),
        left = wall(r#"<rotate y="1" angle="90"/><translate x="-1"/>"#, "0.8, 0.9, 0.8"),
        right = wall(r#"<rotate y="1" angle="-90"/><translate x="1"/>"#, "0.8, 0.8, 0.9"),
        front = wall(r#"<rotate y="1" angle="180"/><translate z="1"/>"#, "0.9"),
    );
    render::loader::load_str(&xml, Path::new("box.xml"), &scenes(), &[]).unwrap_or_else(|e| panic!("{e}"))
}

fn run(scene: &Scene, threads: usize, eager: bool) -> RenderOutput {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    let settings = RenderSettings { eager_footprints: eager, ..RenderSettings::new(4, 11) };
    pool.install(|| render(scene, settings, &|_| {}))
}

#[test]
fn deferred_footprints_change_the_work_but_not_the_image() {
    let cases = [
        ("marble", demo("marble")),
        ("rusted_metal", demo("rusted_metal")),
        ("poster_wall", demo("poster_wall")),
        ("wood_floor", demo("wood_floor")),
        ("box", box_with_patch()),
    ];
    for (name, scene) in &cases {
        assert!(scene.footprints_needed && !scene.masked, "{name}");
        let eager = run(scene, 1, true);
        let (e, skipped) = (eager.counts.footprints, eager.counts.footprints_skipped);
        assert!(e > 0 && skipped == 0, "{name}: eager paths computed {e} footprints and skipped {skipped}");
        for threads in [1, 2] {
            let lazy = run(scene, threads, false);
            assert!(lazy.image == eager.image, "{name}, {threads} threads: deferring footprints changed the image");
            let (l, s) = (lazy.counts.footprints, lazy.counts.footprints_skipped);
            // Every hit's footprint is either computed (when reached or later) or skipped.
            assert_eq!(l + s, e, "{name}, {threads} threads: {l} computed + {s} skipped against {e} eager");
            // These scenes have plain walls, mirrors or glass that paths leave for the sky or a
            // light without meeting a texture again, and first hits that read their pixel's
            // textures; the wood floor's paths almost never meet a texture after the first hit.
            let least = if *name == "wood_floor" { 0.9 } else { 0.03 };
            assert!(s as f64 > least * e as f64, "{name}: only {s} of {e} footprints skipped");
            eprintln!("{name}, {threads} threads: {s} of {e} footprints skipped");
        }
    }
}

/// Where shadow rays cross partly transparent surfaces, the footprint they carry starts from the
/// shading vertex's: nothing is deferred there.
#[test]
fn masked_scenes_defer_nothing() {
    let xml = r#"<scene version="3.0.0">
        <sensor type="perspective"><float name="fov" value="40"/>
            <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
        </sensor>
        <shape type="rectangle"><bsdf type="mask"><float name="opacity" value="0.5"/><bsdf type="diffuse"/></bsdf></shape>
        <shape type="rectangle"><transform name="to_world"><scale value="3"/><translate z="-1"/></transform>
            <bsdf type="diffuse"><texture type="mtlx" name="reflectance">
                <string name="filename" value="marble.mtlx"/><string name="output" value="NG_marble_tiles/out_color"/>
            </texture></bsdf></shape>
        <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
    </scene>"#;
    let scene =
        render::loader::load_str(xml, Path::new("masked.xml"), &scenes(), &[]).unwrap_or_else(|e| panic!("{e}"));
    assert!(scene.masked && scene.footprints_needed);
    let out = run(&scene, 1, false);
    assert!(out.counts.footprints > 0 && out.counts.footprints_skipped == 0, "{:?}", out.counts);
}
