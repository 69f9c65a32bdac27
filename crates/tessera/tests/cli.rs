//! End-to-end tests of the `tessera` binary.

use std::path::{Path, PathBuf};
use std::process::Command;

fn tessera() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tessera-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn refs_scene(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/refs/scenes").join(name)
}

#[test]
fn default_scene_renders_png_and_exr() {
    let dir = temp_dir("default");
    let out = tessera()
        .current_dir(&dir)
        .args(["render", "-D", "res=40", "-D", "spp=2", "--stats-json", "stats.json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for f in ["tessera.png", "tessera.exr", "stats.json"] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("stats.json")).unwrap()).unwrap();
    assert_eq!(stats["schema"], "tessera.stats/1");
    assert_eq!(stats["width"], 40);
    assert_eq!(stats["counts"]["samples"], 40 * 40 * 2);
    assert!(stats["phases"]["render_s"].as_f64().unwrap() > 0.0);
    // Only the finished files are left: no temporaries.
    let names: Vec<String> =
        std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(names.len(), 3, "{names:?}");
}

fn render_bytes(dir: &Path, threads: &str, name: &str) -> Vec<u8> {
    let out = tessera()
        .current_dir(dir)
        .args(["render", "--quiet", "-D", "res=48", "-D", "spp=3", "--seed", "7", "--threads", threads, "--out", name])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    std::fs::read(dir.join(name)).unwrap()
}

#[test]
fn images_are_identical_for_any_thread_count() {
    let dir = temp_dir("threads");
    let one = render_bytes(&dir, "1", "one.exr");
    let two = render_bytes(&dir, "2", "two.exr");
    let three = render_bytes(&dir, "3", "three.exr");
    assert!(one == two && two == three, "images differ between thread counts");
}

fn expect_failure(args: &[&str], dir: &Path, needles: &[&str]) {
    let out = tessera().current_dir(dir).args(args).output().unwrap();
    assert!(!out.status.success(), "{args:?} should fail");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: stderr lacks '{n}': {err}");
    }
}

#[test]
fn bad_input_gives_clear_errors_and_no_output() {
    let dir = temp_dir("bad");
    expect_failure(&["render", "missing.xml", "--out", "x.exr"], &dir, &["missing.xml", "not found"]);
    std::fs::write(dir.join("broken.xml"), "<scene version=\"3.0.0\">\n  <shape type=\"sphere\">\n</scene>\n").unwrap();
    expect_failure(&["render", "broken.xml", "--out", "x.exr"], &dir, &["broken.xml:"]);
    std::fs::write(
        dir.join("unknown.xml"),
        "<scene version=\"3.0.0\">\n  <sensor type=\"perspective\"/>\n  <shape type=\"teapot\"/>\n</scene>\n",
    )
    .unwrap();
    expect_failure(&["render", "unknown.xml", "--out", "x.exr"], &dir, &["unknown.xml:3", "teapot"]);
    expect_failure(&["render", "--spp", "0", "--out", "x.exr"], &dir, &["spp"]);
    expect_failure(&["render", "--out", "x.tiff", "-D", "res=8"], &dir, &["x.tiff"]);
    expect_failure(&["render", "--threads", "0"], &dir, &["threads"]);
    // Not one thread per request until the system refuses: a bound, named with the machine's cores.
    expect_failure(&["render", "--threads", "100000", "-D", "res=8"], &dir, &["--threads 100000", "1024", "cores"]);
    expect_failure(
        &["bake", "x.mtlx", "--element", "o", "--res", "4", "--out", "b.png", "--threads", "5000"],
        &dir,
        &["--threads 5000"],
    );
    // A filter 1e18 footprints wide overflowed the moments' arithmetic (a panic); 1e20 hung.
    expect_failure(&["render", "--filter-scale", "1e18", "-D", "res=8"], &dir, &["filter scale", "100"]);
    // A folder is not a missing file.
    std::fs::create_dir_all(dir.join("scene_dir.xml")).unwrap();
    expect_failure(&["render", "scene_dir.xml", "--out", "x.exr"], &dir, &["scene_dir.xml", "folder"]);
    expect_failure(&["render", "-D", "res=0"], &dir, &["film size"]);
    expect_failure(&["render", "-D", "res=100000"], &dir, &["exceeds"]);
    expect_failure(&["render", "-D", "noequals"], &dir, &["NAME=VALUE"]);
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.ends_with(".xml"))
        .collect();
    assert!(left.is_empty(), "failed runs left files behind: {left:?}");
}

/// A `-D` that no `<default>` declares and no `$name` reads (a misspelling) changes nothing, so
/// it is reported; declared and read ones are not.
#[test]
fn unused_defines_are_reported() {
    let dir = temp_dir("defines");
    let run = |defines: &[&str]| {
        let mut args = vec!["render", "--quiet", "--out", "x.png"];
        for d in defines {
            args.extend(["-D", d]);
        }
        let out = tessera().current_dir(&dir).args(&args).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = run(&["res=8", "spp=1", "spp_typo=4"]);
    assert!(err.contains("-D spp_typo=") && err.contains("no effect"), "{err}");
    assert!(!err.contains("-D res=") && !err.contains("-D spp="), "{err}");
    assert!(!run(&["res=8", "spp=1"]).contains("no effect"));
}

#[test]
fn reference_scene_renders_from_the_command_line() {
    let dir = temp_dir("refscene");
    let out = tessera()
        .current_dir(&dir)
        .arg("render")
        .arg(refs_scene("textured_mesh.xml"))
        .args(["--spp", "1", "--quiet", "--out", "t.png"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let img = image::open(dir.join("t.png")).unwrap();
    assert_eq!((img.width(), img.height()), (256, 256));
}

#[test]
fn footprint_command_prints_a_consistent_path() {
    let out = tessera()
        .arg("footprint")
        .arg(refs_scene("dielectrics.xml"))
        .args(["--pixel", "80", "140", "--seed", "0", "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["schema"], "tessera.footprint/1");
    let vertices = v["vertices"].as_array().unwrap();
    // This pixel looks through the smooth glass sphere: refraction with η = 1.5, α = 0.
    assert_eq!(vertices[0]["event"], "refract");
    assert!((vertices[0]["eta"].as_f64().unwrap() - 1.5).abs() < 1e-6);
    assert_eq!(vertices[0]["alpha"].as_f64().unwrap(), 0.0);
    for vx in vertices.iter().filter(|v| v.get("cov_world").is_some()) {
        let w: Vec<Vec<f64>> = serde_json::from_value(vx["cov_world"].clone()).unwrap();
        let n: Vec<f64> = serde_json::from_value(vx["normal"].clone()).unwrap();
        for (i, row) in w.iter().enumerate() {
            assert!(row[i] >= 0.0);
            for (j, x) in row.iter().enumerate() {
                assert!(x.is_finite() && (x - w[j][i]).abs() <= 1e-9 * (1.0 + row[i].abs()));
            }
        }
        // T Σ Tᵀ lies in the tangent plane: the shading normal is in its null space.
        let wn: Vec<f64> = (0..3).map(|i| (0..3).map(|j| w[i][j] * n[j]).sum()).collect();
        let scale = w[0][0] + w[1][1] + w[2][2];
        assert!(wn.iter().all(|x| x.abs() <= 1e-4 * scale.max(1e-30)), "{wn:?} vs trace {scale}");
        assert!(vx["lod"].as_f64().unwrap().is_finite());
    }
    // Out-of-image pixels are an error.
    let bad =
        tessera().arg("footprint").arg(refs_scene("dielectrics.xml")).args(["--pixel", "999", "0"]).output().unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("outside"));
}

#[test]
fn footprint_aov_grows_toward_the_horizon() {
    let dir = temp_dir("aov");
    let out = tessera()
        .current_dir(&dir)
        .arg("render")
        .arg(refs_scene("dielectrics.xml"))
        .args(["--spp", "2", "--quiet", "--aov", "footprint", "--out", "d.exr"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(dir.join("d.footprint.png").is_file());
    let img = image::open(dir.join("d.footprint.exr")).unwrap().into_rgb32f();
    // Column 20 sees the floor from row ~120 (far) down to row 255 (near): the first-bounce
    // footprint in uv shrinks toward the camera.
    let lod = |y: u32| img.get_pixel(20, y)[0];
    assert!(lod(130) > lod(250) + 1.0, "far {} near {}", lod(130), lod(250));
    assert!(img.pixels().all(|p| p.0.iter().all(|c| c.is_finite())));
}

#[test]
fn strategies_from_the_command_line() {
    let dir = temp_dir("strategy");
    let out = tessera()
        .current_dir(&dir)
        .args([
            "render",
            "-D",
            "res=24",
            "-D",
            "spp=1",
            "--strategy",
            "outputs",
            "--budget-mb",
            "8",
            "--out",
            "s.exr",
            "--stats-json",
            "s.json",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("s.json")).unwrap()).unwrap();
    let cache = &stats["cache"];
    assert!(cache["lookups"].as_u64().unwrap() > 0 && cache["tiles_filled"].as_u64().unwrap() > 0);
    assert!(cache["peak_bytes"].as_u64().unwrap() <= 8 << 20);
    assert!(!cache["cached_nodes"].as_array().unwrap().is_empty());
    // Per-node, per-level statistics add up to the totals.
    let nodes = cache["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), cache["cached_nodes"].as_array().unwrap().len());
    let fills: u64 =
        nodes.iter().flat_map(|n| n["levels"].as_array().unwrap().iter()).map(|l| l["fills"].as_u64().unwrap()).sum();
    assert_eq!(fills, cache["tiles_filled"].as_u64().unwrap());
    expect_failure(&["render", "-D", "res=8", "--strategy", "nodes:nope"], &dir, &["nope"]);
    expect_failure(&["render", "-D", "res=8", "--strategy", "sometimes"], &dir, &["strategy"]);
    expect_failure(&["render", "-D", "res=8", "--strategy", "all", "--budget-mb", "0"], &dir, &["budget"]);
    expect_failure(
        &["render", "-D", "res=8", "--strategy", "all", "--budget-mb", "0.0001"],
        &dir,
        &["smaller than one tile"],
    );
}

/// A floor textured by an image whose texels are NaN on one side: a known source of non-finite
/// texture values (EXR files do hold NaNs). Writes the scene, its document and the image to `dir`.
fn nan_texture_scene(dir: &Path) -> PathBuf {
    exr::prelude::write_rgb_file(
        dir.join("nan.exr"),
        4,
        4,
        |x, _| if x < 2 { (f32::NAN, 0.5, 0.5) } else { (0.5, 0.5, 0.5) },
    )
    .unwrap();
    std::fs::write(
        dir.join("nan.mtlx"),
        r#"<?xml version="1.0"?>
<materialx version="1.39">
  <nodegraph name="NG">
    <image name="tex" type="color3"><input name="file" type="filename" value="nan.exr"/></image>
    <output name="out" type="color3" nodename="tex"/>
  </nodegraph>
</materialx>"#,
    )
    .unwrap();
    let scene = dir.join("nan.xml");
    std::fs::write(
        &scene,
        r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="perspective"><float name="fov" value="50"/>
        <transform name="to_world"><lookat origin="0, 2, 0.01" target="0, 0, 0" up="0, 0, -1"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
        <sampler type="independent"><integer name="sample_count" value="2"/></sampler>
    </sensor>
    <shape type="rectangle">
        <bsdf type="diffuse" id="nan_floor">
            <texture type="mtlx" name="reflectance"><string name="filename" value="nan.mtlx"/><string name="output" value="NG/out"/></texture>
        </bsdf>
    </shape>
    <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>"#,
    )
    .unwrap();
    scene
}

#[test]
fn non_finite_texture_values_are_reported_and_strict_refuses_them() {
    let dir = temp_dir("nonfinite");
    let scene = nan_texture_scene(&dir);
    let out = tessera()
        .current_dir(&dir)
        .args(["render", "--quiet", "--stats-json", "stats.json", "--out", "nan.exr.out.exr"])
        .arg(&scene)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8_lossy(&out.stderr);
    // Even with --quiet: the graph, the node and how often. (Texture reads map a NaN to 0, so
    // the samples themselves stay finite: without this report the floor would only look dark.)
    for needle in [
        "procedural texture values that were not finite",
        "nan.mtlx",
        "node `NG/tex` (image)",
        "times",
        "material 'nan_floor'",
        "bounce 0",
    ] {
        assert!(err.contains(needle), "no `{needle}` in: {err}");
    }
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("stats.json")).unwrap()).unwrap();
    assert_eq!(stats["nonfinite"]["samples"], stats["counts"]["nonfinite_samples"]);
    let first_node = &stats["nonfinite"]["nodes"][0];
    assert_eq!(first_node["node"], "NG/tex");
    assert_eq!(first_node["graph"], "nan.mtlx");
    let count = first_node["count"].as_u64().unwrap();
    assert!(count > 0);
    // Where: the first shading points, with the material and the bounce.
    let value = &stats["nonfinite"]["values"][0]["origin"];
    assert_eq!(value["material"], "nan_floor");
    assert_eq!(value["node"], "NG/tex");
    assert_eq!(value["bounce"], 0);
    assert!(value["uv"][0].as_f64().unwrap() < 0.7, "{value}");
    let node = stats["graphs"][0]["nodes"].as_array().unwrap().iter().find(|v| v["name"] == "NG/tex").unwrap().clone();
    assert_eq!(node["nonfinite"].as_u64(), Some(count), "{node}");
    // The image holds no NaN.
    let img = exr::prelude::read_first_rgba_layer_from_file(
        dir.join("nan.exr.out.exr"),
        |r, _| vec![0.0f32; r.width() * r.height() * 4],
        |v, p, (r, g, b, _): (f32, f32, f32, f32)| {
            let i = (p.y() * 16 + p.x()) * 4;
            v[i..i + 3].copy_from_slice(&[r, g, b]);
        },
    )
    .unwrap();
    assert!(img.layer_data.channel_data.pixels.iter().all(|x| x.is_finite()));

    // --strict: an error naming the node, and nothing written.
    let scene_arg = scene.to_str().unwrap();
    expect_failure(
        &["render", "--quiet", "--strict", "--out", "strict.exr", "--stats-json", "strict.json", scene_arg],
        &dir,
        &["--strict", "node `NG/tex` (image)", "nothing was written"],
    );
    assert!(!dir.join("strict.exr").exists() && !dir.join("strict.json").exists());

    // tessera bake never writes a NaN texel: an error naming the node and the texel.
    expect_failure(
        &["bake", "nan.mtlx", "--element", "NG/out", "--out", "bake.exr", "--res", "8"],
        &dir,
        &["not finite", "texel (0, 0)", "node `NG/tex` (image)"],
    );
    assert!(!dir.join("bake.exr").exists());
}

#[test]
fn demo_scenes_have_no_non_finite_values() {
    let dir = temp_dir("demo-finite");
    let scenes = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    for name in ["marble", "brick_moss", "rusted_metal", "wood_floor"] {
        let out = tessera()
            .current_dir(&dir)
            .args([
                "render",
                "--quiet",
                "--strict",
                "-D",
                "res=32",
                "-D",
                "spp=2",
                "--stats-json",
                "s.json",
                "--out",
                "x.exr",
            ])
            .arg(scenes.join(format!("{name}.xml")))
            .output()
            .unwrap();
        assert!(out.status.success(), "{name}: {}", String::from_utf8_lossy(&out.stderr));
        let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("s.json")).unwrap()).unwrap();
        assert_eq!(stats["nonfinite"]["samples"], 0, "{name}");
        assert_eq!(stats["nonfinite"]["nodes"].as_array().map(|a| a.len()), Some(0), "{name}");
    }
}

/// A render split on the command line, into sample passes on one side and windows on the
/// other, merges into the very file the unsplit render writes; every step's bad input is an
/// error and leaves no file behind.
#[test]
fn split_renders_merge_into_the_unsplit_image() {
    let dir = temp_dir("passes");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "--quiet", "-D", "res=40", "--spp", "5", "--seed", "4", "--strategy", "outputs"];
        args.extend_from_slice(extra);
        let out = tessera().current_dir(&dir).args(&args).output().unwrap();
        assert!(out.status.success(), "{extra:?}: {}", String::from_utf8_lossy(&out.stderr));
    };
    render(&["--out", "whole.exr"]);
    render(&["--samples", "0..2", "--out", "p0.exr", "--threads", "1"]);
    render(&["--samples", "2..5", "--out", "p1.exr"]);
    render(&["--crop", "0,0,40,13", "--out", "top.exr"]);
    render(&["--crop", "0,13,40,40", "--samples", "0..4", "--out", "bottom0.exr"]);
    render(&["--crop", "0,13,40,40", "--samples", "4..5", "--out", "bottom1.exr"]);
    let merge = |cmd: &str, passes: &[&str], out: &str| {
        let mut args = vec![cmd, "--out", out];
        args.extend_from_slice(passes);
        let o = tessera().current_dir(&dir).args(&args).output().unwrap();
        assert!(o.status.success(), "{cmd} {passes:?}: {}", String::from_utf8_lossy(&o.stderr));
        std::fs::read(dir.join(out)).unwrap()
    };
    let whole = std::fs::read(dir.join("whole.exr")).unwrap();
    assert!(merge("merge", &["p1.exr", "p0.exr"], "merged.exr") == whole, "merged sample passes differ");
    assert!(merge("assemble", &["top.exr", "bottom1.exr", "bottom0.exr"], "assembled.exr") == whole);
    merge("merge", &["p0.exr", "p1.exr"], "merged.png");

    let base = ["render", "-D", "res=40", "--spp", "5"];
    fn with<'a>(base: &[&'a str], extra: &[&'a str]) -> Vec<&'a str> {
        base.iter().chain(extra).copied().collect()
    }
    expect_failure(&with(&base, &["--samples", "3..2", "--out", "x.exr"]), &dir, &["--samples", "A..B"]);
    expect_failure(&with(&base, &["--samples", "3..9", "--out", "x.exr"]), &dir, &["3..9", "5 samples per pixel"]);
    expect_failure(&with(&base, &["--crop", "0,0,41,10", "--out", "x.exr"]), &dir, &["--crop", "40 × 40"]);
    expect_failure(&with(&base, &["--crop", "0,0,10", "--out", "x.exr"]), &dir, &["x0,y0,x1,y1"]);
    expect_failure(&with(&base, &["--samples", "0..2", "--out", "x.png"]), &dir, &["pass file", ".exr"]);
    expect_failure(&with(&base, &["--samples", "0..2", "--strategy", "auto", "--out", "x.exr"]), &dir, &["plan:FILE"]);
    expect_failure(&["merge", "p0.exr", "--out", "x.exr"], &dir, &["no pass has samples 2..5"]);
    expect_failure(&["merge", "p0.exr", "p0.exr", "p1.exr", "--out", "x.exr"], &dir, &["p0.exr", "given twice"]);
    expect_failure(&["merge", "whole.exr", "--out", "x.exr"], &dir, &["whole.exr", "not a tessera pass file"]);
    expect_failure(&["merge", "p0.exr", "p1.exr", "--out", "p0.exr"], &dir, &["p0.exr", "one of the passes"]);
    assert!(!dir.join("x.exr").exists() && !dir.join("x.png").exists());

    // An output that is one of the scene's inputs is refused, and the input is left intact.
    let refs = refs_scene("textured_mesh.xml");
    let scene_dir = dir.join("scene");
    std::fs::create_dir_all(scene_dir.join("textures")).unwrap();
    std::fs::create_dir_all(scene_dir.join("meshes")).unwrap();
    for f in ["textured_mesh.xml", "textures/uvgrid.png", "meshes/torus.obj", "meshes/ribbon.obj"] {
        std::fs::copy(refs.parent().unwrap().join(f), scene_dir.join(f)).unwrap();
    }
    let texture = scene_dir.join("textures/uvgrid.png");
    let before = std::fs::read(&texture).unwrap();
    let scene = scene_dir.join("textured_mesh.xml");
    expect_failure(
        &["render", scene.to_str().unwrap(), "--spp", "1", "--out", texture.to_str().unwrap()],
        &dir,
        &["uvgrid.png", "input files"],
    );
    expect_failure(
        &["render", scene.to_str().unwrap(), "--spp", "1", "--out", "ok.exr", "--stats-json", scene.to_str().unwrap()],
        &dir,
        &["textured_mesh.xml", "input files"],
    );
    assert_eq!(std::fs::read(&texture).unwrap(), before);

    // The longest legal file name is written (its temporary file's name is cut to fit); a longer
    // one is refused before rendering.
    let longest = format!("{}.exr", "a".repeat(251));
    render(&["--out", &longest]);
    assert!(dir.join(&longest).is_file());
    let too_long = format!("{}.exr", "b".repeat(252));
    expect_failure(&with(&base, &["--out", &too_long]), &dir, &["256 bytes long", "at most 255"]);
}

/// Outputs are never destroyed: a symbolic link is followed (the link stays), special files
/// (stdout, a FIFO) are written through, unwritable folders are found before rendering, and
/// an interrupted run leaves neither its outputs nor their temporary files.
#[test]
fn outputs_follow_links_write_through_special_files_and_are_checked_first() {
    use std::os::unix::fs::FileTypeExt;
    let dir = temp_dir("outputs");
    let small = ["render", "-D", "res=16", "--spp", "1", "--quiet"];
    let run = |extra: &[&str]| {
        let args: Vec<&str> = small.iter().chain(extra).copied().collect();
        let out = tessera().current_dir(&dir).args(&args).output().unwrap();
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        out
    };
    // A link to an existing image: the image it names is replaced, the link stays.
    std::fs::write(dir.join("real.exr"), "old").unwrap();
    std::os::unix::fs::symlink("real.exr", dir.join("link.exr")).unwrap();
    run(&["--out", "link.exr"]);
    assert!(std::fs::symlink_metadata(dir.join("link.exr")).unwrap().file_type().is_symlink());
    assert!(std::fs::read(dir.join("real.exr")).unwrap().starts_with(&[0x76, 0x2f, 0x31, 0x01]), "not an EXR");
    // Standard output by name.
    let out = run(&["--out", "x.exr", "--stats-json", "/dev/stdout"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("\"schema\": \"tessera.stats/1\""));
    // A FIFO is written through to its reader and stays a FIFO.
    let fifo = dir.join("stats.fifo");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
    };
    run(&["--out", "x.exr", "--stats-json", fifo.to_str().unwrap()]);
    assert!(reader.join().unwrap().contains("tessera.stats/1"));
    assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());

    // Unwritable places are errors before the (long) render, and nothing is written.
    let long = ["render", "-D", "res=256", "--spp", "4096"];
    fn with<'a>(long: &[&'a str], extra: &[&'a str]) -> Vec<&'a str> {
        long.iter().chain(extra).copied().collect()
    }
    expect_failure(&with(&long, &["--out", "missing/x.exr"]), &dir, &["missing/x.exr", "folder", "does not exist"]);
    expect_failure(
        &with(&long, &["--out", "y.exr", "--stats-json", "missing/s.json"]),
        &dir,
        &["missing/s.json", "does not exist"],
    );
    expect_failure(&with(&long, &["--out", "."]), &dir, &["is a folder"]);
    expect_failure(&with(&long, &["--out", "y.exr", "--stats-json", "."]), &dir, &["is a folder"]);
    expect_failure(
        &with(&long, &["--out", "y.exr", "--stats-json", "./y.exr"]),
        &dir,
        &["two of the render's outputs"],
    );
    assert!(!dir.join("y.exr").exists());

    // Interrupted while writing (a large image, its PNG and its footprint AOV take a while to
    // encode): exit 130, no outputs and no temporary files. The poll catches the write phase.
    let names = |d: &Path| -> Vec<String> {
        std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect()
    };
    let sig = dir.join("sig");
    std::fs::create_dir_all(&sig).unwrap();
    let mut seen = false;
    for _ in 0..3 {
        let mut child = tessera()
            .current_dir(&sig)
            .args(["render", "-D", "res=1536", "--spp", "1", "--free-textures", "--aov", "footprint", "--quiet"])
            .spawn()
            .unwrap();
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break Some(s);
            }
            if names(&sig).iter().any(|n| n.ends_with(".tmp")) {
                seen = true;
                let kill = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
                assert!(kill.success());
                break None;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        };
        match status {
            Some(_) => {
                // Finished before the poll saw a temporary file: clean up and try again.
                for n in names(&sig) {
                    std::fs::remove_file(sig.join(n)).unwrap();
                }
            }
            None => {
                let s = child.wait().unwrap();
                assert_eq!(s.code(), Some(130), "interrupted run: {s:?}");
                assert_eq!(names(&sig), Vec::<String>::new(), "an interrupted run left files");
                break;
            }
        }
    }
    assert!(seen, "three renders finished before their write phase was seen");
}

/// Runs `tessera args` in `dir` and returns its exit status, stderr and peak resident memory
/// in MiB (the child's own, from `wait4`, not this test process's).
fn run_with_peak_memory(args: &[&str], dir: &Path) -> (std::process::ExitStatus, String, f64) {
    use std::io::Read;
    use std::os::unix::process::ExitStatusExt;
    let mut child = tessera()
        .current_dir(dir)
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        stderr.read_to_string(&mut s).unwrap();
        s
    });
    let mut status = 0;
    // SAFETY: an all-zero rusage is a valid value for wait4 to overwrite.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: waits for our own child; `status` and `usage` outlive the call.
    let pid = unsafe { libc::wait4(child.id() as libc::pid_t, &mut status, 0, &mut usage) };
    assert_eq!(pid, child.id() as libc::pid_t, "wait4 failed");
    let err = reader.join().unwrap();
    (std::process::ExitStatus::from_raw(status), err, usage.ru_maxrss as f64 / 1024.0)
}

/// Inputs built to blow up memory are refused (or loaded) within a bounded footprint, each
/// measured as the process's peak memory: before their limits, defaults that multiply took
/// 15 GB, nested node graphs 5 GB, a 30 000-node chain 1.8 GB and a chain of 20 000 node
/// definitions over 24 GB.
#[test]
fn inputs_built_to_exhaust_memory_stay_small() {
    let dir = temp_dir("memory");
    // The XML "billion laughs": nine levels of ten, a 10^10-byte value.
    let mut laughs = String::from("<scene version=\"3.0.0\">\n<default name=\"v0\" value=\"xxxxxxxxxx\"/>\n");
    for i in 1..10 {
        laughs += &format!("<default name=\"v{i}\" value=\"{}\"/>\n", format!("$v{}", i - 1).repeat(10));
    }
    laughs += "<shape type=\"sphere\"><string name=\"x\" value=\"$v9\"/></shape>\n</scene>\n";
    std::fs::write(dir.join("laughs.xml"), laughs).unwrap();
    // 100 000 shapes nested in each other.
    let n = 100_000;
    std::fs::write(
        dir.join("deep.xml"),
        format!("<scene version=\"3.0.0\">\n{}{}</scene>\n", "<shape type=\"sphere\">".repeat(n), "</shape>".repeat(n)),
    )
    .unwrap();
    // Node graphs used as node implementations, each level using the previous ten times (10^8
    // nodes at eight levels).
    let mut multiply = String::from(
        "<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n\
         <nodedef name=\"ND_l0\" node=\"l0\"><output name=\"out\" type=\"float\"/></nodedef>\n\
         <nodegraph name=\"NG_l0\" nodedef=\"ND_l0\"><constant name=\"c\" type=\"float\">\
         <input name=\"value\" type=\"float\" value=\"1\"/></constant><output name=\"out\" type=\"float\" nodename=\"c\"/></nodegraph>\n",
    );
    for l in 1..=8 {
        multiply +=
            &format!("<nodedef name=\"ND_l{l}\" node=\"l{l}\"><output name=\"out\" type=\"float\"/></nodedef>\n");
        multiply += &format!("<nodegraph name=\"NG_l{l}\" nodedef=\"ND_l{l}\">");
        for k in 0..10 {
            multiply += &format!("<l{} name=\"a{k}\" type=\"float\"/>", l - 1);
        }
        let mut prev = "a0".to_string();
        for k in 1..10 {
            multiply += &format!(
                "<add name=\"s{k}\" type=\"float\"><input name=\"in1\" type=\"float\" nodename=\"{prev}\"/>\
                 <input name=\"in2\" type=\"float\" nodename=\"a{k}\"/></add>"
            );
            prev = format!("s{k}");
        }
        multiply += &format!("<output name=\"out\" type=\"float\" nodename=\"{prev}\"/></nodegraph>\n");
    }
    multiply += "<nodegraph name=\"g\"><l8 name=\"top\" type=\"float\"/><output name=\"out\" type=\"float\" nodename=\"top\"/></nodegraph>\n</materialx>\n";
    std::fs::write(dir.join("multiply.mtlx"), multiply).unwrap();
    // A legal chain of 30 000 additions: loads and bakes.
    let mut chain = String::from(
        "<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n<nodegraph name=\"g\">\n\
         <constant name=\"a0\" type=\"float\"><input name=\"value\" type=\"float\" value=\"0\"/></constant>\n",
    );
    for i in 1..30_000 {
        chain += &format!(
            "<add name=\"a{i}\" type=\"float\"><input name=\"in1\" type=\"float\" nodename=\"a{}\"/>\
             <input name=\"in2\" type=\"float\" value=\"0.00001\"/></add>\n",
            i - 1
        );
    }
    chain += "<output name=\"out\" type=\"float\" nodename=\"a29999\"/>\n</nodegraph>\n</materialx>\n";
    std::fs::write(dir.join("chain.mtlx"), chain).unwrap();
    // 20 000 node definitions, each implemented by a graph holding one node of the one before.
    let mut defs = String::from(
        "<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n\
         <nodedef name=\"ND_d0\" node=\"d0\"><output name=\"out\" type=\"float\"/></nodedef>\n\
         <nodegraph name=\"NG_d0\" nodedef=\"ND_d0\"><constant name=\"c\" type=\"float\">\
         <input name=\"value\" type=\"float\" value=\"1\"/></constant><output name=\"out\" type=\"float\" nodename=\"c\"/></nodegraph>\n",
    );
    for l in 1..20_000 {
        defs += &format!(
            "<nodedef name=\"ND_d{l}\" node=\"d{l}\"><output name=\"out\" type=\"float\"/></nodedef>\n\
             <nodegraph name=\"NG_d{l}\" nodedef=\"ND_d{l}\"><d{} name=\"a\" type=\"float\"/>\
             <output name=\"out\" type=\"float\" nodename=\"a\"/></nodegraph>\n",
            l - 1
        );
    }
    defs += "<nodegraph name=\"g\"><d19999 name=\"top\" type=\"float\"/><output name=\"out\" type=\"float\" nodename=\"top\"/></nodegraph>\n</materialx>\n";
    std::fs::write(dir.join("defs.mtlx"), defs).unwrap();

    fn bake(doc: &str) -> Vec<&str> {
        vec!["bake", doc, "--element", "g/out", "--res", "4", "--out", "b.exr", "--quiet"]
    }
    let cases: Vec<(Vec<&str>, bool, &str)> = vec![
        (vec!["render", "laughs.xml", "--out", "x.exr"], false, "grows beyond 1 MiB"),
        (vec!["render", "deep.xml", "--out", "x.exr"], false, "objects deep"),
        (bake("multiply.mtlx"), false, "65536"),
        (bake("chain.mtlx"), true, ""),
        (bake("defs.mtlx"), false, "nested more than 64 deep"),
    ];
    for (args, ok, needle) in cases {
        let (status, err, peak_mib) = run_with_peak_memory(&args, &dir);
        println!("{args:?}: peak {peak_mib:.0} MiB");
        assert_eq!(status.success(), ok, "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(err.replace(' ', "").contains(&needle.replace(' ', "")), "{args:?}: stderr lacks '{needle}': {err}");
        assert!(peak_mib < 400.0, "{args:?} peaked at {peak_mib:.0} MiB");
    }
}

/// `--accel`: each backend renders the scene and says which traced the rays; without the
/// library (`TESSERA_EMBREE` naming a file that is not there) `embree` is an error naming the
/// file and the install script, and `auto` falls back to the built-in BVH; `auto` tests every
/// primitive of a small scene.
#[test]
fn accel_backends_render_and_say_which_traced_the_rays() {
    let dir = temp_dir("accel");
    let scene = refs_scene("cbox.xml");
    let render = |accel: &str, embree: Option<&str>| {
        let mut cmd = tessera();
        cmd.current_dir(&dir).arg("render").arg(&scene).args(["--spp", "2", "--accel", accel]);
        cmd.args(["--out", &format!("{accel}.exr"), "--stats-json", &format!("{accel}.json")]);
        if let Some(path) = embree {
            cmd.env("TESSERA_EMBREE", path);
        }
        cmd.output().unwrap()
    };
    let accel_of = |name: &str| -> String {
        let stats: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join(format!("{name}.json"))).unwrap()).unwrap();
        stats["accel"].as_str().unwrap().to_string()
    };
    let out = render("bvh", None);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(accel_of("bvh").starts_with("built-in BVH"), "{}", accel_of("bvh"));
    assert!(String::from_utf8_lossy(&out.stderr).contains("by built-in BVH"));

    let missing = dir.join("no-such-libembree3.so");
    let missing = missing.to_str().unwrap();
    let out = render("embree", Some(missing));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    for needle in ["--accel embree", "no-such-libembree3.so", "install-embree.sh"] {
        assert!(err.contains(needle), "error '{err}' lacks '{needle}'");
    }
    assert!(!dir.join("embree.exr").exists(), "a failed render left an image");

    let out = render("exhaustive", None);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(accel_of("exhaustive").starts_with("every primitive tested (36 triangles"), "{}", accel_of("exhaustive"));
    // The box's 36 triangles are few enough to be tested exhaustively by default; a mesh of
    // thousands (textured_mesh) is not, and without Embree it falls back to the built-in BVH.
    let out = render("auto", None);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(accel_of("auto").starts_with("every primitive tested"), "{}", accel_of("auto"));
    let out = tessera()
        .current_dir(&dir)
        .arg("render")
        .arg(refs_scene("textured_mesh.xml"))
        .args(["--spp", "1", "--out", "large.exr", "--stats-json", "large.json"])
        .env("TESSERA_EMBREE", missing)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(accel_of("large").starts_with("built-in BVH"), "{}", accel_of("large"));

    if render::embree::available().is_ok() {
        let out = render("embree", None);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        assert!(accel_of("embree").starts_with("Embree 3."), "{}", accel_of("embree"));
    } else {
        eprintln!("accel_backends_render_and_say_which_traced_the_rays: Embree part skipped (not installed)");
    }
}
