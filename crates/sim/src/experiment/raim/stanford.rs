//! The Stanford diagram of the RAIM experiment as SVG: horizontal position error (x)
//! against the horizontal protection level (y), both on log axes, epochs counted in
//! cells (colour by log count), with the HPE = HPL diagonal, the HAL lines and the
//! regions: nominal, misleading information (HPE > HPL), hazardously misleading
//! (HPE > HAL while HPL ≤ HAL) and unavailable (HPL > HAL). Written by hand: a cell
//! grid and a few lines are all it needs.

use std::fmt::Write;

/// Axis range, m (both axes): 0.1 m to 1,000 m.
const LO: f64 = -1.0;
const HI: f64 = 3.0;
/// Cells per decade.
const CELLS: usize = 12;
/// Plot frame: left and top margins and the square's side, px.
const LEFT: f64 = 70.0;
const TOP: f64 = 40.0;
const SIZE: f64 = 420.0;

fn px(v: f64) -> f64 {
    let l = v.max(10f64.powf(LO)).log10().min(HI);
    (l - LO) / (HI - LO) * SIZE
}

fn colour(count: usize, max: usize) -> String {
    // Light to dark blue by log count.
    let f = ((count as f64).ln_1p() / (max as f64).ln_1p()).clamp(0.0, 1.0);
    let c = |a: f64, b: f64| (a + (b - a) * f).round() as u8;
    format!(
        "#{:02x}{:02x}{:02x}",
        c(198.0, 8.0),
        c(219.0, 48.0),
        c(239.0, 107.0)
    )
}

/// The diagram of `points` `(HPE, HPL)` for alert limit `hal_m`, titled `title`, with
/// the region counts in the legend.
pub fn stanford_svg(title: &str, points: &[(f64, f64)], hal_m: f64) -> String {
    let n = CELLS * (HI - LO) as usize;
    let mut grid = vec![0usize; n * n];
    let (mut nominal, mut mi, mut hmi, mut unavailable) = (0, 0, 0, 0);
    for &(e, l) in points {
        let cell = |v: f64| ((px(v) / SIZE * n as f64) as usize).min(n - 1);
        grid[cell(l) * n + cell(e)] += 1;
        if l > hal_m {
            unavailable += 1;
        } else if e > hal_m {
            hmi += 1;
        } else if e > l {
            mi += 1;
        } else {
            nominal += 1;
        }
    }
    let max = grid.iter().copied().max().unwrap_or(0).max(1);
    let (w, h) = (LEFT + SIZE + 230.0, TOP + SIZE + 60.0);
    let mut s = String::with_capacity(64 * 1024);
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12"><rect width="100%" height="100%" fill="white"/><text x="10" y="22" font-size="14">{}</text><g transform="translate({LEFT},{TOP})">"#,
        escape(title)
    );
    let (hal, c) = (px(hal_m), SIZE / n as f64);
    // Regions: unavailable above the HAL, HMI right of it below, MI under the diagonal.
    let _ = write!(
        s,
        r##"<rect x="0" y="0" width="{SIZE}" height="{}" fill="#eeeeee"/><rect x="{hal}" y="{}" width="{}" height="{hal}" fill="#f4cccc"/><polygon points="0,{SIZE} {hal},{} {hal},{SIZE}" fill="#fce5cd"/>"##,
        SIZE - hal,
        SIZE - hal,
        SIZE - hal,
        SIZE - hal
    );
    for (i, &count) in grid.iter().enumerate().filter(|(_, c)| **c > 0) {
        let (row, col) = (i / n, i % n);
        let _ = write!(
            s,
            r#"<rect x="{:.1}" y="{:.1}" width="{c:.1}" height="{c:.1}" fill="{}"/>"#,
            col as f64 * c,
            SIZE - (row + 1) as f64 * c,
            colour(count, max)
        );
    }
    let _ = write!(
        s,
        r##"<line x1="0" y1="{SIZE}" x2="{SIZE}" y2="0" stroke="black" stroke-dasharray="4 3"/><line x1="{hal}" y1="0" x2="{hal}" y2="{SIZE}" stroke="#c00000"/><line x1="0" y1="{}" x2="{SIZE}" y2="{}" stroke="#c00000"/><rect width="{SIZE}" height="{SIZE}" fill="none" stroke="black"/>"##,
        SIZE - hal,
        SIZE - hal
    );
    axes(&mut s);
    let _ = write!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">HPE (m)</text><text transform="translate(-45,{}) rotate(-90)" text-anchor="middle">HPL (m)</text>"#,
        SIZE / 2.0,
        SIZE + 38.0,
        SIZE / 2.0
    );
    let legend = [
        ("epochs", points.len()),
        ("nominal (HPE ≤ HPL ≤ HAL)", nominal),
        ("MI (HPE > HPL)", mi),
        ("HMI (HPE > HAL, HPL ≤ HAL)", hmi),
        ("unavailable (HPL > HAL)", unavailable),
    ];
    for (k, (label, count)) in legend.iter().enumerate() {
        let _ = write!(
            s,
            r#"<text x="{}" y="{}">{label}: {count}</text>"#,
            SIZE + 15.0,
            20.0 + 18.0 * k as f64
        );
    }
    let _ = write!(
        s,
        r#"<text x="{x}" y="{}">HAL = {hal_m} m</text><text x="{x}" y="{}">Regions by HPE and HPL alone:</text><text x="{x}" y="{}">an epoch whose test fired is</text><text x="{x}" y="{}">drawn where its errors fall.</text></g></svg>"#,
        20.0 + 18.0 * legend.len() as f64,
        56.0 + 18.0 * legend.len() as f64,
        74.0 + 18.0 * legend.len() as f64,
        92.0 + 18.0 * legend.len() as f64,
        x = SIZE + 15.0,
    );
    s
}

/// Decade ticks on both axes.
fn axes(s: &mut String) {
    for d in (LO as i32)..=(HI as i32) {
        let v = 10f64.powi(d);
        let p = px(v);
        let label = if d < 0 {
            format!("{v}")
        } else {
            format!("{v:.0}")
        };
        let _ = write!(
            s,
            r#"<line x1="{p}" y1="{SIZE}" x2="{p}" y2="{}" stroke="black"/><text x="{p}" y="{}" text-anchor="middle">{label}</text><line x1="0" y1="{}" x2="-5" y2="{}" stroke="black"/><text x="-8" y="{}" text-anchor="end">{label}</text>"#,
            SIZE + 5.0,
            SIZE + 18.0,
            SIZE - p,
            SIZE - p,
            SIZE - p + 4.0
        );
    }
}

fn escape(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_point_falls_in_one_region_and_the_counts_say_which() {
        let points = [
            (1.0, 10.0),
            (20.0, 10.0),
            (50.0, 30.0),
            (5.0, 60.0),
            (2.0, 3.0),
        ];
        let svg = stanford_svg("t", &points, 40.0);
        assert!(svg.contains("nominal (HPE ≤ HPL ≤ HAL): 2"), "{svg}");
        assert!(svg.contains("MI (HPE > HPL): 1"));
        assert!(svg.contains("HMI (HPE > HAL, HPL ≤ HAL): 1"));
        assert!(svg.contains("unavailable (HPL > HAL): 1"));
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>"));
        // Decades 0.1 … 1000 on each axis: 5 ticks, each labelled twice.
        assert_eq!(svg.matches(">1000<").count(), 2);
    }
}
