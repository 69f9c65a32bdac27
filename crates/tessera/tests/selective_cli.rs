//! `tessera profile`, `tessera plan`, `tessera analyze` and `tessera render --strategy auto` end
//! to end on the embedded demo scene: files exist and parse, plans respect the budget and are
//! readable by `--strategy plan:FILE`, and bad input gets clear errors.

use std::path::PathBuf;
use std::process::{Command, Output};

fn tessera(dir: &PathBuf, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tessera")).current_dir(dir).args(args).output().unwrap()
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tessera-sel-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn json(path: PathBuf) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))).unwrap()
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn profile_plan_analyze_and_render_with_the_plan() {
    let dir = temp_dir("pipeline");
    ok(&tessera(&dir, &["profile", "-D", "res=32", "--pixel-fraction", "0.5", "--out", "p.json", "--quiet"]));
    let p = json(dir.join("p.json"));
    assert_eq!(p["schema"], "tessera.profile/1");
    assert!(p["render"]["samples"].as_u64().unwrap() > 0);
    ok(&tessera(&dir, &["plan", "p.json", "--spp", "8", "--budget-mb", "1", "--out", "plan.json"]));
    let plan = json(dir.join("plan.json"));
    assert_eq!(plan["schema"], "tessera.plan/1");
    assert!(plan["predicted"]["peak_bytes"].as_f64().unwrap() <= 1048576.0);
    ok(&tessera(
        &dir,
        &[
            "render",
            "-D",
            "res=32",
            "--spp",
            "8",
            "--strategy",
            "plan:plan.json",
            "--budget-mb",
            "1",
            "--quiet",
            "--out",
            "x.png",
            "--stats-json",
            "s.json",
        ],
    ));
    let s = json(dir.join("s.json"));
    assert!(s["cache"].is_null() || s["cache"]["peak_bytes"].as_f64().unwrap() <= 1048576.0);
    let o = tessera(&dir, &["analyze", "p.json", "--spp", "8", "--measured", "s.json", "--report", "rep"]);
    ok(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("Predicted against measured") && text.contains("| none |"), "{text}");
    for f in ["table.md", "levels.svg", "node_levels.svg", "predicted_vs_measured.svg"] {
        assert!(dir.join("rep").join(f).is_file(), "{f} missing");
    }
}

#[test]
fn auto_strategy_profiles_plans_renders_and_reports() {
    let dir = temp_dir("auto");
    ok(&tessera(
        &dir,
        &[
            "render",
            "-D",
            "res=32",
            "--spp",
            "8",
            "--strategy",
            "auto",
            "--budget-mb",
            "64",
            "--quiet",
            "--out",
            "a.png",
            "--stats-json",
            "a.json",
        ],
    ));
    let s = json(dir.join("a.json"));
    assert_eq!(s["plan"]["strategy"], "auto");
    assert!(s["plan"]["profile_s"].as_f64().unwrap() > 0.0);
    assert!(s["plan"]["predicted"]["render_s"].as_f64().unwrap() > 0.0);
    for f in ["profile.json", "plan.json", "table.md", "levels.svg", "node_levels.svg", "predicted_vs_measured.svg"] {
        assert!(dir.join("a.report").join(f).is_file(), "{f} missing");
    }
}

/// `--profile-share` is a share of the pixels where a pixel's samples share their first-hit
/// textures (one profile sample per traced pixel, a quarter of them a second, timed one), and of
/// the samples where every sample evaluates its own.
#[test]
fn the_profile_share_counts_pixels_where_samples_share_their_textures() {
    let dir = temp_dir("share");
    let profile_samples = |extra: &[&str], name: &str| {
        let (out, json_name) = (format!("{name}.exr"), format!("{name}.json"));
        let mut args = vec![
            "render",
            "-D",
            "res=64",
            "--spp",
            "16",
            "--strategy",
            "auto",
            "--profile-share",
            "0.5",
            "--quiet",
            "--out",
            &out,
            "--stats-json",
            &json_name,
        ];
        args.extend_from_slice(extra);
        ok(&tessera(&dir, &args));
        let s = json(dir.join(&json_name));
        let p = json(dir.join(format!("{name}.report")).join("profile.json"));
        (s["plan"]["profile_samples"].as_u64().unwrap(), p["render"]["spp"].as_u64().unwrap())
    };
    // Half the 4096 pixels, one sample each, and about a quarter of those a second.
    let (shared, spp) = profile_samples(&[], "a");
    assert_eq!(spp, 1);
    assert!((2048 + 400..=2048 + 650).contains(&shared), "{shared}");
    // Half the 65 536 samples: 8 on every pixel.
    let (own, spp) = profile_samples(&["--per-sample-textures"], "b");
    assert_eq!((own, spp), (32768, 8));
}

#[test]
fn bad_profiles_plans_and_budgets_are_clear_errors() {
    let dir = temp_dir("bad");
    std::fs::write(dir.join("junk.json"), "{ \"schema\": \"tessera.profile/1\", \"scene\": 3 }").unwrap();
    let o = tessera(&dir, &["plan", "junk.json", "--spp", "4"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("junk.json") && e.contains("line 1"), "{e}");
    let o = tessera(&dir, &["plan", "missing.json"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("missing.json"));
    ok(&tessera(&dir, &["profile", "-D", "res=16", "--out", "p.json", "--quiet"]));
    let o = tessera(&dir, &["plan", "p.json", "--budget-mb", "0"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--budget-mb"));
    let o = tessera(&dir, &["profile", "-D", "res=16", "--pixel-fraction", "0"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--pixel-fraction"));
    // A plan file naming nodes the scene does not have.
    std::fs::write(
        dir.join("other.json"),
        r#"{"schema":"tessera.plan/1","scene":{"name":"x","hash":"0"},"budget_bytes":1,"target":{"samples":1,"threads":1},
            "nodes":[{"graph":"marble.mtlx","node":"NG_marble/not_here","min_level":0}],"predicted":{"evaluations":0,"lookups":0,
            "tiles_filled":0,"texels_filled":0,"peak_bytes":0,"texture_thread_s":0,"render_s":0},"search":{"method":"x","candidates":0,
            "plans_evaluated":0,"seconds":0}}"#,
    )
    .unwrap();
    let o = tessera(
        &dir,
        &["render", "-D", "res=16", "--spp", "1", "--strategy", "plan:other.json", "--quiet", "--out", "x.png"],
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("other.json") && e.contains("NG_marble/not_here"), "{e}");
    assert!(!dir.join("x.png").exists(), "no image may be left after an error");
}
