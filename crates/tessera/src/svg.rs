//! Small hand-written SVG charts for the benchmark report: stacked horizontal bars with a
//! reference line, level histograms, cached-vs-evaluated split bars and predicted-vs-measured
//! scatter plots. Each function returns one `<svg>` element meant to be inlined in HTML (no
//! namespace URL, no external references, no scripts).

use std::fmt::Write;

/// Escapes text for HTML and SVG content and attribute values.
pub fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A number in at most 3 significant digits, with k/M/G suffixes for large counts.
pub fn short(v: f64) -> String {
    let a = v.abs();
    if !v.is_finite() {
        return "–".into();
    }
    let (x, suffix) = if a >= 1e9 {
        (v / 1e9, "G")
    } else if a >= 1e6 {
        (v / 1e6, "M")
    } else if a >= 1e4 {
        (v / 1e3, "k")
    } else {
        (v, "")
    };
    let ax = x.abs();
    let digits = if ax == 0.0 || ax >= 100.0 {
        0
    } else if ax >= 10.0 {
        1
    } else if ax >= 1.0 {
        2
    } else {
        (2 - ax.log10().floor() as i32).clamp(2, 6) as usize
    };
    let mut text = format!("{x:.digits$}");
    if ax < 1.0 && text.contains('.') {
        text = text.trim_end_matches('0').trim_end_matches('.').to_string();
    }
    format!("{text}{suffix}")
}

/// Tick positions: 1, 2 or 5 times a power of ten, covering [0, max].
fn linear_ticks(max: f64) -> Vec<f64> {
    if !(max > 0.0 && max.is_finite()) {
        return vec![0.0, 1.0];
    }
    let raw = max / 5.0;
    let p = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * p).find(|s| *s >= raw).unwrap_or(10.0 * p);
    let n = (max / step).ceil() as usize;
    (0..=n).map(|i| i as f64 * step).collect()
}

fn svg_open(w: f64, h: f64, label: &str) -> String {
    format!(
        "<svg class=\"chart\" width=\"{w:.0}\" height=\"{h:.0}\" viewBox=\"0 0 {w:.0} {h:.0}\" role=\"img\" aria-label=\"{}\">",
        esc(label)
    )
}

/// One coloured part of a bar.
pub struct Segment {
    /// Length in the chart's unit.
    pub value: f64,
    /// CSS colour.
    pub color: &'static str,
    /// Legend entry.
    pub label: &'static str,
}

/// One bar of [`stacked_bars`].
pub struct BarRow {
    /// Text left of the bar.
    pub label: String,
    /// Parts, drawn left to right.
    pub segments: Vec<Segment>,
    /// Spread of the bar's total (min, max) drawn as a whisker.
    pub whisker: Option<(f64, f64)>,
    /// Text right of the bar.
    pub note: String,
}

/// Horizontal stacked bars, one per row, with min–max whiskers and an optional dashed vertical
/// reference line (e.g. the free-texture lower bound).
pub fn stacked_bars(title: &str, rows: &[BarRow], reference: Option<(f64, &str)>, unit: &str) -> String {
    let (label_w, chart_w, note_w, row_h, top) = (120.0, 420.0, 150.0, 24.0, 34.0);
    let totals = rows.iter().map(|r| r.segments.iter().map(|s| s.value).sum::<f64>());
    let mut max = totals.fold(0.0f64, f64::max);
    for r in rows {
        if let Some((_, hi)) = r.whisker {
            max = max.max(hi);
        }
    }
    if let Some((v, _)) = reference {
        max = max.max(v);
    }
    let ticks = linear_ticks(max);
    let max = *ticks.last().unwrap_or(&1.0);
    let x = |v: f64| label_w + chart_w * (v / max).clamp(0.0, 1.0);
    let h = top + rows.len() as f64 * row_h + 30.0;
    let mut s = svg_open(label_w + chart_w + note_w, h, title);
    // Legend: one entry per distinct segment label, then the reference line.
    let mut legend: Vec<(&str, &str)> = Vec::new();
    for seg in rows.iter().flat_map(|r| &r.segments) {
        if !legend.iter().any(|(l, _)| *l == seg.label) {
            legend.push((seg.label, seg.color));
        }
    }
    let mut lx = label_w;
    for (label, color) in &legend {
        let _ = write!(s, "<rect x=\"{lx:.1}\" y=\"6\" width=\"10\" height=\"10\" fill=\"{color}\"/>");
        let _ = write!(s, "<text x=\"{:.1}\" y=\"15\" class=\"small\">{}</text>", lx + 14.0, esc(label));
        lx += 24.0 + 6.5 * label.len() as f64;
    }
    if let Some((_, name)) = reference {
        let _ = write!(
            s,
            "<line x1=\"{lx:.1}\" y1=\"11\" x2=\"{:.1}\" y2=\"11\" class=\"refline\"/><text x=\"{:.1}\" y=\"15\" class=\"small\">{}</text>",
            lx + 16.0,
            lx + 20.0,
            esc(name)
        );
    }
    // Grid and axis labels.
    let axis_y = top + rows.len() as f64 * row_h;
    for t in &ticks {
        let tx = x(*t);
        let _ = write!(s, "<line x1=\"{tx:.1}\" y1=\"{top:.1}\" x2=\"{tx:.1}\" y2=\"{axis_y:.1}\" class=\"grid\"/>");
        let _ = write!(
            s,
            "<text x=\"{tx:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"middle\">{}</text>",
            axis_y + 14.0,
            short(*t)
        );
    }
    let _ = write!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"middle\">{}</text>",
        label_w + chart_w / 2.0,
        axis_y + 27.0,
        esc(unit)
    );
    for (i, r) in rows.iter().enumerate() {
        let y = top + i as f64 * row_h;
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
            label_w - 6.0,
            y + row_h * 0.65,
            esc(&r.label)
        );
        let mut acc = 0.0;
        for seg in &r.segments {
            let (x0, x1) = (x(acc), x(acc + seg.value));
            if x1 > x0 {
                let _ = write!(
                    s,
                    "<rect x=\"{x0:.2}\" y=\"{:.1}\" width=\"{:.2}\" height=\"{:.1}\" fill=\"{}\"><title>{}: {} {}</title></rect>",
                    y + 4.0,
                    x1 - x0,
                    row_h - 8.0,
                    seg.color,
                    esc(seg.label),
                    short(seg.value),
                    esc(unit)
                );
            }
            acc += seg.value;
        }
        if let Some((lo, hi)) = r.whisker {
            let (x0, x1, ym) = (x(lo), x(hi), y + row_h / 2.0);
            let _ = write!(
                s,
                "<path d=\"M{x0:.1} {:.1}V{:.1}M{x0:.1} {ym:.1}H{x1:.1}M{x1:.1} {:.1}V{:.1}\" class=\"whisker\"/>",
                ym - 5.0,
                ym + 5.0,
                ym - 5.0,
                ym + 5.0
            );
        }
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" class=\"small\">{}</text>",
            label_w + chart_w + 6.0,
            y + row_h * 0.65,
            esc(&r.note)
        );
    }
    if let Some((v, _)) = reference {
        let rx = x(v);
        let _ = write!(
            s,
            "<line x1=\"{rx:.1}\" y1=\"{:.1}\" x2=\"{rx:.1}\" y2=\"{axis_y:.1}\" class=\"refline\"/>",
            top - 4.0
        );
    }
    s.push_str("</svg>");
    s
}

/// A small histogram of counts per integer bin (e.g. requests per mip level), over the shared
/// bin range `range` so that several histograms can be compared side by side.
pub fn histogram(title: &str, bins: &[(i64, f64)], range: (i64, i64), color: &str) -> String {
    let (w, h, left, bottom, top) = (200.0, 104.0, 8.0, 18.0, 18.0);
    let n = (range.1 - range.0 + 1).max(1) as f64;
    let bw = (w - 2.0 * left) / n;
    let max = bins.iter().map(|b| b.1).fold(0.0f64, f64::max).max(1e-300);
    let mut s = svg_open(w, h, title);
    let _ = write!(s, "<text x=\"{left}\" y=\"12\" class=\"small\">{}</text>", esc(&truncate(title, 34)));
    let base = h - bottom;
    for &(level, count) in bins {
        let bx = left + (level - range.0) as f64 * bw;
        let bh = (base - top) * count / max;
        let _ = write!(
            s,
            "<rect x=\"{bx:.2}\" y=\"{:.2}\" width=\"{:.2}\" height=\"{bh:.2}\" fill=\"{color}\"><title>level {level}: {} requests</title></rect>",
            base - bh,
            (bw - 1.0).max(0.5),
            short(count)
        );
    }
    let _ = write!(s, "<line x1=\"{left}\" y1=\"{base}\" x2=\"{:.1}\" y2=\"{base}\" class=\"axis\"/>", w - left);
    let every = ((n / 8.0).ceil() as i64).max(1);
    let mut level = range.0;
    while level <= range.1 {
        let tx = left + ((level - range.0) as f64 + 0.5) * bw;
        let _ = write!(
            s,
            "<text x=\"{tx:.1}\" y=\"{:.1}\" class=\"tiny\" text-anchor=\"middle\">{level}</text>",
            base + 11.0
        );
        level += every;
    }
    s.push_str("</svg>");
    s
}

/// One row per node: a full-width bar split into the share of values answered by the cache
/// (lookups) and the share computed by evaluation, with the counts beside it.
pub fn split_bars(title: &str, rows: &[(String, f64, f64)], evaluated_color: &str, cached_color: &str) -> String {
    let (label_w, bar_w, note_w, row_h, top) = (230.0, 260.0, 150.0, 16.0, 24.0);
    let h = top + rows.len() as f64 * row_h + 6.0;
    let mut s = svg_open(label_w + bar_w + note_w, h, title);
    let _ = write!(s, "<rect x=\"{label_w}\" y=\"4\" width=\"10\" height=\"10\" fill=\"{evaluated_color}\"/>");
    let _ = write!(s, "<text x=\"{}\" y=\"13\" class=\"small\">evaluated</text>", label_w + 14.0);
    let _ = write!(s, "<rect x=\"{}\" y=\"4\" width=\"10\" height=\"10\" fill=\"{cached_color}\"/>", label_w + 90.0);
    let _ = write!(s, "<text x=\"{}\" y=\"13\" class=\"small\">cache lookups</text>", label_w + 104.0);
    for (i, (name, evaluated, cached)) in rows.iter().enumerate() {
        let y = top + i as f64 * row_h;
        let total = evaluated + cached;
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"end\">{}</text>",
            label_w - 6.0,
            y + 11.0,
            esc(&truncate(name, 36))
        );
        let fe = if total > 0.0 { evaluated / total } else { 0.0 };
        let _ = write!(
            s,
            "<rect x=\"{label_w}\" y=\"{:.1}\" width=\"{:.2}\" height=\"{:.1}\" fill=\"{evaluated_color}\"><title>{}: {} evaluations</title></rect>",
            y + 2.0,
            bar_w * fe,
            row_h - 4.0,
            esc(name),
            short(*evaluated)
        );
        let _ = write!(
            s,
            "<rect x=\"{:.2}\" y=\"{:.1}\" width=\"{:.2}\" height=\"{:.1}\" fill=\"{cached_color}\"><title>{}: {} lookups</title></rect>",
            label_w + bar_w * fe,
            y + 2.0,
            if total > 0.0 { bar_w * (1.0 - fe) } else { 0.0 },
            row_h - 4.0,
            esc(name),
            short(*cached)
        );
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" class=\"small\">{} / {}</text>",
            label_w + bar_w + 6.0,
            y + 11.0,
            short(*evaluated),
            short(*cached)
        );
    }
    s.push_str("</svg>");
    s
}

/// Predicted (x) against measured (y), one labelled point each, with the line y = x. Axes are
/// logarithmic when every value is positive and they span more than a factor of 10.
pub fn scatter(title: &str, points: &[(String, f64, f64)], unit: &str) -> String {
    let (w, h, m) = (300.0, 280.0, 44.0);
    let vals: Vec<f64> = points.iter().flat_map(|p| [p.1, p.2]).filter(|v| v.is_finite()).collect();
    let lo = vals.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = vals.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let log = lo > 0.0 && hi / lo > 10.0;
    let (a, b) = if !lo.is_finite() {
        (0.0, 1.0)
    } else if log {
        (lo.log10().floor(), hi.log10().ceil().max(lo.log10().floor() + 1.0))
    } else {
        let top = *linear_ticks(hi.max(0.0) * 1.05).last().unwrap_or(&1.0);
        (lo.min(0.0), top.max(1e-300))
    };
    let t = |v: f64| if log { v.max(1e-300).log10() } else { v };
    let px = |v: f64| m + (w - 1.5 * m) * ((t(v) - a) / (b - a)).clamp(0.0, 1.0);
    let py = |v: f64| h - m - (h - 1.5 * m) * ((t(v) - a) / (b - a)).clamp(0.0, 1.0);
    let mut s = svg_open(w, h, title);
    let _ = write!(s, "<text x=\"{m}\" y=\"14\">{}</text>", esc(title));
    let ticks: Vec<f64> = if log {
        (a as i64..=b as i64).map(|e| 10f64.powi(e as i32)).collect()
    } else {
        linear_ticks(b).into_iter().filter(|v| *v >= a && *v <= b * (1.0 + 1e-9)).collect()
    };
    for tv in &ticks {
        let (tx, ty) = (px(*tv), py(*tv));
        let _ = write!(
            s,
            "<line x1=\"{tx:.1}\" y1=\"{:.1}\" x2=\"{tx:.1}\" y2=\"{:.1}\" class=\"grid\"/>",
            py(ticks[0]).max(m / 2.0),
            h - m
        );
        let _ = write!(s, "<line x1=\"{m}\" y1=\"{ty:.1}\" x2=\"{:.1}\" y2=\"{ty:.1}\" class=\"grid\"/>", w - m / 2.0);
        let _ = write!(
            s,
            "<text x=\"{tx:.1}\" y=\"{:.1}\" class=\"tiny\" text-anchor=\"middle\">{}</text>",
            h - m + 12.0,
            short(*tv)
        );
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" class=\"tiny\" text-anchor=\"end\">{}</text>",
            m - 3.0,
            ty + 3.0,
            short(*tv)
        );
    }
    let (d0, d1) = if log { (10f64.powf(a), 10f64.powf(b)) } else { (a, b) };
    let _ = write!(
        s,
        "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" class=\"refline\"><title>predicted = measured</title></line>",
        px(d0),
        py(d0),
        px(d1),
        py(d1)
    );
    let _ = write!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"middle\">predicted ({})</text>",
        m + (w - 1.5 * m) / 2.0,
        h - 8.0,
        esc(unit)
    );
    let _ = write!(
        s,
        "<text x=\"12\" y=\"{:.1}\" class=\"small\" text-anchor=\"middle\" transform=\"rotate(-90 12 {:.1})\">measured ({})</text>",
        h / 2.0,
        h / 2.0,
        esc(unit)
    );
    for (label, p, q) in points.iter().filter(|p| p.1.is_finite() && p.2.is_finite()) {
        let _ = write!(
            s,
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" class=\"point\"><title>{}: predicted {} measured {}</title></circle>",
            px(*p),
            py(*q),
            esc(label),
            short(*p),
            short(*q)
        );
        let _ =
            write!(s, "<text x=\"{:.1}\" y=\"{:.1}\" class=\"tiny\">{}</text>", px(*p) + 6.0, py(*q) - 4.0, esc(label));
    }
    s.push_str("</svg>");
    s
}

fn truncate(s: &str, n: usize) -> String {
    if s.chars().count() <= n {
        s.to_string()
    } else {
        let tail: String = s.chars().rev().take(n - 1).collect::<Vec<_>>().into_iter().rev().collect();
        format!("…{tail}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_markup() {
        assert_eq!(esc("a<b & \"c\"'"), "a&lt;b &amp; &quot;c&quot;&#39;");
    }

    #[test]
    fn ticks_cover_the_range_with_round_steps() {
        for max in [0.37, 1.0, 7.3, 123.0, 4.5e6] {
            let t = linear_ticks(max);
            assert_eq!(t[0], 0.0);
            assert!(*t.last().unwrap() >= max && t.len() <= 12, "{max}: {t:?}");
        }
    }

    #[test]
    fn short_numbers() {
        assert_eq!(short(1234567.0), "1.23M");
        assert_eq!(short(0.01234), "0.0123");
        assert_eq!(short(12.0), "12.0");
        assert_eq!(short(0.0), "0");
        assert_eq!(short(0.05), "0.05");
    }

    #[test]
    fn charts_are_single_svg_elements_without_external_references() {
        let rows = vec![BarRow {
            label: "none".into(),
            segments: vec![Segment { value: 1.5, color: "#123", label: "render" }],
            whisker: Some((1.4, 1.7)),
            note: "1.2× <bound>".into(),
        }];
        let charts = [
            stacked_bars("t", &rows, Some((1.0, "free")), "s"),
            histogram("n", &[(3, 10.0), (5, 2.0)], (0, 8), "#456"),
            split_bars("c", &[("a/b".into(), 3.0, 7.0), ("zero".into(), 0.0, 0.0)], "#111", "#222"),
            scatter("p", &[("x".into(), 10.0, 1000.0), ("y".into(), 2.0, 3.0)], "s"),
            scatter("empty", &[], "s"),
        ];
        for c in &charts {
            assert!(c.starts_with("<svg") && c.ends_with("</svg>") && c.matches("<svg").count() == 1);
            assert!(!c.contains("http") && !c.contains("NaN") && !c.contains("inf"), "{c}");
        }
        assert!(charts[0].contains("&lt;bound&gt;"));
    }
}
