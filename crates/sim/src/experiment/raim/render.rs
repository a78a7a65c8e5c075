//! The RAIM experiment's text tables: per data set the σ scale, the fault-free figures
//! per method, and per fault case and method detection, exclusion, MI and HMI.

use std::fmt::Write;

use super::{DatasetResult, FaultFree, Faulted, RaimResult};

fn pct(n: usize, d: usize) -> String {
    if d == 0 {
        "-".into()
    } else {
        format!("{:.1} %", 100.0 * n as f64 / d as f64)
    }
}

fn fault_free_row(out: &mut String, label: &str, f: &FaultFree, p_fa: f64) {
    let rate = f.exceedances as f64 / f.epochs.max(1) as f64;
    let _ = writeln!(
        out,
        "  {label:<22} {:>6} {:>9.4} ({:>5.1} × p_fa) {:>6} {:>7.2} {:>9} {:>9} {:>6.2} {:>6.2} {:>6.2}",
        f.epochs,
        rate,
        rate / p_fa,
        f.exclusions,
        f.alarms as f64 / f.hours.max(1e-9),
        pct(f.available, f.epochs),
        pct(f.bounded, f.epochs),
        f.hpe[0],
        f.hpe[1],
        f.hpe[2],
    );
}

fn faulted_row(out: &mut String, case: &str, method: &str, f: &Faulted) {
    let tested = f.draws - f.skipped;
    let tte = if f.time_to_exclude_s.is_empty() {
        "-".to_owned()
    } else {
        let mut v = f.time_to_exclude_s.clone();
        v.sort_by(f64::total_cmp);
        format!("{:.0} s ({}/{})", v[v.len() / 2], v.len(), tested)
    };
    let _ = writeln!(
        out,
        "  {case:<14} {method:<20} {:>5} {:>8} {:>8} {:>8} {:>8} {:>6} {:>7} {:>5} {:>4} {:>18} {:>5}",
        tested,
        pct(f.detected_first, tested),
        pct(f.excluded_first, tested),
        pct(f.detected_any, tested),
        pct(f.correct_out, f.epochs),
        f.wrong_exclusions,
        f.epochs,
        f.mi,
        f.hmi,
        tte,
        f.passed_hpl_before_out,
    );
}

fn dataset(out: &mut String, d: &DatasetResult, r: &RaimResult) {
    let _ = writeln!(
        out,
        "\n{}: {} epochs, {}–{} satellites; σ scale the fault-free data need: {:.2}",
        d.name, d.epochs, d.sats.0, d.sats.1, d.sigma_scale
    );
    let _ = writeln!(
        out,
        "  fault-free             epochs  FA rate                  excl.  alarm/h  avail.    HPE≤HPL   HPE mean/95%/max (m)"
    );
    fault_free_row(out, "σ as given (greedy)", &d.fault_free_unit, r.p_fa);
    for (method, f) in &d.fault_free {
        fault_free_row(out, &format!("scaled, {method}"), f, r.p_fa);
    }
    let _ = writeln!(
        out,
        "  faults (scaled σ)     method               draws det.1st  excl.1st det.any  out/ep  wrong  epochs    MI  HMI   ramp: time out   >HPL"
    );
    for (case, by_method) in &d.faulted {
        for (method, f) in by_method {
            faulted_row(out, case, method, f);
        }
    }
}

/// The tables of `r`.
pub fn render(r: &RaimResult) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "RAIM on real data: p_fa {} per epoch, HAL {} m, ARAIM protection levels, classic policy, {} draws per fault case",
        r.p_fa, r.hal_m, r.draws
    );
    for d in &r.datasets {
        dataset(&mut out, d, r);
    }
    let _ = writeln!(
        out,
        "\ndet.1st: the raim test fired on the fault's first epoch; excl.1st: every faulty satellite excluded on it; \
         out/ep: faulted epochs with every faulty satellite out of the fix; wrong: exclusions of a healthy satellite; \
         MI: HPE > HPL with the test silent; HMI: HPE > HAL while available; ramp: median time until the satellite is out \
         (draws that got it out / draws), and draws whose HPE passed the HPL first."
    );
    out
}
