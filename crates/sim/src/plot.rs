//! SVG line charts, drawn by `plotters`' SVG backend: axes, ticks, labels, several
//! series with a legend, an optional horizontal threshold line and an optional
//! logarithmic y axis. They draw the experiments' figures ([`crate::experiment`],
//! e.g. seed 004 Figs. 3–10) and `navguard loadgen --ramp`'s curve; nothing before
//! `sim` in the flow plots. Pure: returns the document as a `String`; the CLI writes
//! it to a file.
//!
//! What this module adds to `plotters`: the axis ranges (fitted to the data and
//! the threshold, 1–2–5 ticks, whole decades on a log axis), the thinning of long
//! series, and the clamping of out-of-range values to the axis. `plotters` works
//! in whole pixels, so drawn coordinates are within a pixel of
//! [`Chart::x_to_px`]/[`Chart::y_to_px`]. Text is written as SVG `<text>`
//! (the crate's `ttf`/`ab_glyph` features are off): no system fonts are read;
//! label sizes for layout are estimated.

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Colours given to series in order (colour-blind-safe Okabe–Ito palette).
const PALETTE: [RGBColor; 8] = [
    RGBColor(0x00, 0x72, 0xb2),
    RGBColor(0xd5, 0x5e, 0x00),
    RGBColor(0x00, 0x9e, 0x73),
    RGBColor(0xcc, 0x79, 0xa7),
    RGBColor(0xe6, 0x9f, 0x00),
    RGBColor(0x56, 0xb4, 0xe9),
    RGBColor(0x00, 0x00, 0x00),
    RGBColor(0xf0, 0xe4, 0x42),
];

/// The threshold line's colour.
const THRESHOLD_COLOUR: RGBColor = RGBColor(0xc0, 0x00, 0x00);
/// Grid lines.
const GRID_COLOUR: RGBColor = RGBColor(0xe0, 0xe0, 0xe0);

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
    /// Shaded x intervals `(from, to)` behind the series (e.g. GNSS outages).
    pub bands: Vec<(f64, f64)>,
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
            bands: Vec::new(),
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

    /// Shades the x intervals `bands` behind the series.
    pub fn with_bands(mut self, bands: Vec<(f64, f64)>) -> Self {
        self.bands = bands;
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
        let mut svg = String::with_capacity(16 * 1024);
        if let Err(e) = self.draw(&mut svg) {
            // Drawing into a String cannot fail on I/O; keep whatever was drawn.
            svg.push_str(&format!("<!-- plotters: {e} -->\n"));
        }
        svg
    }

    /// Draws the chart into `svg` with `plotters`: title, axes, ticks, series,
    /// threshold and legend, in that order.
    fn draw(&self, svg: &mut String) -> Result<(), String> {
        let f = self.frame();
        let (w, h) = (self.width.max(1.0) as u32, self.height.max(1.0) as u32);
        let root = SVGBackend::with_string(svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let title = ("sans-serif", 15)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center));
        root.draw_text(&self.title, &title, ((w / 2) as i32, 20))
            .map_err(|e| e.to_string())?;

        let axes = self.axes(&f);
        let (left, right, top, bottom) = (
            f.left,
            self.width - f.left - f.w,
            f.top,
            self.height - f.top - f.h,
        );
        let mut chart = ChartBuilder::on(&root)
            .margin_top(top as u32)
            .margin_right(right.max(0.0) as u32)
            .x_label_area_size(bottom.max(0.0) as u32)
            .y_label_area_size(left as u32)
            .build_cartesian_2d(axes.x.0..axes.x.1, axes.y.0..axes.y.1)
            .map_err(|e| e.to_string())?;
        // The mesh draws the axes and their descriptions; the ticks are ours (1–2–5
        // steps, decades on a log axis), as plotters' own key points cannot be
        // bound to its f64 formatter.
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(0)
            .y_labels(0)
            .axis_style(BLACK)
            .axis_desc_style(("sans-serif", 12))
            .x_desc(self.x_label.as_str())
            .y_desc(self.y_label.as_str())
            .draw()
            .map_err(|e| e.to_string())?;
        self.draw_ticks(&root, &mut chart, &f, &axes)?;
        let band = RGBColor(0xee, 0xee, 0xee).filled();
        for &(from, to) in &self.bands {
            let (from, to) = (from.max(axes.x.0), to.min(axes.x.1));
            if from < to {
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(from, axes.y.0), (to, axes.y.1)],
                        band,
                    )))
                    .map_err(|e| e.to_string())?;
            }
        }
        self.draw_series(&mut chart, &f, &axes)?;
        self.draw_threshold(&root, &mut chart, &f, &axes)?;
        if self.series.len() >= 2 {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(0x99, 0x99, 0x99))
                .label_font(("sans-serif", 12))
                .draw()
                .map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())
    }

    /// The plotted axes: a log axis is drawn as a linear axis over log10(y),
    /// ticked at whole decades.
    fn axes(&self, f: &Frame) -> Axes {
        let (x_lo, x_hi) = f.x;
        let (y_lo, y_hi) = (self.axis_y(f.y.0), self.axis_y(f.y.1));
        let y_step = if self.log_y {
            1.0
        } else {
            nice_step((y_hi - y_lo) / 6.0)
        };
        Axes {
            x: (x_lo, x_hi),
            y: (y_lo, y_hi),
            x_step: nice_step((x_hi - x_lo) / 8.0),
            y_step,
        }
    }

    /// A data y value in the plotted (possibly log10) coordinate.
    fn axis_y(&self, y: f64) -> f64 {
        if self.log_y { y.log10() } else { y }
    }

    /// Grid lines and tick labels on both axes.
    fn draw_ticks(
        &self,
        root: &Root<'_>,
        chart: &mut Plot<'_, '_>,
        f: &Frame,
        a: &Axes,
    ) -> Result<(), String> {
        let grid = |from: (f64, f64), to: (f64, f64)| PathElement::new([from, to], GRID_COLOUR);
        let tick_font = ("sans-serif", 12).into_font().color(&BLACK);
        let below = tick_font.pos(Pos::new(HPos::Center, VPos::Top));
        for v in ticks(a.x.0, a.x.1, a.x_step) {
            chart
                .draw_series([grid((v, a.y.0), (v, a.y.1))])
                .map_err(|e| e.to_string())?;
            let at = (f.px(v) as i32, (f.top + f.h + 6.0) as i32);
            root.draw_text(&tick_label(v, a.x_step), &below, at)
                .map_err(|e| e.to_string())?;
        }
        let left_of = tick_font.pos(Pos::new(HPos::Right, VPos::Center));
        for v in ticks(a.y.0, a.y.1, a.y_step) {
            chart
                .draw_series([grid((a.x.0, v), (a.x.1, v))])
                .map_err(|e| e.to_string())?;
            let (label, y) = if self.log_y {
                (format!("1e{}", v.round() as i32), 10f64.powf(v))
            } else {
                (tick_label(v, a.y_step), v)
            };
            let at = ((f.left - 6.0) as i32, f.py(y) as i32);
            root.draw_text(&label, &left_of, at)
                .map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    /// Every series as a thinned line, clamped to the axis, with its legend entry.
    fn draw_series(&self, chart: &mut Plot<'_, '_>, f: &Frame, a: &Axes) -> Result<(), String> {
        for (i, series) in self.series.iter().enumerate() {
            let colour = PALETTE[i % PALETTE.len()];
            let points: Vec<(f64, f64)> = series
                .points
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .map(|(x, y)| (x, self.axis_y(if self.log_y { y.max(f.y.0) } else { y })))
                .map(|(x, y)| (x, y.clamp(a.y.0, a.y.1)))
                .collect();
            chart
                .draw_series(LineSeries::new(
                    thin(&points, MAX_POINTS),
                    colour.stroke_width(1),
                ))
                .map_err(|e| e.to_string())?
                .label(series.label.as_str())
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2))
                });
        }
        Ok(())
    }

    /// The threshold as a solid horizontal line with its label at the right end.
    fn draw_threshold(
        &self,
        root: &Root<'_>,
        chart: &mut Plot<'_, '_>,
        f: &Frame,
        a: &Axes,
    ) -> Result<(), String> {
        let Some(th) = &self.threshold else {
            return Ok(());
        };
        if !th.y.is_finite() || (self.log_y && th.y <= 0.0) {
            return Ok(());
        }
        let y = self.axis_y(th.y).clamp(a.y.0, a.y.1);
        chart
            .draw_series(LineSeries::new(
                [(a.x.0, y), (a.x.1, y)],
                THRESHOLD_COLOUR.stroke_width(2),
            ))
            .map_err(|e| e.to_string())?;
        let style = ("sans-serif", 12)
            .into_font()
            .color(&THRESHOLD_COLOUR)
            .pos(Pos::new(HPos::Right, VPos::Bottom));
        let (px, py) = (f.left + f.w - 4.0, f.py(th.y) - 4.0);
        root.draw_text(&th.label, &style, (px as i32, py as i32))
            .map_err(|e| e.to_string())
    }
}

/// The drawing area of one chart.
type Root<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;
/// The chart's plotting context over f64 data coordinates.
type Plot<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// The plotted ranges (y in log10 units on a log axis) and tick steps.
#[derive(Debug, Clone, Copy)]
struct Axes {
    x: (f64, f64),
    y: (f64, f64),
    x_step: f64,
    y_step: f64,
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

/// The multiples of `step` within `[lo, hi]`.
fn ticks(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut k = (lo / step).ceil();
    while k * step <= hi + step * 1e-9 && out.len() < 1000 {
        out.push(k * step);
        k += 1.0;
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

    /// Every `<polyline>`: its stroke colour and its points.
    fn polylines(svg: &str) -> Vec<(String, Vec<(f64, f64)>)> {
        svg.split("<polyline")
            .skip(1)
            .map(|p| {
                let element = &p[..p.find("/>").unwrap()];
                let points = text_attr(element, "points")
                    .split_whitespace()
                    .map(|xy| {
                        let (x, y) = xy.split_once(',').unwrap();
                        (x.parse().unwrap(), y.parse().unwrap())
                    })
                    .collect();
                (text_attr(element, "stroke").to_lowercase(), points)
            })
            .collect()
    }

    fn text_attr<'a>(element: &'a str, name: &str) -> &'a str {
        let key = format!(" {name}=\"");
        let i = element.find(&key).unwrap() + key.len();
        &element[i..i + element[i..].find('"').unwrap()]
    }

    /// The contents of every `<text>` element, trimmed.
    fn texts(svg: &str) -> Vec<String> {
        svg.split("<text")
            .skip(1)
            .map(|t| {
                let body = &t[t.find('>').unwrap() + 1..];
                body[..body.find("</text>").unwrap()].trim().to_owned()
            })
            .collect()
    }

    fn hex(c: RGBColor) -> String {
        format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2)
    }

    /// The longest polyline drawn in `colour`, the first on a tie (legend samples
    /// are two points, drawn after the lines).
    fn line_in(svg: &str, colour: RGBColor) -> Vec<(f64, f64)> {
        polylines(svg)
            .into_iter()
            .rev()
            .filter(|(c, _)| *c == hex(colour))
            .map(|(_, p)| p)
            .max_by_key(Vec::len)
            .unwrap_or_default()
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
    fn chart_is_well_formed_with_one_line_per_series_and_its_labels() {
        let c = chart().with_threshold(20.0, "T_D = 20");
        let svg = c.to_svg();
        assert!(svg.starts_with("<svg "), "{svg}");
        assert!(balanced(&svg), "{svg}");
        // Each series is one polyline in its colour carrying all its points, where
        // the chart's mapping puts them (plotters draws in whole pixels: within two).
        for (i, series) in c.series.iter().enumerate() {
            let line = line_in(&svg, PALETTE[i]);
            assert_eq!(line.len(), series.points.len(), "series {i}");
            for (&(x, y), &(px, py)) in series.points.iter().zip(&line) {
                assert!((px - c.x_to_px(x)).abs() <= 2.0, "x {x}: {px}");
                assert!((py - c.y_to_px(y)).abs() <= 2.0, "y {y}: {py}");
            }
        }
        let labels = texts(&svg);
        for expected in [
            "errors &amp; λ &lt;test&gt;",
            "t, s",
            "error, m",
            "T_D = 20",
        ] {
            assert!(
                labels.iter().any(|t| t == expected),
                "{expected}: {labels:?}"
            );
        }
        // The legend names every series; x ticks are the 1–2–5 steps over 0..99.
        for expected in ["a", "b", "c", "0", "20", "40", "60", "80"] {
            assert!(
                labels.iter().any(|t| t == expected),
                "{expected}: {labels:?}"
            );
        }
    }

    #[test]
    fn a_band_is_a_shaded_rectangle_over_its_x_interval() {
        let c = chart().with_bands(vec![(20.0, 40.0), (200.0, 300.0)]);
        let svg = c.to_svg();
        assert!(balanced(&svg));
        let rects: Vec<&str> = svg
            .match_indices("<rect")
            .map(|(i, _)| &svg[i..i + svg[i..].find("/>").unwrap_or(0)])
            .filter(|r| r.contains("#EEEEEE") || r.contains("#eeeeee"))
            .collect();
        // The second band lies beyond the data (x ≤ 99): not drawn.
        assert_eq!(rects.len(), 1, "{rects:?}");
        let attr = |name: &str| -> f64 {
            let r = rects[0];
            let at = r.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
            r[at..at + r[at..].find('"').unwrap()].parse().unwrap()
        };
        assert!((attr("x") - c.x_to_px(20.0)).abs() <= 2.0);
        assert!((attr("x") + attr("width") - c.x_to_px(40.0)).abs() <= 2.0);
    }

    #[test]
    fn a_single_series_has_no_legend() {
        let svg = Chart::new("one", "x", "y")
            .with_series(Series::new("only", vec![(0.0, 1.0), (1.0, 2.0)]))
            .to_svg();
        assert!(!texts(&svg).iter().any(|t| t == "only"));
        assert_eq!(line_in(&svg, PALETTE[0]).len(), 2);
    }

    #[test]
    fn threshold_line_sits_at_its_value_on_the_axis() {
        // Plot box: top 40, height 400 − 40 − 52 = 308; y in [0, 40] → 20 is mid-height.
        let c = chart().with_y_range(0.0, 40.0).with_threshold(20.0, "T");
        assert!((c.y_to_px(20.0) - (40.0 + 308.0 * 0.5)).abs() < 1e-9);
        let svg = c.to_svg();
        let line = line_in(&svg, THRESHOLD_COLOUR);
        assert_eq!(line.len(), 2);
        assert_eq!(line[0].1, line[1].1);
        assert!((line[0].1 - (40.0 + 308.0 * 0.5)).abs() <= 2.0, "{line:?}");
        assert!((line[0].0 - 72.0).abs() <= 1.0, "{line:?}");
        assert!((line[1].0 - (800.0 - 24.0)).abs() <= 2.0, "{line:?}");
        // Values beyond a fixed range are drawn on its edge, not outside the box.
        let clipped = Chart::new("c", "x", "y")
            .with_series(Series::new("s", vec![(0.0, -5.0), (1.0, 100.0)]))
            .with_y_range(0.0, 10.0);
        let line = line_in(&clipped.to_svg(), PALETTE[0]);
        assert!((line[0].1 - clipped.y_to_px(0.0)).abs() <= 2.0);
        assert!((line[1].1 - clipped.y_to_px(10.0)).abs() <= 2.0);
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
        let labels = texts(&svg);
        for label in ["1e-1", "1e0", "1e1", "1e2"] {
            assert!(labels.iter().any(|t| t == label), "{label}: {labels:?}");
        }
        // The zero is drawn at the axis floor; the threshold at 20 on the log scale.
        let line = line_in(&svg, PALETTE[0]);
        assert_eq!(line.len(), 3);
        assert!((line[1].1 - c.y_to_px(50.0)).abs() <= 2.0, "{line:?}");
        assert!((line[2].1 - c.y_to_px(0.1)).abs() <= 2.0, "{line:?}");
        let th = line_in(&svg, THRESHOLD_COLOUR);
        assert!((th[0].1 - expected).abs() <= 2.0, "{th:?}");
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
