//! Line charts as SVG text (xtask stays free of image libraries; Markdown viewers show SVG).

/// One line: a name and its (x, y) points.
pub type Series = (String, Vec<(f64, f64)>);

const COLORS: [&str; 10] =
    ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"];

fn nice(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if v.abs() >= 1000.0 || v.abs() < 0.01 {
        format!("{v:.1e}")
    } else {
        format!("{}", (v * 1000.0).round() / 1000.0)
    }
}

/// A line chart of `series` (points sorted by x; a series with one point is drawn as a dot); `log_y`
/// plots log10(y) for positive y. Returns `None` when there is nothing to draw.
pub fn lines(title: &str, x_label: &str, y_label: &str, series: &[Series], log_y: bool) -> Option<String> {
    let ty = |y: f64| if log_y { y.log10() } else { y };
    let pts: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|(_, p)| p.iter().copied())
        .filter(|&(x, y)| x.is_finite() && y.is_finite() && (!log_y || y > 0.0))
        .map(|(x, y)| (x, ty(y)))
        .collect();
    if pts.is_empty() {
        return None;
    }
    let (mut x0, mut x1) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (mut y0, mut y1) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.1), b.max(p.1)));
    if x1 - x0 < 1e-12 {
        (x0, x1) = (x0 - 1.0, x1 + 1.0);
    }
    if y1 - y0 < 1e-12 {
        (y0, y1) = (y0 - 0.5 * y0.abs().max(1e-3), y1 + 0.5 * y1.abs().max(1e-3));
    }
    let pad = 0.05 * (y1 - y0);
    (y0, y1) = (y0 - pad, y1 + pad);
    let (w, h, left, right, top, bottom) = (720.0, 420.0, 70.0, 170.0, 30.0, 45.0);
    let px = |x: f64| left + (x - x0) / (x1 - x0) * (w - left - right);
    let py = |y: f64| top + (y1 - y) / (y1 - y0) * (h - top - bottom);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-family=\"sans-serif\" \
         font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"{}\" y=\"18\" text-anchor=\"middle\" font-size=\"14\">{}</text>\n",
        w / 2.0,
        escape(title)
    );
    for i in 0..=4 {
        let (fx, fy) = (x0 + (x1 - x0) * i as f64 / 4.0, y0 + (y1 - y0) * i as f64 / 4.0);
        let ylab = if log_y { nice(10f64.powf(fy)) } else { nice(fy) };
        s += &format!(
            "<line x1=\"{l}\" x2=\"{r}\" y1=\"{y}\" y2=\"{y}\" stroke=\"#ddd\"/><text x=\"{tx}\" y=\"{ty}\" \
             text-anchor=\"end\">{ylab}</text>\n<text x=\"{x}\" y=\"{bx}\" text-anchor=\"middle\">{xlab}</text>\n",
            l = left,
            r = w - right,
            y = py(fy),
            tx = left - 5.0,
            ty = py(fy) + 4.0,
            x = px(fx),
            bx = h - bottom + 16.0,
            xlab = nice(fx)
        );
    }
    s += &format!(
        "<rect x=\"{left}\" y=\"{top}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"black\"/>\n\
         <text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n\
         <text transform=\"translate(16 {}) rotate(-90)\" text-anchor=\"middle\">{}{}</text>\n",
        w - left - right,
        h - top - bottom,
        left + (w - left - right) / 2.0,
        h - 8.0,
        escape(x_label),
        top + (h - top - bottom) / 2.0,
        escape(y_label),
        if log_y { " (log)" } else { "" }
    );
    for (i, (name, p)) in series.iter().enumerate() {
        let color = COLORS[i % COLORS.len()];
        let p: Vec<(f64, f64)> = p
            .iter()
            .filter(|&&(x, y)| x.is_finite() && y.is_finite() && (!log_y || y > 0.0))
            .map(|&(x, y)| (px(x), py(ty(y))))
            .collect();
        if p.len() == 1 {
            s += &format!("<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"3\" fill=\"{color}\"/>\n", p[0].0, p[0].1);
        } else if !p.is_empty() {
            let d: Vec<String> = p.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
            s += &format!(
                "<polyline fill=\"none\" stroke=\"{color}\" stroke-width=\"1.5\" points=\"{}\"/>\n",
                d.join(" ")
            );
        }
        let ly = top + 10.0 + 16.0 * i as f64;
        s += &format!(
            "<line x1=\"{a}\" x2=\"{b}\" y1=\"{ly}\" y2=\"{ly}\" stroke=\"{color}\" stroke-width=\"2\"/>\
             <text x=\"{c}\" y=\"{t}\">{}</text>\n",
            escape(name),
            a = w - right + 10.0,
            b = w - right + 30.0,
            c = w - right + 35.0,
            t = ly + 4.0
        );
    }
    s += "</svg>\n";
    Some(s)
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_chart_has_a_line_per_series_and_a_legend() {
        let series =
            vec![("a<b".to_string(), vec![(1.0, 0.5), (2.0, 0.25), (3.0, 0.2)]), ("one".to_string(), vec![(2.0, 0.3)])];
        let svg = lines("t", "epoch", "loss", &series, true).unwrap();
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert_eq!(svg.matches("<polyline").count(), 1);
        assert_eq!(svg.matches("<circle").count(), 1);
        assert!(svg.contains("a&lt;b") && svg.contains("loss (log)"));
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
        assert_eq!(lines("t", "x", "y", &[("e".into(), vec![(1.0, f64::NAN)])], false), None);
    }
}
