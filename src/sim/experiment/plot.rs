//! A small SVG line-chart writer for the experiments' figures (seed 004 Figs.
//! 3–10): axes, ticks, labels, several series, an optional horizontal threshold
//! line and an optional logarithmic y axis. Pure: returns the document as a
//! `String`; the CLI writes it to a file.

use std::fmt::Write as _;

/// Colours given to series in order (colour-blind-safe Okabe–Ito palette).
const PALETTE: [&str; 8] = [
    "#0072b2", "#d55e00", "#009e73", "#cc79a7", "#e69f00", "#56b4e9", "#000000", "#f0e442",
];

/// Above this many points a series is thinned to a min/max envelope per pixel
/// column, which draws the same picture with a bounded file size.
const MAX_POINTS: usize = 4000;

/// One line of a chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// `(x, y)` points in drawing order; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// A series from a label and its points.
    pub fn new(label: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Series {
            label: label.into(),
            points,
        }
    }
}

/// A horizontal reference line (a detection threshold).
#[derive(Debug, Clone, PartialEq)]
pub struct Threshold {
    /// Its y value.
    pub y: f64,
    /// Its label, drawn at the right end of the line.
    pub label: String,
}

/// A line chart, drawn by [`Chart::to_svg`].
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// x-axis label.
    pub x_label: String,
    /// y-axis label.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
    /// Optional horizontal threshold line.
    pub threshold: Option<Threshold>,
    /// Logarithmic y axis (non-positive values are drawn at the axis floor).
    pub log_y: bool,
    /// Fixed y range; `None` fits the data (and the threshold).
    pub y_range: Option<(f64, f64)>,
    /// Width in pixels.
    pub width: f64,
    /// Height in pixels.
    pub height: f64,
}

/// Plot margins in pixels: left, right, top, bottom.
const MARGIN: (f64, f64, f64, f64) = (72.0, 24.0, 40.0, 52.0);

impl Chart {
    /// An empty 800 × 400 chart with a title and axis labels.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Chart {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            threshold: None,
            log_y: false,
            y_range: None,
            width: 800.0,
            height: 400.0,
        }
    }

    /// Adds a series.
    pub fn with_series(mut self, series: Series) -> Self {
        self.series.push(series);
        self
    }

    /// Sets the threshold line.
    pub fn with_threshold(mut self, y: f64, label: impl Into<String>) -> Self {
        self.threshold = Some(Threshold {
            y,
            label: label.into(),
        });
        self
    }

    /// Switches the y axis to log scale.
    pub fn with_log_y(mut self, log_y: bool) -> Self {
        self.log_y = log_y;
        self
    }

    /// Fixes the y range.
    pub fn with_y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y_range = Some((lo, hi));
        self
    }

    fn finite_points(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.series
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|(x, y)| x.is_finite() && y.is_finite() && (!self.log_y || *y > 0.0))
    }

    /// The x range of the data, widened when degenerate.
    fn x_range(&self) -> (f64, f64) {
        let (lo, hi) = self
            .finite_points()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (x, _)| {
                (lo.min(x), hi.max(x))
            });
        widen(lo, hi, false)
    }

    /// The y range of the axis in data units (for log axes, whole decades).
    fn y_axis(&self) -> (f64, f64) {
        if let Some((lo, hi)) = self.y_range
            && lo.is_finite()
            && hi.is_finite()
            && hi > lo
            && (!self.log_y || lo > 0.0)
        {
            return (lo, hi);
        }
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for (_, y) in self.finite_points() {
            lo = lo.min(y);
            hi = hi.max(y);
        }
        if let Some(th) = &self.threshold
            && th.y.is_finite()
            && (!self.log_y || th.y > 0.0)
        {
            lo = lo.min(th.y);
            hi = hi.max(th.y);
        }
        if self.log_y {
            let (lo, hi) = widen(lo, hi, true);
            (
                10f64.powf(lo.log10().floor()),
                10f64.powf(hi.log10().ceil().max(lo.log10().floor() + 1.0)),
            )
        } else {
            let (lo, hi) = widen(lo, hi, false);
            let step = nice_step((hi - lo) / 6.0);
            ((lo / step).floor() * step, (hi / step).ceil() * step)
        }
    }

    fn plot_box(&self) -> (f64, f64, f64, f64) {
        let (l, r, t, b) = MARGIN;
        (
            l,
            t,
            (self.width - l - r).max(1.0),
            (self.height - t - b).max(1.0),
        )
    }

    /// The axes' ranges and the plot box, computed once per drawing (the
    /// ranges scan every point).
    fn frame(&self) -> Frame {
        let (left, top, w, h) = self.plot_box();
        Frame {
            x: self.x_range(),
            y: self.y_axis(),
            log_y: self.log_y,
            left,
            top,
            w,
            h,
        }
    }

    /// Maps a data y value to the pixel row it is drawn at.
    pub fn y_to_px(&self, y: f64) -> f64 {
        self.frame().py(y)
    }

    /// Maps a data x value to the pixel column it is drawn at.
    pub fn x_to_px(&self, x: f64) -> f64 {
        self.frame().px(x)
    }

    /// Renders the chart as a standalone SVG document.
    pub fn to_svg(&self) -> String {
        let mut s = String::with_capacity(16 * 1024);
        let (w, h) = (self.width, self.height);
        let f = self.frame();
        let (left, top, pw, ph) = (f.left, f.top, f.w, f.h);
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#
        );
        let _ = writeln!(
            s,
            r#"<rect x="0" y="0" width="{w}" height="{h}" fill="white"/>"#
        );
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="22" text-anchor="middle" font-size="15">{}</text>"#,
            w / 2.0,
            escape(&self.title)
        );
        self.draw_x_axis(&mut s, &f);
        self.draw_y_axis(&mut s, &f);
        let _ = writeln!(
            s,
            r#"<rect x="{left:.2}" y="{top:.2}" width="{pw:.2}" height="{ph:.2}" fill="none" stroke="black"/>"#
        );
        let _ = writeln!(
            s,
            r#"<clipPath id="plot"><rect x="{left:.2}" y="{top:.2}" width="{pw:.2}" height="{ph:.2}"/></clipPath>"#
        );
        for (i, series) in self.series.iter().enumerate() {
            self.draw_series(&mut s, &f, series, PALETTE[i % PALETTE.len()]);
        }
        if let Some(th) = &self.threshold
            && th.y.is_finite()
        {
            let y = f.py(th.y);
            let _ = writeln!(
                s,
                r##"<line class="threshold" x1="{left:.2}" y1="{y:.2}" x2="{:.2}" y2="{y:.2}" stroke="#c00000" stroke-width="1.5" stroke-dasharray="6 4"/>"##,
                left + pw
            );
            let _ = writeln!(
                s,
                r##"<text x="{:.2}" y="{:.2}" text-anchor="end" fill="#c00000" stroke="white" stroke-width="3" paint-order="stroke">{}</text>"##,
                left + pw - 4.0,
                y - 4.0,
                escape(&th.label)
            );
        }
        self.draw_legend(&mut s);
        s.push_str("</svg>\n");
        s
    }

    fn draw_x_axis(&self, s: &mut String, f: &Frame) {
        let (lo, hi) = f.x;
        let (left, top, pw, ph) = (f.left, f.top, f.w, f.h);
        let step = nice_step((hi - lo) / 8.0);
        let mut v = (lo / step).ceil() * step;
        while v <= hi + step * 1e-9 {
            let x = f.px(v);
            let _ = writeln!(
                s,
                r##"<line x1="{x:.2}" y1="{top:.2}" x2="{x:.2}" y2="{:.2}" stroke="#e0e0e0"/>"##,
                top + ph
            );
            let _ = writeln!(
                s,
                r#"<text x="{x:.2}" y="{:.2}" text-anchor="middle">{}</text>"#,
                top + ph + 16.0,
                tick_label(v, step)
            );
            v += step;
        }
        let _ = writeln!(
            s,
            r#"<text x="{:.2}" y="{:.2}" text-anchor="middle">{}</text>"#,
            left + pw / 2.0,
            self.height - 12.0,
            escape(&self.x_label)
        );
    }

    fn draw_y_axis(&self, s: &mut String, f: &Frame) {
        let (lo, hi) = f.y;
        let (left, top, pw, ph) = (f.left, f.top, f.w, f.h);
        let ticks: Vec<(f64, String)> = if self.log_y {
            let (a, b) = (lo.log10().round() as i32, hi.log10().round() as i32);
            (a..=b).map(|e| (10f64.powi(e), format!("1e{e}"))).collect()
        } else {
            let step = nice_step((hi - lo) / 6.0);
            let mut out = Vec::new();
            let mut v = (lo / step).ceil() * step;
            while v <= hi + step * 1e-9 {
                out.push((v, tick_label(v, step)));
                v += step;
            }
            out
        };
        for (v, label) in ticks {
            let y = f.py(v);
            let _ = writeln!(
                s,
                r##"<line x1="{left:.2}" y1="{y:.2}" x2="{:.2}" y2="{y:.2}" stroke="#e0e0e0"/>"##,
                left + pw
            );
            let _ = writeln!(
                s,
                r#"<text x="{:.2}" y="{:.2}" text-anchor="end">{label}</text>"#,
                left - 6.0,
                y + 4.0
            );
        }
        let (cx, cy) = (16.0, top + ph / 2.0);
        let _ = writeln!(
            s,
            r#"<text x="{cx:.2}" y="{cy:.2}" text-anchor="middle" transform="rotate(-90 {cx:.2} {cy:.2})">{}</text>"#,
            escape(&self.y_label)
        );
    }

    fn draw_series(&self, s: &mut String, f: &Frame, series: &Series, colour: &str) {
        let (lo_y, _) = f.y;
        let points: Vec<(f64, f64)> = series
            .points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, y)| (x, if self.log_y { y.max(lo_y) } else { y }))
            .collect();
        let points = thin(&points, MAX_POINTS);
        let _ = write!(
            s,
            r#"<polyline fill="none" stroke="{colour}" stroke-width="1.2" clip-path="url(#plot)" points=""#
        );
        for (i, (x, y)) in points.iter().enumerate() {
            if i > 0 {
                s.push(' ');
            }
            let _ = write!(s, "{:.2},{:.2}", f.px(*x), f.py(*y));
        }
        s.push_str("\"/>\n");
    }

    fn draw_legend(&self, s: &mut String) {
        if self.series.len() < 2 {
            return;
        }
        let (left, top, pw, _) = self.plot_box();
        let longest = self
            .series
            .iter()
            .map(|x| x.label.chars().count())
            .max()
            .unwrap_or(0) as f64;
        let box_w = 34.0 + 7.0 * longest;
        let x0 = (left + pw - box_w - 8.0).max(left + 4.0);
        let y0 = top + 8.0;
        let _ = writeln!(
            s,
            r##"<rect x="{x0:.2}" y="{y0:.2}" width="{box_w:.2}" height="{:.2}" fill="white" fill-opacity="0.85" stroke="#999999"/>"##,
            8.0 + 16.0 * self.series.len() as f64
        );
        for (i, series) in self.series.iter().enumerate() {
            let y = y0 + 14.0 + 16.0 * i as f64;
            let _ = writeln!(
                s,
                r#"<line x1="{:.2}" y1="{:.2}" x2="{:.2}" y2="{:.2}" stroke="{}" stroke-width="2"/>"#,
                x0 + 6.0,
                y - 4.0,
                x0 + 26.0,
                y - 4.0,
                PALETTE[i % PALETTE.len()]
            );
            let _ = writeln!(
                s,
                r#"<text x="{:.2}" y="{y:.2}">{}</text>"#,
                x0 + 30.0,
                escape(&series.label)
            );
        }
    }
}

/// Where a chart's data lands on the page.
#[derive(Debug, Clone, Copy)]
struct Frame {
    x: (f64, f64),
    y: (f64, f64),
    log_y: bool,
    left: f64,
    top: f64,
    w: f64,
    h: f64,
}

impl Frame {
    fn px(&self, x: f64) -> f64 {
        let (lo, hi) = self.x;
        self.left + self.w * (x - lo) / (hi - lo)
    }

    fn py(&self, y: f64) -> f64 {
        let (lo, hi) = self.y;
        let frac = if self.log_y {
            (y.max(lo).log10() - lo.log10()) / (hi.log10() - lo.log10())
        } else {
            (y - lo) / (hi - lo)
        };
        self.top + self.h * (1.0 - frac.clamp(-0.02, 1.02))
    }
}

/// Widens a degenerate or empty range so it can be drawn.
fn widen(lo: f64, hi: f64, positive: bool) -> (f64, f64) {
    if !lo.is_finite() || !hi.is_finite() {
        return if positive { (1.0, 10.0) } else { (0.0, 1.0) };
    }
    if hi > lo {
        return (lo, hi);
    }
    if positive {
        (lo / 2.0, hi * 2.0)
    } else {
        let pad = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
        (lo - pad, hi + pad)
    }
}

/// The 1–2–5 step nearest above `raw`.
fn nice_step(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let nice = if f <= 1.0 {
        1.0
    } else if f <= 2.0 {
        2.0
    } else if f <= 5.0 {
        5.0
    } else {
        10.0
    };
    nice * mag
}

/// A tick label with as many decimals as the step needs.
fn tick_label(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    };
    let v = if v.abs() < step * 1e-9 { 0.0 } else { v };
    format!("{v:.decimals$}")
}

/// Keeps at most about `max` points: the first and last point of each bucket
/// plus its minimum and maximum, in x order, so peaks survive thinning.
fn thin(points: &[(f64, f64)], max: usize) -> Vec<(f64, f64)> {
    if points.len() <= max || max < 8 {
        return points.to_vec();
    }
    let buckets = max / 4;
    let per = points.len().div_ceil(buckets);
    let mut out = Vec::with_capacity(max);
    for chunk in points.chunks(per) {
        let (mut imin, mut imax) = (0, 0);
        for (i, p) in chunk.iter().enumerate() {
            if p.1 < chunk[imin].1 {
                imin = i;
            }
            if p.1 > chunk[imax].1 {
                imax = i;
            }
        }
        let mut idx = [0, imin, imax, chunk.len() - 1];
        idx.sort_unstable();
        let mut last = usize::MAX;
        for i in idx {
            if i != last {
                out.push(chunk[i]);
                last = i;
            }
        }
    }
    out
}

/// Escapes text for XML content and attributes.
fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks that every element is closed in order (a tiny XML well-formedness check).
    fn balanced(svg: &str) -> bool {
        let mut stack: Vec<String> = Vec::new();
        let mut rest = svg;
        while let Some(start) = rest.find('<') {
            let Some(end) = rest[start..].find('>') else {
                return false;
            };
            let tag = &rest[start + 1..start + end];
            rest = &rest[start + end + 1..];
            if let Some(name) = tag.strip_prefix('/') {
                if stack.pop().as_deref() != Some(name.trim()) {
                    return false;
                }
            } else if !tag.ends_with('/') {
                let name = tag.split_whitespace().next().unwrap_or("");
                stack.push(name.to_owned());
            }
        }
        stack.is_empty()
    }

    fn attr(element: &str, name: &str) -> f64 {
        let key = format!(" {name}=\"");
        let i = element.find(&key).unwrap() + key.len();
        element[i..i + element[i..].find('"').unwrap()]
            .parse()
            .unwrap()
    }

    fn chart() -> Chart {
        Chart::new("errors & λ <test>", "t, s", "error, m")
            .with_series(Series::new(
                "a",
                (0..100).map(|i| (i as f64, i as f64 * 0.3)).collect(),
            ))
            .with_series(Series::new(
                "b",
                (0..100)
                    .map(|i| (i as f64, 30.0 - i as f64 * 0.3))
                    .collect(),
            ))
            .with_series(Series::new("c", vec![(0.0, 5.0), (99.0, 5.0)]))
    }

    #[test]
    fn chart_is_well_formed_with_one_polyline_per_series() {
        let svg = chart().with_threshold(20.0, "T_D = 20").to_svg();
        assert!(svg.starts_with("<svg "));
        assert!(balanced(&svg), "{svg}");
        assert_eq!(svg.matches("<polyline").count(), 3);
        assert!(svg.contains("errors &amp; λ &lt;test&gt;"));
        // Each polyline carries all its points.
        let first = svg.split("<polyline").nth(1).unwrap();
        let points = &first[first.find("points=\"").unwrap() + 8..];
        let points = &points[..points.find('"').unwrap()];
        assert_eq!(points.split(' ').count(), 100);
    }

    #[test]
    fn threshold_line_sits_at_its_value_on_the_axis() {
        // Plot box: top 40, height 400 − 40 − 52 = 308; y in [0, 40] → 20 is mid-height.
        let svg = chart()
            .with_y_range(0.0, 40.0)
            .with_threshold(20.0, "T")
            .to_svg();
        let line = svg
            .lines()
            .find(|l| l.contains("class=\"threshold\""))
            .unwrap();
        assert!((attr(line, "y1") - (40.0 + 308.0 * 0.5)).abs() < 0.01);
        assert_eq!(attr(line, "y1"), attr(line, "y2"));
        assert!((attr(line, "x1") - 72.0).abs() < 1e-9);
        assert!((attr(line, "x2") - (800.0 - 24.0)).abs() < 1e-9);
    }

    #[test]
    fn log_axis_places_decades_evenly() {
        let c = Chart::new("λ", "t", "λ")
            .with_series(Series::new("λ", vec![(0.0, 0.5), (1.0, 50.0), (2.0, 0.0)]))
            .with_threshold(20.0, "T")
            .with_log_y(true);
        // Data 0.5..50 → axis 0.1..100: three decades over 308 px.
        let (y1, y10, y100) = (c.y_to_px(1.0), c.y_to_px(10.0), c.y_to_px(100.0));
        assert!((y1 - y10 - 308.0 / 3.0).abs() < 1e-9);
        assert!((y10 - y100 - 308.0 / 3.0).abs() < 1e-9);
        let expected = 40.0 + 308.0 * (1.0 - (20f64.log10() + 1.0) / 3.0);
        assert!((c.y_to_px(20.0) - expected).abs() < 1e-9);
        let svg = c.to_svg();
        assert!(balanced(&svg));
        for label in ["1e-1", "1e0", "1e1", "1e2"] {
            assert!(svg.contains(&format!(">{label}</text>")), "{label}");
        }
    }

    #[test]
    fn nice_steps_are_one_two_five() {
        assert_eq!(nice_step(0.7), 1.0);
        assert_eq!(nice_step(1.3), 2.0);
        assert_eq!(nice_step(3.0), 5.0);
        assert_eq!(nice_step(7.0), 10.0);
        assert!((nice_step(0.013) - 0.02).abs() < 1e-15);
        assert_eq!(tick_label(0.25, 0.05), "0.25");
        assert_eq!(tick_label(1200.0, 200.0), "1200");
    }

    #[test]
    fn thinning_keeps_extremes_and_bounds_size() {
        let mut points: Vec<(f64, f64)> = (0..100_000).map(|i| (i as f64, 0.0)).collect();
        points[54_321].1 = 9.0;
        points[7].1 = -3.0;
        let thinned = thin(&points, 400);
        assert!(thinned.len() <= 400);
        assert!(thinned.contains(&(54_321.0, 9.0)));
        assert!(thinned.contains(&(7.0, -3.0)));
        assert!(thinned.windows(2).all(|w| w[0].0 < w[1].0));
        assert_eq!(thinned.last(), Some(&(99_999.0, 0.0)));
    }
}
