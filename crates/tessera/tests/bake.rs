//! `tessera bake` end to end: against MaterialX's own bakes, orientations, uv rectangles,
//! formats, thread counts, and bad input (clear errors, no output left behind).

use std::path::{Path, PathBuf};
use std::process::Command;

fn tessera() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tessera-bake-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn suite() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/mtlx-suite")
}

/// An EXR's size and channels by name (row 0 at the top).
fn read_exr(path: &Path) -> (usize, usize, Vec<(String, Vec<f32>)>) {
    use exr::prelude::*;
    let img = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let size = img.layer_data.size;
    let chans = img
        .layer_data
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect();
    (size.0, size.1, chans)
}

fn channel<'a>(chans: &'a [(String, Vec<f32>)], name: &str) -> &'a [f32] {
    &chans.iter().find(|(n, _)| n == name).unwrap_or_else(|| panic!("no channel {name}")).1
}

fn bake(dir: &Path, args: &[&str]) {
    let out = tessera().current_dir(dir).arg("bake").args(args).output().unwrap();
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

fn names_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn bakes_match_materialx_in_both_orientations() {
    let dir = temp_dir("noise");
    let doc = suite().join("docs/noise/noise.mtlx");
    let doc = doc.to_str().unwrap();
    bake(&dir, &[doc, "--element", "out_fractal2d_vector3", "--res", "128", "--out", "mx.exr", "--quiet"]);
    bake(
        &dir,
        &[doc, "--element", "out_fractal2d_vector3", "--res", "128", "--out", "mi.exr", "--orientation", "mitsuba"],
    );
    let (w, h, mx) = read_exr(&dir.join("mx.exr"));
    assert_eq!((w, h), (128, 128));
    let (_, _, reference) = read_exr(&suite().join("bakes/noise/noise/out_fractal2d_vector3.exr"));
    // MaterialX orientation: texel for texel the baker's image (row 0 = v = 1).
    for c in ["R", "G", "B"] {
        let (a, r) = (channel(&mx, c), channel(&reference, c));
        let worst = a.iter().zip(r).map(|(x, y)| (x - y).abs() / y.abs().max(1.0)).fold(0.0f32, f32::max);
        assert!(worst <= 1e-4, "channel {c}: max error {worst}");
    }
    // Mitsuba orientation: the same values with rows reversed (row 0 = v = 0).
    let (_, _, mi) = read_exr(&dir.join("mi.exr"));
    let (a, b) = (channel(&mx, "G"), channel(&mi, "G"));
    for j in 0..h {
        for i in 0..w {
            assert_eq!(a[j * w + i], b[(h - 1 - j) * w + i], "texel ({i}, {j})");
        }
    }
    assert_eq!(names_in(&dir), ["mi.exr", "mx.exr"]);
}

#[test]
fn uv_rectangles_resolutions_formats_and_threads() {
    let dir = temp_dir("rect");
    let doc = suite().join("docs/noise/noise.mtlx");
    let doc = doc.to_str().unwrap();
    let e = "out_noise2d_float";
    bake(&dir, &[doc, "--element", e, "--res", "128", "--out", "full.exr", "--threads", "1"]);
    // u in [0.25, 0.5], v in [0.5, 1]: columns 32..64 and rows 0..64 of the full bake.
    bake(
        &dir,
        &[
            doc,
            "--element",
            e,
            "--res",
            "32",
            "--res-y",
            "64",
            "--uv-min",
            "0.25,0.5",
            "--uv-max",
            "0.5,1",
            "--out",
            "part.exr",
        ],
    );
    let (_, _, full) = read_exr(&dir.join("full.exr"));
    let (w, h, part) = read_exr(&dir.join("part.exr"));
    assert_eq!((w, h), (32, 64));
    let (f, p) = (channel(&full, "Y"), channel(&part, "Y"));
    for j in 0..64 {
        for i in 0..32 {
            let d = (p[j * 32 + i] - f[j * 128 + 32 + i]).abs();
            assert!(d <= 1e-5, "texel ({i}, {j}): {d}");
        }
    }
    // The image does not depend on the thread count.
    bake(&dir, &[doc, "--element", e, "--res", "128", "--out", "three.exr", "--threads", "3"]);
    assert_eq!(std::fs::read(dir.join("full.exr")).unwrap(), std::fs::read(dir.join("three.exr")).unwrap());
    // PNG: 8-bit, grey for a float, sRGB-encoded.
    bake(&dir, &[doc, "--element", e, "--res", "40", "--res-y", "20", "--out", "grey.png"]);
    let png = image::open(dir.join("grey.png")).unwrap();
    assert_eq!((png.width(), png.height()), (40, 20));
    assert_eq!(png.color(), image::ColorType::L8);
    // Texel filtering of an image lookup, reached through a material input: a color3 is
    // written as R, G, B.
    let cascade = suite().join("docs/nodegraphs/cascade_nodegraphs.mtlx");
    let images = suite().join("images");
    bake(
        &dir,
        &[
            cascade.to_str().unwrap(),
            "--element",
            "surfacematerial/standard_surface/base_color",
            "--res",
            "16",
            "--filter",
            "texel",
            "--search-path",
            images.to_str().unwrap(),
            "--out",
            "material.exr",
        ],
    );
    let (_, _, m) = read_exr(&dir.join("material.exr"));
    let mut names: Vec<&str> = m.iter().map(|(n, _)| n.as_str()).collect();
    names.sort();
    assert_eq!(names, ["B", "G", "R"]);
}

fn expect_failure(dir: &Path, args: &[&str], needles: &[&str]) {
    let before = names_in(dir);
    let out = tessera().current_dir(dir).arg("bake").args(args).output().unwrap();
    assert!(!out.status.success(), "{args:?} should fail");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: stderr lacks '{n}': {err}");
    }
    assert_eq!(names_in(dir), before, "{args:?} left files behind");
}

#[test]
fn bad_input_gives_clear_errors_and_no_output() {
    let dir = temp_dir("bad");
    let write = |name: &str, body: &str| {
        std::fs::write(
            dir.join(name),
            format!("<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n{body}\n</materialx>\n"),
        )
        .unwrap();
    };
    write(
        "doc.mtlx",
        "  <nodegraph name=\"g\">\n    <frobnicate name=\"f\" type=\"float\" />\n    <constant name=\"k\" type=\"float\" />\n    <output name=\"bad\" type=\"float\" nodename=\"f\" />\n    <output name=\"good\" type=\"float\" nodename=\"k\" />\n  </nodegraph>",
    );
    let base = ["--res", "8", "--out", "x.exr"];
    let with = |extra: &[&'static str]| -> Vec<&'static str> { extra.iter().chain(base.iter()).copied().collect() };
    // Unknown elements list the available ones.
    expect_failure(&dir, &with(&["doc.mtlx", "--element", "g/nope"]), &["doc.mtlx", "g/nope", "available: g/good"]);
    // An element that needs an unsupported node names it, with its line.
    expect_failure(&dir, &with(&["doc.mtlx", "--element", "g/bad"]), &["frobnicate", "doc.mtlx:4:"]);
    // Missing and malformed documents, missing includes.
    expect_failure(&dir, &with(&["missing.mtlx", "--element", "g/good"]), &["missing.mtlx"]);
    write("broken.mtlx", "  <nodegraph name=\"g\">\n");
    expect_failure(&dir, &with(&["broken.mtlx", "--element", "g/good"]), &["broken.mtlx:"]);
    std::fs::write(
        dir.join("include.mtlx"),
        "<?xml version=\"1.0\"?>\n<materialx version=\"1.39\" xmlns:xi=\"http://www.w3.org/2001/XInclude\">\n  <xi:include href=\"gone.mtlx\" />\n</materialx>\n",
    )
    .unwrap();
    expect_failure(&dir, &with(&["include.mtlx", "--element", "g/good"]), &["include.mtlx:3:", "gone.mtlx"]);
    std::fs::write(dir.join("future.mtlx"), "<?xml version=\"1.0\"?>\n<materialx version=\"2.0\">\n</materialx>\n")
        .unwrap();
    expect_failure(&dir, &with(&["future.mtlx", "--element", "g/good"]), &["future.mtlx:2:", "2.0"]);
    // Bad settings.
    expect_failure(&dir, &["doc.mtlx", "--element", "g/good", "--res", "0", "--out", "x.exr"], &["no texels"]);
    expect_failure(
        &dir,
        &["doc.mtlx", "--element", "g/good", "--res", "8", "--out", "x.tif"],
        &["x.tif", ".exr or .png"],
    );
    expect_failure(
        &dir,
        &["doc.mtlx", "--element", "g/good", "--res", "8", "--out", "x.exr", "--uv-min", "0,nan"],
        &["--uv-min", "u,v"],
    );
    expect_failure(
        &dir,
        &["doc.mtlx", "--element", "g/good", "--res", "8", "--out", "x.exr", "--uv-min", "1,0", "--uv-max", "1,1"],
        &["empty"],
    );
    expect_failure(
        &dir,
        &["doc.mtlx", "--element", "g/good", "--res", "8", "--out", "x.exr", "--filter", "box"],
        &["point or texel"],
    );
    expect_failure(
        &dir,
        &["doc.mtlx", "--element", "g/good", "--res", "8", "--out", "x.exr", "--orientation", "up"],
        &["mitsuba or materialx"],
    );
    expect_failure(&dir, &["doc.mtlx", "--element", "g/good", "--res", "8", "--out", "no/such/dir/x.exr"], &["x.exr"]);
    // The good output still bakes.
    bake(&dir, &["doc.mtlx", "--element", "g/good", "--res", "8", "--out", "x.exr", "--quiet"]);
}

/// Extreme but finite inputs bake finite values quickly, point-sampled and filtered: a
/// checkerboard tiled 1e30 times, a fractal asking for 10^6 octaves (the sum stops at its
/// octave limit), and noise at coordinates of 1e9 and beyond (f32's lattice there is whole
/// numbers, where gradient noise is 0).
#[test]
fn extreme_finite_inputs_bake_finite_values_quickly() {
    let dir = temp_dir("extreme");
    std::fs::write(
        dir.join("extreme.mtlx"),
        r#"<?xml version="1.0"?>
<materialx version="1.39">
  <nodegraph name="NG">
    <checkerboard name="c" type="color3"><input name="uvtiling" type="vector2" value="1e30, 1e30"/></checkerboard>
    <fractal2d name="f" type="float"><input name="octaves" type="integer" value="1000000"/></fractal2d>
    <noise2d name="n" type="float"><input name="texcoord" type="vector2" value="3e9, 7e9"/></noise2d>
    <output name="checker" type="color3" nodename="c"/>
    <output name="fractal" type="float" nodename="f"/>
    <output name="far_noise" type="float" nodename="n"/>
  </nodegraph>
</materialx>
"#,
    )
    .unwrap();
    for element in ["NG/checker", "NG/fractal", "NG/far_noise"] {
        for filter in ["point", "texel"] {
            let t = std::time::Instant::now();
            let out = format!("{}-{filter}.exr", element.replace('/', "_"));
            bake(&dir, &["extreme.mtlx", "--element", element, "--res", "16", "--filter", filter, "--out", &out]);
            assert!(t.elapsed().as_secs_f64() < 30.0, "{element} {filter} took {:?}", t.elapsed());
            let (_, _, chans) = read_exr(&dir.join(&out));
            for (name, values) in &chans {
                assert!(values.iter().all(|v| v.is_finite()), "{element} {filter} channel {name}");
            }
        }
    }
}

/// `--frame` sets what `frame` and `time` read (1 by default); a frame that is not a number is
/// refused before anything is written.
#[test]
fn frame_option_reaches_time_nodes() {
    let dir = temp_dir("frame");
    std::fs::write(
        dir.join("t.mtlx"),
        r#"<?xml version="1.0"?><materialx version="1.39"><nodegraph name="g">
  <time name="t" type="float"><input name="fps" type="float" value="24"/></time>
  <output name="out" type="float" nodename="t"/></nodegraph></materialx>"#,
    )
    .unwrap();
    for (frame, want) in [(None, 1.0f32 / 24.0), (Some("48"), 2.0)] {
        let mut args = vec!["t.mtlx", "--element", "g/out", "--res", "2", "--out", "t.exr"];
        if let Some(f) = frame {
            args.extend(["--frame", f]);
        }
        bake(&dir, &args);
        let (_, _, chans) = read_exr(&dir.join("t.exr"));
        assert!(channel(&chans, "Y").iter().all(|v| *v == want), "frame {frame:?}: {:?}", channel(&chans, "Y"));
    }
    let out = tessera()
        .current_dir(&dir)
        .args(["bake", "t.mtlx", "--element", "g/out", "--res", "2", "--out", "u.exr", "--frame", "soon"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a frame number"));
    assert!(!dir.join("u.exr").exists());
}
