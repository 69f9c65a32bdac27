//! End-to-end test of `tessera bench --quick`: the outputs exist and parse, their numbers are
//! consistent with each other, and the HTML report is self-contained.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn tessera() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tessera-bench-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs the quick benchmark with one strategy the renderer rejects; returns results.json.
fn quick_bench(out: &Path, refs: &Path) -> Value {
    let run = tessera()
        .args(["bench", "--quick", "--quiet", "--strategies", "none,outputs,all,not-a-strategy", "--out"])
        .arg(out)
        .arg("--ref-cache")
        .arg(refs)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
fn quick_bench_writes_consistent_results_and_a_self_contained_report() {
    let dir = temp_dir("quick");
    let (out, refs) = (dir.join("results"), dir.join("refs"));
    let r = quick_bench(&out, &refs);
    assert_eq!(r["schema"], "tessera.bench/1");
    let settings = &r["settings"];
    assert_eq!((settings["res"].as_u64(), settings["spp"].as_u64()), (Some(32), Some(2)));
    let scenes = r["scenes"].as_array().unwrap();
    assert_eq!(scenes.len(), 1);
    let scene = &scenes[0];
    assert!(scene["error"].is_null(), "{}", scene["error"]);
    assert_eq!(scene["reference"]["reused"], false);
    let runs = scene["runs"].as_array().unwrap();
    let names: Vec<&str> = runs.iter().map(|x| x["strategy"].as_str().unwrap()).collect();
    assert_eq!(names, ["none", "outputs", "all", "not-a-strategy", "free"]);
    let by = |n: &str| runs.iter().find(|x| x["strategy"] == n).unwrap();

    // A strategy the renderer rejects is recorded, and the benchmark carries on.
    let bad = by("not-a-strategy");
    assert!(bad["summary"].is_null());
    assert!(bad["error"].as_str().unwrap().contains("not-a-strategy"), "{}", bad["error"]);
    assert!(by("free")["lower_bound"].as_bool().unwrap());

    let ok: Vec<&Value> = runs.iter().filter(|x| !x["summary"].is_null()).collect();
    assert_eq!(ok.len(), 4);
    for run in &ok {
        let s = &run["summary"];
        let name = run["strategy"].as_str().unwrap();
        // Every run renders the same samples.
        assert_eq!(s["samples"].as_u64(), Some(32 * 32 * 2), "{name}");
        // The time is the sum of the phases it is defined as (one repeat: the median is that run).
        let p = &s["phases"];
        let sum = f(&p["profile_s"]) + f(&p["plan_s"]) + f(&p["cache_setup_s"]) + f(&p["render_s"]);
        assert!((f(&s["time_s"]["median"]) - sum).abs() <= 1e-9 * sum.max(1.0), "{name}");
        assert!(f(&s["process_s"]["median"]) >= f(&p["render_s"]), "{name}: the process outlives its render");
        // Nothing renders much faster than the free-texture lower bound (noise aside).
        let ratio = f(&s["ratio_to_lower_bound"]["median"]);
        assert!(ratio > 0.5, "{name}: {ratio} × the lower bound");
        let e = &s["image_error"];
        assert!(f(&e["rel_mse"]) > 0.0 && f(&e["rel_mse"]).is_finite(), "{name}");
        assert!(f(&e["flip"]) > 0.0 && f(&e["flip"]) < 1.0, "{name}");
        for key in ["image", "flip_image", "stats"] {
            let path = out.join(run[key].as_str().unwrap());
            assert!(path.is_file(), "{name}: {} missing", path.display());
        }
    }
    // Caching every node costs far more than free textures; free textures skip the graphs.
    assert!(f(&by("all")["summary"]["ratio_to_lower_bound"]["median"]) > 1.0);
    assert_eq!(by("free")["summary"]["node_evaluations"].as_u64(), Some(0));
    assert!(by("none")["summary"]["node_evaluations"].as_u64().unwrap() > 0);
    // Replacing textures by their means is biased: further from the reference than `none`.
    let rel = |n: &str| f(&by(n)["summary"]["image_error"]["rel_mse"]);
    assert!(rel("free") > rel("none"), "free {} none {}", rel("free"), rel("none"));

    // `none` has no cache and performs no lookup; cached strategies look up and stay in budget.
    assert!(by("none")["summary"]["cache"].is_null());
    let none_stats: Value =
        serde_json::from_slice(&std::fs::read(out.join(by("none")["stats"].as_str().unwrap())).unwrap()).unwrap();
    let lookups: u64 = none_stats["graphs"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|g| g["nodes"].as_array().unwrap())
        .map(|n| n["lookups"].as_u64().unwrap())
        .sum();
    assert_eq!(lookups, 0);
    for n in ["outputs", "all"] {
        let c = &by(n)["summary"]["cache"];
        assert!(c["lookups"].as_u64().unwrap() > 0, "{n}");
        assert!(c["peak_bytes"].as_u64().unwrap() <= c["budget_bytes"].as_u64().unwrap(), "{n}");
        assert!(c["tile_hits"].as_u64().unwrap() + c["tile_misses"].as_u64().unwrap() > 0, "{n}");
    }
    assert!(
        by("all")["summary"]["cache"]["cached_nodes"].as_u64()
            > by("outputs")["summary"]["cache"]["cached_nodes"].as_u64()
    );

    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(md.contains("| none |") && md.contains("not-a-strategy"));
    check_report(&std::fs::read_to_string(out.join("report.html")).unwrap(), 4);
    // Only finished files: no work folder, no temporaries.
    for e in walk(&out) {
        let name = e.file_name().unwrap().to_string_lossy().into_owned();
        assert!(!name.starts_with('.'), "left behind: {}", e.display());
    }

    // A second run reuses the cached reference, and the same renders give the same errors.
    let out2 = dir.join("again");
    let r2 = quick_bench(&out2, &refs);
    let scene2 = &r2["scenes"][0];
    assert_eq!(scene2["reference"]["reused"], true);
    assert_eq!(scene2["reference"]["key"], scene["reference"]["key"]);
    let err2 = &scene2["runs"][0]["summary"]["image_error"];
    assert_eq!(err2, &by("none")["summary"]["image_error"]);
    let _ = std::fs::remove_dir_all(&dir);
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        }
        out.push(p);
    }
    out
}

/// The report parses as HTML, embeds its images and charts, and refers to nothing outside itself.
fn check_report(html: &str, strategies_ok: usize) {
    use scraper::{Html, Selector};
    // The parser does report errors (so an empty list below means something).
    assert!(!Html::parse_document("<p>a</div>").errors.is_empty());
    let doc = Html::parse_document(html);
    assert!(doc.errors.is_empty(), "HTML parse errors: {:?}", doc.errors);
    for needle in ["http:", "https:", "file:", "//cdn", "<script", "<link", "@import", "url("] {
        assert!(!html.contains(needle), "report contains '{needle}'");
    }
    let all = Selector::parse("*").unwrap();
    for el in doc.select(&all) {
        for (name, value) in el.value().attrs() {
            match name {
                "src" => {
                    assert!(value.starts_with("data:image/png;base64,"), "<{}> src={value:.60}", el.value().name())
                }
                "href" => assert!(value.starts_with('#'), "<{}> href={value}", el.value().name()),
                _ => {}
            }
        }
    }
    let imgs: Vec<_> = doc.select(&Selector::parse("img").unwrap()).collect();
    // Reference, footprint heat map, and an image and a ꟻLIP map per strategy that ran.
    assert_eq!(imgs.len(), 2 + 2 * strategies_ok);
    for img in &imgs {
        let data = &img.value().attr("src").unwrap()["data:image/png;base64,".len()..];
        assert!(data.len() > 100 && data.len() % 4 == 0, "truncated image data");
    }
    let svgs = doc.select(&Selector::parse("svg").unwrap()).count();
    // Time bars, level histograms (outputs, all) and cached-vs-evaluated bars (outputs, all).
    assert!(svgs >= 1 + 2 + 2, "only {svgs} charts");
    let h2: Vec<String> = doc.select(&Selector::parse("h2").unwrap()).map(|e| e.text().collect()).collect();
    assert!(h2.iter().any(|t| t.contains("rusted_metal")), "{h2:?}");
}

#[test]
fn bench_bad_input_is_a_clear_error_with_no_output() {
    let dir = temp_dir("bad");
    let cases: [(&[&str], &str); 5] = [
        (&["bench", "no-such-folder"], "no-such-folder"),
        (&["bench", "--quick", "--repeats", "0"], "repeats"),
        (&["bench", "--quick", "--strategies", "free"], "strategy"),
        (&["bench", "--quick", "-D", "res=8"], "--res"),
        (&["bench", "--quick", "--scenes", "nope"], "nope"),
    ];
    for (args, needle) in cases {
        let run = tessera().current_dir(&dir).args(args).args(["--out", "out"]).output().unwrap();
        assert!(!run.status.success(), "{args:?} should fail");
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(err.contains(needle) && !err.contains("panicked"), "{args:?}: {err}");
        assert!(!dir.join("out").exists(), "{args:?} left an output folder");
    }
    // Every requested strategy rejected by the renderer: the lower bound alone is not a success
    // (the results are still written, with each failure).
    let run = tessera()
        .current_dir(&dir)
        .args(["bench", "--quick", "--quiet", "--strategies", "not-a-strategy", "--out", "all_bad"])
        .output()
        .unwrap();
    assert!(!run.status.success(), "a bench whose every strategy failed should fail");
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("requested strategies") && !err.contains("panicked"), "{err}");
    assert!(dir.join("all_bad/results.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
