//! A progress line on stderr for long CLI runs (`replay`): a bar redrawn in
//! place at most ten times a second on a terminal, or a plain line every 10 %
//! when stderr is redirected (so logs stay readable).

use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

/// Least time between two redraws on a terminal.
const REDRAW: Duration = Duration::from_millis(100);
/// Bar width in characters.
const BAR: usize = 24;

/// The progress display.
#[derive(Debug)]
pub struct Progress {
    total_s: f64,
    total_epochs: u64,
    tty: bool,
    enabled: bool,
    start: Instant,
    last_draw: Option<Instant>,
    last_decile: i64,
    drawn: bool,
}

impl Progress {
    /// A display for a run of `total_s` seconds of epoch time and
    /// `total_epochs` epochs; `enabled = false` draws nothing.
    pub fn new(total_s: f64, total_epochs: u64, enabled: bool) -> Self {
        Progress {
            total_s,
            total_epochs,
            tty: std::io::stderr().is_terminal(),
            enabled,
            start: Instant::now(),
            last_draw: None,
            last_decile: -1,
            drawn: false,
        }
    }

    /// Reports that epochs up to `done_s` seconds (from the first epoch) and
    /// `epochs` epochs in all have been sent; `extra` is appended to the line.
    pub fn update(&mut self, done_s: f64, epochs: u64, extra: &str) {
        if !self.enabled {
            return;
        }
        let now = Instant::now();
        let frac = fraction(done_s, self.total_s, epochs, self.total_epochs);
        if self.tty {
            let finished = epochs >= self.total_epochs;
            if !finished && self.last_draw.is_some_and(|t| now - t < REDRAW) {
                return;
            }
            self.last_draw = Some(now);
            let line = self.line(frac, done_s, epochs, extra);
            let mut err = std::io::stderr().lock();
            let _ = write!(err, "\r{line}\x1b[K");
            let _ = err.flush();
            self.drawn = true;
        } else {
            let decile = (frac * 10.0).floor() as i64;
            if decile > self.last_decile {
                self.last_decile = decile;
                let line = self.line(frac, done_s, epochs, extra);
                eprintln!("{line}");
            }
        }
    }

    fn line(&self, frac: f64, done_s: f64, epochs: u64, extra: &str) -> String {
        let elapsed = self.start.elapsed().as_secs_f64();
        let rate = if elapsed > 0.0 {
            epochs as f64 / elapsed
        } else {
            0.0
        };
        let mut line = format!(
            "{} {:>3.0}% {:.0}/{:.0} s  {} epochs/s",
            bar(frac),
            100.0 * frac,
            done_s,
            self.total_s,
            thousands(rate.round() as u64)
        );
        if !extra.is_empty() {
            line.push_str("  ");
            line.push_str(extra);
        }
        line
    }

    /// Ends the in-place line so later output starts on a fresh line.
    pub fn finish(&mut self) {
        if self.enabled && self.tty && self.drawn {
            eprintln!();
            self.drawn = false;
        }
    }
}

/// Fraction done, by epoch time when the run spans time, else by epochs.
fn fraction(done_s: f64, total_s: f64, epochs: u64, total_epochs: u64) -> f64 {
    let f = if total_s > 0.0 {
        done_s / total_s
    } else if total_epochs > 0 {
        epochs as f64 / total_epochs as f64
    } else {
        1.0
    };
    if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// `[#####     ]` for a fraction in [0, 1].
pub fn bar(frac: f64) -> String {
    let filled = ((frac.clamp(0.0, 1.0) * BAR as f64).round() as usize).min(BAR);
    format!("[{}{}]", "#".repeat(filled), " ".repeat(BAR - filled))
}

/// `12345678` → `12,345,678`.
pub fn thousands(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i) % 3 == 0 {
            out.push(',');
        }
        out.push(c);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thousands_are_grouped_by_three() {
        assert_eq!(thousands(0), "0");
        assert_eq!(thousands(999), "999");
        assert_eq!(thousands(12_345), "12,345");
        assert_eq!(thousands(1_234_567), "1,234,567");
    }

    #[test]
    fn bar_fills_in_proportion() {
        assert_eq!(bar(0.0), format!("[{}]", " ".repeat(BAR)));
        assert_eq!(bar(1.0), format!("[{}]", "#".repeat(BAR)));
        assert_eq!(bar(0.5).matches('#').count(), BAR / 2);
        assert_eq!(bar(7.0), bar(1.0));
    }

    #[test]
    fn fraction_uses_time_then_epochs() {
        assert_eq!(fraction(1872.0, 3600.0, 5, 10), 0.52);
        assert_eq!(fraction(0.0, 0.0, 5, 10), 0.5);
        assert_eq!(fraction(5.0, 0.0, 0, 0), 1.0);
        assert_eq!(fraction(f64::NAN, 10.0, 0, 1), 0.0);
    }
}
