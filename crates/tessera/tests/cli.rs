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
