//! The benchmark's readable outputs: `results.md` (tables) and `report.html` (one self-contained
//! page: images and charts embedded as `data:` URIs and inline SVG, no scripts, no references to
//! anything outside the file).

use crate::bench::{BenchResults, SceneResult, StrategyResult, LOWER_BOUND, PLAN_QUANTITIES};
use crate::svg::{self, esc, short};
use serde_json::Value;
use std::fmt::Write;

const RENDER_COLOR: &str = "#4e79a7";
const SETUP_COLOR: &str = "#f28e2b";
const PLAN_COLOR: &str = "#b07aa1";
const EVALUATED_COLOR: &str = "#e15759";
const CACHED_COLOR: &str = "#59a14f";
const HISTOGRAM_COLOR: &str = "#76b7b2";

/// Column headers of the per-scene tables.
const COLUMNS: [&str; 14] = [
    "strategy",
    "time s",
    "× lower bound",
    "render s",
    "setup s",
    "profile+plan s",
    "Msamples/s",
    "node evals",
    "lookups",
    "tile hits",
    "tiles filled",
    "peak MiB",
    "rel. MSE",
    "ꟻLIP",
];

fn strategy_name(r: &StrategyResult) -> String {
    if r.lower_bound {
        format!("{LOWER_BOUND} (lower bound)")
    } else {
        r.strategy.clone()
    }
}

fn with_spread(median: f64, min: f64, max: f64, repeats: u32) -> String {
    if repeats > 1 {
        format!("{} [{}–{}]", short(median), short(min), short(max))
    } else {
        short(median)
    }
}

/// The table cells of one strategy (plain text), or its error.
fn cells(r: &StrategyResult) -> Result<Vec<String>, String> {
    let Some(s) = &r.summary else {
        return Err(r.error.clone().unwrap_or_else(|| "no successful run".into()));
    };
    let n = s.runs_ok;
    let ratio =
        s.ratio_to_lower_bound.map_or("–".to_string(), |q| with_spread(q.median, q.min, q.max, n)).replace('[', "[×");
    let cache = s.cache.as_ref();
    let c = |f: fn(&render::stats::CacheTotals) -> u64| cache.map_or("–".to_string(), |c| short(f(&c.totals) as f64));
    let err = s.image_error;
    Ok(vec![
        strategy_name(r),
        with_spread(s.time_s.median, s.time_s.min, s.time_s.max, n),
        if r.lower_bound { "1".into() } else { ratio },
        short(s.phases.render_s),
        short(s.phases.cache_setup_s),
        short(s.phases.profile_s + s.phases.plan_s),
        short(s.samples_per_s / 1e6),
        short(s.node_evaluations as f64),
        c(|c| c.lookups),
        c(|c| c.tile_hits),
        c(|c| c.tiles_filled),
        cache.map_or("–".to_string(), |c| format!("{:.1}", c.totals.peak_bytes as f64 / 1048576.0)),
        err.map_or("–".to_string(), |e| format!("{:.3e}", e.rel_mse)),
        err.map_or("–".to_string(), |e| format!("{:.4}", e.flip)),
    ])
}

fn settings_line(r: &BenchResults) -> String {
    let s = &r.settings;
    format!(
        "Suite {}; {}×{} pixels (res {}), {} spp, seed {}, {} repeat(s) (median [min–max]); references {} spp (seed {}); budget {} MiB; {} threads; tessera {}.",
        s.suite,
        s.res,
        s.res,
        s.res,
        s.spp,
        s.seed,
        s.repeats,
        s.ref_spp,
        s.ref_seed,
        s.budget_mb,
        s.threads.map_or("all".to_string(), |t| t.to_string()),
        r.tessera_version
    )
}

const TIME_NOTE: &str = "Time = profile + plan + cache setup + render (what the user waits for, less loading and \
writing). × lower bound = that time over the free-texture render's in the same repeat. Counters are those of the \
median run. Image error against the reference: relative MSE on linear radiance, mean LDR-ꟻLIP on the sRGB images.";

fn md_escape(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// `results.md`.
pub fn markdown(r: &BenchResults) -> String {
    let mut m = String::new();
    let _ = writeln!(m, "# tessera bench\n\n{}\n\n{TIME_NOTE}\n", settings_line(r));
    for s in &r.scenes {
        let size = match (s.width, s.height) {
            (Some(w), Some(h)) => format!(" ({w}×{h})"),
            _ => String::new(),
        };
        let _ = writeln!(m, "## {}{size}\n", s.name);
        if let Some(e) = &s.error {
            let _ = writeln!(m, "Error: {}\n", md_escape(e));
            continue;
        }
        let _ = writeln!(m, "| {} |", COLUMNS.join(" | "));
        let _ = writeln!(m, "|{}", "---|".repeat(COLUMNS.len()));
        for run in &s.runs {
            match cells(run) {
                Ok(c) => {
                    let _ = writeln!(m, "| {} |", c.iter().map(|x| md_escape(x)).collect::<Vec<_>>().join(" | "));
                }
                Err(e) => {
                    let rest = vec!["–"; COLUMNS.len() - 2].join(" | ");
                    let _ = writeln!(m, "| {} | error: {} | {rest} |", md_escape(&strategy_name(run)), md_escape(&e));
                }
            }
        }
        let _ = writeln!(m);
    }
    let plans = plan_rows(r);
    if !plans.is_empty() {
        let _ = writeln!(m, "## Predicted vs measured\n");
        let _ = writeln!(m, "| scene | strategy | quantity | predicted | measured | predicted / measured |");
        let _ = writeln!(m, "|---|---|---|---|---|---|");
        for (scene, strategy, q, p, me) in plans {
            let ratio = if me > 0.0 { format!("{:.2}", p / me) } else { "–".into() };
            let _ =
                writeln!(m, "| {scene} | {} | {q} | {} | {} | {ratio} |", md_escape(&strategy), short(p), short(me));
        }
    }
    m
}

/// (scene, strategy, quantity, predicted, measured) for every run that had a plan.
fn plan_rows(r: &BenchResults) -> Vec<(String, String, &'static str, f64, f64)> {
    let mut rows = Vec::new();
    for s in &r.scenes {
        for run in &s.runs {
            let Some(plan) = run.summary.as_ref().and_then(|x| x.plan.as_ref()) else { continue };
            for q in PLAN_QUANTITIES {
                if let (Some(p), Some(me)) = (plan.predicted.get(q), plan.measured.get(q)) {
                    rows.push((s.name.clone(), run.strategy.clone(), q, *p, *me));
                }
            }
        }
    }
    rows
}

// ---------------------------------------------------------------------------------------------
// HTML
// ---------------------------------------------------------------------------------------------

const STYLE: &str = "
body { font: 14px/1.45 system-ui, sans-serif; margin: 24px auto; max-width: 1400px; padding: 0 16px; color: #222; }
h1 { margin-bottom: 4px; } h2 { border-bottom: 1px solid #ccc; margin-top: 40px; } h3 { margin: 22px 0 8px; }
table { border-collapse: collapse; font-size: 13px; } td, th { border: 1px solid #ddd; padding: 3px 7px; }
th { background: #f3f3f3; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
td.err, p.err { color: #b00; } tr.bound td { background: #f7f7ff; }
.grid { display: flex; flex-wrap: wrap; gap: 14px; align-items: flex-start; }
figure { margin: 0; } figcaption { font-size: 12px; color: #444; max-width: 560px; }
img.px { image-rendering: pixelated; border: 1px solid #ccc; }
svg.chart { font: 12px system-ui, sans-serif; background: #fff; }
svg .small { font-size: 11px; } svg .tiny { font-size: 9px; fill: #555; }
svg .grid { stroke: #e4e4e4; } svg .axis { stroke: #888; }
svg .refline { stroke: #222; stroke-dasharray: 5 3; stroke-width: 1.5; }
svg .whisker { stroke: #222; fill: none; } svg .point { fill: #4e79a7; stroke: #fff; }
details { margin: 8px 0; } summary { cursor: pointer; font-weight: 600; }
p.note { color: #555; max-width: 900px; }
";

/// Standard base64 (RFC 4648) with padding.
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// The width of a PNG, from its IHDR chunk.
fn png_width(png: &[u8]) -> Option<u64> {
    let b: [u8; 4] = png.get(16..20)?.try_into().ok()?;
    Some(u32::from_be_bytes(b) as u64)
}

/// Integer magnification that shows an image of `width` pixels at about 256 pixels or more.
fn magnification(width: Option<u64>) -> u64 {
    width.filter(|w| *w > 0).map_or(1, |w| (256 / w).max(1))
}

/// An `<img>` with the PNG embedded, shown `scale` times its size (at most 1400 pixels wide).
fn png_img(png: &[u8], alt: &str, scale: u64) -> String {
    let w = png_width(png).map_or(String::new(), |w| format!(" width=\"{}\"", (w * scale).min(1400)));
    format!("<img class=\"px\" alt=\"{}\"{w} src=\"data:image/png;base64,{}\">", esc(alt), base64(png))
}

/// `report.html`.
pub fn html(r: &BenchResults) -> String {
    let mut h = String::new();
    let _ = writeln!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>tessera bench</title>\n<style>{STYLE}</style>\n</head>\n<body>"
    );
    let _ = writeln!(
        h,
        "<h1>tessera bench</h1>\n<p>{}</p>\n<p class=\"note\">{}</p>",
        esc(&settings_line(r)),
        esc(TIME_NOTE)
    );
    overview(&mut h, r);
    for s in &r.scenes {
        scene_section(&mut h, s, r.settings.repeats);
    }
    predicted_section(&mut h, r);
    h.push_str("</body>\n</html>\n");
    h
}

fn anchor(name: &str) -> String {
    format!("scene-{}", name.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '-' }).collect::<String>())
}

/// A scene × strategy matrix of times relative to the lower bound.
fn overview(h: &mut String, r: &BenchResults) {
    let mut strategies: Vec<&str> = Vec::new();
    for run in r.scenes.iter().flat_map(|s| &s.runs).filter(|x| !x.lower_bound) {
        if !strategies.contains(&run.strategy.as_str()) {
            strategies.push(&run.strategy);
        }
    }
    let _ = write!(h, "<h2>Overview: time over the free-texture lower bound (median)</h2>\n<table><tr><th>scene</th>");
    for s in &strategies {
        let _ = write!(h, "<th>{}</th>", esc(s));
    }
    let _ = writeln!(h, "<th>lower bound s</th></tr>");
    for s in &r.scenes {
        let _ = write!(h, "<tr><td><a href=\"#{}\">{}</a></td>", anchor(&s.name), esc(&s.name));
        for name in &strategies {
            let run = s.runs.iter().find(|x| !x.lower_bound && x.strategy == *name);
            match run.and_then(|x| x.summary.as_ref()) {
                Some(sum) => {
                    let v = sum.ratio_to_lower_bound.map_or("–".into(), |q| format!("×{}", short(q.median)));
                    let _ = write!(h, "<td class=\"num\">{v}</td>");
                }
                None => {
                    let msg = run.and_then(|x| x.error.clone()).or_else(|| s.error.clone()).unwrap_or_default();
                    let _ = write!(h, "<td class=\"err\" title=\"{}\">error</td>", esc(&msg));
                }
            }
        }
        let bound = s.runs.iter().find(|x| x.lower_bound).and_then(|x| x.summary.as_ref());
        let _ = writeln!(h, "<td class=\"num\">{}</td></tr>", bound.map_or("–".into(), |b| short(b.time_s.median)));
    }
    h.push_str("</table>\n");
}

fn scene_section(h: &mut String, s: &SceneResult, repeats: u32) {
    let _ = write!(h, "<h2 id=\"{}\">{}</h2>\n<p>{}", anchor(&s.name), esc(&s.name), esc(&s.file));
    if let (Some(w), Some(hh)) = (s.width, s.height) {
        let _ = write!(h, ", {w}×{hh} pixels");
    }
    if let Some(rf) = &s.reference {
        let how = if rf.reused { "reused from the reference cache" } else { "rendered for this benchmark" };
        let _ = write!(h, "; reference {} spp, {how} (key {})", rf.spp, esc(&rf.key));
    }
    h.push_str(".</p>\n");
    if let Some(e) = &s.error {
        let _ = writeln!(h, "<p class=\"err\">Error: {}</p>", esc(e));
        return;
    }
    // Table.
    h.push_str("<table><tr>");
    for c in COLUMNS {
        let _ = write!(h, "<th>{}</th>", esc(c));
    }
    h.push_str("</tr>\n");
    for run in &s.runs {
        let class = if run.lower_bound { " class=\"bound\"" } else { "" };
        match cells(run) {
            Ok(c) => {
                let _ = write!(h, "<tr{class}><td>{}</td>", esc(&c[0]));
                for x in &c[1..] {
                    let _ = write!(h, "<td class=\"num\">{}</td>", esc(x));
                }
                h.push_str("</tr>\n");
            }
            Err(e) => {
                let _ = writeln!(
                    h,
                    "<tr{class}><td>{}</td><td class=\"err\" colspan=\"{}\">error: {}</td></tr>",
                    esc(&strategy_name(run)),
                    COLUMNS.len() - 1,
                    esc(&e)
                );
            }
        }
    }
    h.push_str("</table>\n");
    time_chart(h, s, repeats);
    images(h, s);
    level_histograms(h, s);
    cached_vs_evaluated(h, s);
}

fn time_chart(h: &mut String, s: &SceneResult, repeats: u32) {
    let bound = s.runs.iter().find(|x| x.lower_bound).and_then(|x| x.summary.as_ref()).map(|b| b.time_s.median);
    let rows: Vec<svg::BarRow> = s
        .runs
        .iter()
        .map(|run| match &run.summary {
            Some(sum) => svg::BarRow {
                label: strategy_name(run),
                segments: vec![
                    svg::Segment {
                        value: sum.phases.profile_s + sum.phases.plan_s,
                        color: PLAN_COLOR,
                        label: "profile + plan",
                    },
                    svg::Segment { value: sum.phases.cache_setup_s, color: SETUP_COLOR, label: "cache setup" },
                    svg::Segment { value: sum.phases.render_s, color: RENDER_COLOR, label: "render" },
                ],
                whisker: (repeats > 1).then_some((sum.time_s.min, sum.time_s.max)),
                note: match (run.lower_bound, sum.ratio_to_lower_bound) {
                    (true, _) => format!("{} s", short(sum.time_s.median)),
                    (false, Some(q)) => format!("{} s, ×{}", short(sum.time_s.median), short(q.median)),
                    (false, None) => format!("{} s", short(sum.time_s.median)),
                },
            },
            None => svg::BarRow { label: strategy_name(run), segments: vec![], whisker: None, note: "error".into() },
        })
        .collect();
    let _ = writeln!(h, "<h3>Time per strategy</h3>");
    h.push_str(&svg::stacked_bars(
        &format!("{}: time per strategy", s.name),
        &rows,
        bound.map(|b| (b, "free-texture lower bound")),
        "seconds (median phases; whisker: min–max of the total)",
    ));
    h.push('\n');
}

fn images(h: &mut String, s: &SceneResult) {
    let scale = magnification(s.width);
    let _ = writeln!(h, "<h3>Images</h3>\n<div class=\"grid\">");
    if let Some(png) = &s.reference_png {
        let spp = s.reference.as_ref().map_or(0, |r| r.spp);
        let _ = writeln!(
            h,
            "<figure>{}<figcaption>reference, {spp} spp</figcaption></figure>",
            png_img(png, "reference", scale)
        );
    }
    if let Some(png) = &s.footprint_png {
        let _ = writeln!(
            h,
            "<figure>{}<figcaption>footprint LOD heat map of the reference (bounces 1, 2, 3; grey: no vertex)</figcaption></figure>",
            png_img(png, "footprint heat map", (scale / 2).max(1))
        );
    }
    h.push_str("</div>\n<div class=\"grid\">\n");
    for run in &s.runs {
        let (Some(png), Some(sum)) = (&run.assets.png, &run.summary) else { continue };
        let name = strategy_name(run);
        let _ = write!(h, "<figure>{}", png_img(png, &name, scale));
        if let Some(f) = &run.assets.flip_png {
            let _ = write!(h, " {}", png_img(f, &format!("{name}: ꟻLIP error map"), scale));
        }
        let err =
            sum.image_error.map_or(String::new(), |e| format!(": rel. MSE {:.3e}, ꟻLIP {:.4}", e.rel_mse, e.flip));
        let _ = writeln!(
            h,
            "<figcaption>{}{} (left: image; right: ꟻLIP error against the reference)</figcaption></figure>",
            esc(&name),
            esc(&err)
        );
    }
    h.push_str("</div>\n");
}

/// Per cached node: (name, [(level, requests)]) from a run's stats JSON.
fn node_levels(stats: &Value) -> Vec<(String, Vec<(i64, f64)>)> {
    let Some(nodes) = stats["cache"]["nodes"].as_array() else { return Vec::new() };
    nodes
        .iter()
        .map(|n| {
            let name = n["name"].as_str().unwrap_or("?").to_string();
            let levels = n["levels"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|l| Some((l["level"].as_i64()?, l["requests"].as_f64()?)))
                .filter(|(_, r)| *r > 0.0)
                .collect();
            (name, levels)
        })
        .collect()
}

fn level_histograms(h: &mut String, s: &SceneResult) {
    let mut first = true;
    for run in &s.runs {
        let Some(stats) = &run.assets.stats else { continue };
        let nodes = node_levels(stats);
        if nodes.is_empty() {
            continue;
        }
        if first {
            let _ = writeln!(h, "<h3>Requested levels per cached node</h3>");
        }
        let lo = nodes.iter().flat_map(|n| n.1.iter().map(|l| l.0)).min().unwrap_or(0);
        let hi = nodes.iter().flat_map(|n| n.1.iter().map(|l| l.0)).max().unwrap_or(0);
        let _ = write!(
            h,
            "<details{}><summary>{}: {} cached nodes, levels {lo}–{hi} (0 = finest)</summary>\n<div class=\"grid\">",
            if first { " open" } else { "" },
            esc(&strategy_name(run)),
            nodes.len()
        );
        for (name, levels) in &nodes {
            h.push_str(&svg::histogram(name, levels, (lo, hi), HISTOGRAM_COLOR));
        }
        h.push_str("</div></details>\n");
        first = false;
    }
}

fn cached_vs_evaluated(h: &mut String, s: &SceneResult) {
    let mut first = true;
    for run in &s.runs {
        let Some(stats) = &run.assets.stats else { continue };
        if !stats["cache"].is_object() {
            continue;
        }
        let rows: Vec<(String, f64, f64)> = stats["graphs"]
            .as_array()
            .into_iter()
            .flatten()
            .flat_map(|g| g["nodes"].as_array().into_iter().flatten())
            .filter_map(|n| {
                let e = n["evaluations"].as_f64().unwrap_or(0.0);
                let l = n["lookups"].as_f64().unwrap_or(0.0);
                (e + l > 0.0).then(|| (n["name"].as_str().unwrap_or("?").to_string(), e, l))
            })
            .collect();
        if rows.is_empty() {
            continue;
        }
        if first {
            let _ = writeln!(h, "<h3>Cached vs evaluated per node</h3>");
        }
        let _ = writeln!(
            h,
            "<details{}><summary>{}: {} nodes (evaluations include tile fills)</summary>",
            if first { " open" } else { "" },
            esc(&strategy_name(run)),
            rows.len()
        );
        h.push_str(&svg::split_bars(
            &format!("{}: cached vs evaluated", run.strategy),
            &rows,
            EVALUATED_COLOR,
            CACHED_COLOR,
        ));
        h.push_str("</details>\n");
        first = false;
    }
}

fn predicted_section(h: &mut String, r: &BenchResults) {
    let _ = writeln!(h, "<h2 id=\"predicted\">Predicted vs measured</h2>");
    let rows = plan_rows(r);
    if rows.is_empty() {
        h.push_str(
            "<p class=\"note\">No run used a model: a strategy that plans (<code>auto</code>) writes a \
             <code>plan</code> with its predictions into the stats JSON, and none of these runs did.</p>\n",
        );
        return;
    }
    h.push_str("<div class=\"grid\">\n");
    let mut all_zero = Vec::new();
    for q in PLAN_QUANTITIES {
        let points: Vec<(String, f64, f64)> = rows
            .iter()
            .filter(|x| x.2 == q)
            .map(|(scene, strategy, _, p, m)| {
                let label = if strategy == "auto" { scene.clone() } else { format!("{scene} {strategy}") };
                (label, *p, *m)
            })
            .collect();
        if points.is_empty() {
            continue;
        }
        if points.iter().all(|p| p.1 == 0.0 && p.2 == 0.0) {
            all_zero.push(q);
            continue;
        }
        let unit = match q {
            "render_s" => "s",
            "peak_bytes" => "bytes",
            _ => "count",
        };
        h.push_str(&svg::scatter(q, &points, unit));
        h.push('\n');
    }
    h.push_str("</div>\n");
    if !all_zero.is_empty() {
        let _ = writeln!(h, "<p class=\"note\">Predicted and measured 0 in every run: {}.</p>", all_zero.join(", "));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        for (i, o) in
            [("", ""), ("f", "Zg=="), ("fo", "Zm8="), ("foo", "Zm9v"), ("foob", "Zm9vYg=="), ("fooba", "Zm9vYmE=")]
        {
            assert_eq!(base64(i.as_bytes()), o);
        }
        assert_eq!(base64(&[0xff, 0xfe, 0x00]), "//4A");
    }
}
