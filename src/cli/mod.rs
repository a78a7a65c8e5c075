//! The command-line tools beside `serve`: `simulate` writes a scenario as
//! ingest frames (JSON lines), `replay` streams such a file into a running
//! server, `loadgen` puts simulated load on one and measures it (docs/performance.md),
//! `calibrate` proposes thresholds from fault-free data, `convert` turns real receiver
//! files into ingest frames, `experiment` reruns the papers' experiments in-process,
//! and `token` issues entries for the tokens file.
//! Thin: parsing flags, files, sockets and printing; the algorithms live in
//! the library. `anyhow` is used here and in `main.rs` only.

pub(crate) mod calibrate;
pub(crate) mod convert;
pub(crate) mod convert_drive;
pub(crate) mod experiment;
pub(crate) mod experiment_drive;
pub(crate) mod experiment_raim;
pub(crate) mod http;
pub(crate) mod loadgen;
pub(crate) mod replay;
pub(crate) mod simulate;
pub(crate) mod token;

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{HumanCount, ProgressBar, ProgressStyle};

/// A progress bar on stderr for a long run of `len` steps, drawn with
/// `template` (an `indicatif` template). Hidden when `enabled` is false or
/// stderr is not a terminal, so redirected logs and `--json` output stay clean.
pub(crate) fn progress_bar(len: u64, template: &str, enabled: bool) -> ProgressBar {
    if !enabled || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("#>-"));
    }
    bar
}

/// A spinner on stderr saying `message` while an in-process run works (same
/// hiding rules as [`progress_bar`]).
pub(crate) fn spinner(message: &str, enabled: bool) -> ProgressBar {
    let bar = progress_bar(0, "{spinner} {msg} ({elapsed})", enabled);
    bar.set_message(message.to_owned());
    bar.enable_steady_tick(Duration::from_millis(100));
    bar
}

/// `12345678` → `12,345,678`.
pub(crate) fn thousands(n: u64) -> String {
    HumanCount(n).to_string()
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
    fn a_disabled_bar_is_hidden() {
        assert!(progress_bar(10, "{bar}", false).is_hidden());
    }
}
