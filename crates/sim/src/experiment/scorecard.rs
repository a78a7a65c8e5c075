//! The scorecard every experiment ends with (docs/methods.md §M19): per detector (test)
//! and policy, the true-positive, false-alarm and missed-detection rates, mean
//! and max detection delay, time to recover after the fault ends, and time per
//! epoch. Computed from the per-epoch health trace of one test and the known
//! fault windows, after the run; pure.
//!
//! Definitions (chosen here; the papers only name the figures):
//! - An epoch *alarms* when the test's health is not `healthy` (suspect or
//!   isolated: under either policy the measurement is not used).
//! - *Fault epochs* lie in some fault window `[start, end)`. The true-positive
//!   rate is the share of fault epochs that alarm; the missed-detection rate is
//!   its complement (epoch-wise, as seed 000 Table 2 counts missed detections).
//! - *Clear epochs* lie in no fault window and in no recovery tail (from a
//!   fault's end until the test is first healthy again, so a slow recovery is
//!   scored as recovery time, not as false alarms). The false-alarm rate is the
//!   share of clear epochs that alarm.
//! - A fault's detection delay is the time from its onset to the first alarming
//!   epoch inside its window; a fault with no alarming epoch is missed.
//! - A fault's recovery time is the time from its end to the first healthy epoch
//!   at or after the end. When the next fault starts before that, the recovery is
//!   *censored* (merged into the next fault: counted in `recoveries_censored`, not in
//!   `recovery_s`); `None` means the test never returned to healthy before the run
//!   ended. A fault lasting past the run's end has no recovery at all. (Before this
//!   distinction, seed 003's dense jumps made every card read "never" although the
//!   test always recovered: the next jump came first.)
//! - *Alarms* and *warnings per fault-free hour*: the test's alarm-log entries of each
//!   severity at a clear epoch, over the clear time (the sum of the intervals that start
//!   at a clear epoch). The entries are those the server writes: the session core's rule
//!   (docs/architecture.md §A2), as the core wrote them for a monitor run through it
//!   ([`score_test`]), or by the same rule from the health trace for a monitor without a
//!   protection level ([`score`]: entering `isolated` an alarm, entering `suspect` a
//!   warning). `FAR / p_fa` compares the false-alarm rate with the nominal rate the
//!   threshold was set for ([`Scorecard::with_p_fa`]).
//! - *Bursts*: the lengths of the maximal runs of consecutive alarming clear epochs (a
//!   run ends at a healthy epoch, a fault or recovery epoch, or a gap in time, where
//!   pooled draws meet). Printed as their mean and 99th percentile beside what
//!   independent exceedances at the measured rate `q` would give: a geometric length,
//!   `P(L = l) = q^(l−1)(1 − q)`, mean `1/(1 − q)`, 99th percentile
//!   `⌈ln 0.01 / ln q⌉` (docs/methods.md §M14).

use std::fmt::Write as _;

use navguard_core::detect::Health;
use navguard_core::session::rule::{self, AlarmLevel, Severity};

/// A fault interval `[start, end)` in epoch time, s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultWindow {
    /// Onset, s.
    pub start: f64,
    /// End (exclusive), s; `f64::INFINITY` for a fault that lasts to the end.
    pub end: f64,
}

impl FaultWindow {
    /// True when `t` lies in the window.
    pub fn contains(&self, t: f64) -> bool {
        t >= self.start && t < self.end
    }
}

/// The figures of one test under one policy.
#[derive(Debug, Clone, PartialEq)]
pub struct Scorecard {
    /// Detector (test) name, e.g. `gnss`.
    pub detector: String,
    /// Policy label, e.g. `counters T=20`.
    pub policy: String,
    /// Epochs on which the test ran.
    pub epochs: usize,
    /// Of those, epochs inside a fault window.
    pub fault_epochs: usize,
    /// Of those, epochs outside every fault window and recovery tail.
    pub clear_epochs: usize,
    /// Alarming fault epochs / fault epochs (`None` without fault epochs).
    pub true_positive_rate: Option<f64>,
    /// Alarming clear epochs / clear epochs (`None` without clear epochs).
    pub false_alarm_rate: Option<f64>,
    /// 1 − true-positive rate.
    pub missed_detection_rate: Option<f64>,
    /// Number of fault windows that intersect the run.
    pub faults: usize,
    /// Faults with at least one alarming epoch in their window.
    pub detected: usize,
    /// Mean detection delay over detected faults, s.
    pub mean_delay_s: Option<f64>,
    /// Largest detection delay over detected faults, s.
    pub max_delay_s: Option<f64>,
    /// Recovery time of each fault that ended inside the run and was not followed by
    /// another before it recovered (`None`: never recovered before the run ended).
    pub recovery_s: Vec<Option<f64>>,
    /// Faults whose recovery the next fault cut short.
    pub recoveries_censored: usize,
    /// Wall-clock time per epoch of the monitor that produced the trace, s.
    pub time_per_epoch_s: Option<f64>,
    /// Clear (fault-free, outside recovery tails) time, h.
    pub clear_hours: f64,
    /// Log entries of severity `alarm` at a clear epoch.
    pub clear_alarms: usize,
    /// Log entries of severity `warning` at a clear epoch.
    pub clear_warnings: usize,
    /// The nominal per-epoch false-alarm probability of the test, when it has one.
    pub p_fa: Option<f64>,
    /// Lengths of the runs of consecutive alarming clear epochs, epochs, in time order.
    pub clear_bursts: Vec<usize>,
}

impl Scorecard {
    /// The card with the test's nominal false-alarm probability, for `FAR / p_fa`.
    pub fn with_p_fa(mut self, p_fa: f64) -> Self {
        self.p_fa = Some(p_fa);
        self
    }

    /// The false-alarm rate as a multiple of the nominal `p_fa`.
    pub fn far_over_p_fa(&self) -> Option<f64> {
        Some(self.false_alarm_rate? / self.p_fa?)
    }

    /// Alarms per fault-free hour.
    pub fn alarms_per_hour(&self) -> Option<f64> {
        (self.clear_hours > 0.0).then(|| self.clear_alarms as f64 / self.clear_hours)
    }

    /// Warnings per fault-free hour.
    pub fn warnings_per_hour(&self) -> Option<f64> {
        (self.clear_hours > 0.0).then(|| self.clear_warnings as f64 / self.clear_hours)
    }

    /// Mean fault-free burst length, epochs (`None` without bursts).
    pub fn burst_mean(&self) -> Option<f64> {
        let b = &self.clear_bursts;
        (!b.is_empty()).then(|| b.iter().sum::<usize>() as f64 / b.len() as f64)
    }

    /// 99th percentile of the fault-free burst lengths (nearest rank), epochs.
    pub fn burst_p99(&self) -> Option<usize> {
        let mut b = self.clear_bursts.clone();
        b.sort_unstable();
        let rank = (0.99 * b.len() as f64).ceil() as usize;
        b.get(rank.max(1) - 1).copied()
    }

    /// Mean and 99th percentile of the burst length independent exceedances at this
    /// card's false-alarm rate `q` would give (geometric, module doc).
    pub fn independent_bursts(&self) -> Option<(f64, usize)> {
        let q = self.false_alarm_rate?;
        if !(q > 0.0 && q < 1.0) {
            return None;
        }
        Some((
            1.0 / (1.0 - q),
            ((0.01f64).ln() / q.ln()).ceil().max(1.0) as usize,
        ))
    }

    /// Largest recovery time, or `None` when no fault ended or one never recovered.
    pub fn max_recovery_s(&self) -> Option<f64> {
        if self.recovery_s.is_empty() || self.recovery_s.iter().any(Option::is_none) {
            return None;
        }
        self.recovery_s.iter().flatten().copied().reduce(f64::max)
    }
}

/// Scores one test's health trace `(t, health)` (in time order) against the
/// fault windows that concern it. Its alarms and warnings are the entries the session
/// core's rule writes for a monitor without a protection level under the default alarm
/// level ([`rule::trace_entries`]).
pub fn score(
    detector: &str,
    policy: &str,
    trace: &[(f64, Health)],
    faults: &[FaultWindow],
    time_per_epoch_s: Option<f64>,
) -> Scorecard {
    score_runs(detector, policy, trace, faults, time_per_epoch_s, &[])
}

/// [`score`] for a trace made of several runs laid end to end, starting at
/// `run_starts`: a fault's recovery is looked for in its own run only (the monitor
/// starts afresh with the next), and one not seen by the run's end is censored, not
/// "never".
pub fn score_runs(
    detector: &str,
    policy: &str,
    trace: &[(f64, Health)],
    faults: &[FaultWindow],
    time_per_epoch_s: Option<f64>,
    run_starts: &[f64],
) -> Scorecard {
    let entries: Vec<(f64, Severity)> = rule::trace_entries(trace, AlarmLevel::default())
        .into_iter()
        .map(|(t, _, severity)| (t, severity))
        .collect();
    let run = TestRun {
        trace,
        entries: &entries,
        run_starts,
    };
    score_test(detector, policy, run, faults, time_per_epoch_s)
}

/// What one test did over a run, as scored.
#[derive(Debug, Clone, Copy)]
pub struct TestRun<'a> {
    /// Its health `(t, health)` at every epoch on which it ran, in time order.
    pub trace: &'a [(f64, Health)],
    /// Its alarm-log entries `(t, severity)` as the session core wrote them (the server's
    /// rule, with its warnings while converging and standing alarms at convergence).
    pub entries: &'a [(f64, Severity)],
    /// Starts of the runs laid end to end in `trace` (empty: one run).
    pub run_starts: &'a [f64],
}

/// Scores one test's run against the fault windows that concern it: rates and delays
/// from its health trace, alarms and warnings per fault-free hour from its log entries.
pub fn score_test(
    detector: &str,
    policy: &str,
    run: TestRun<'_>,
    faults: &[FaultWindow],
    time_per_epoch_s: Option<f64>,
) -> Scorecard {
    let trace = run.trace;
    let faults = faults_in(trace, faults);
    let recovery = recoveries(trace, &faults, run.run_starts);
    let clear = |t: f64| {
        !faults.iter().any(|f| f.contains(t)) && !recovery.tails.iter().any(|f| f.contains(t))
    };
    let (mut fault_epochs, mut fault_alarms, mut clear_epochs, mut clear_alarms) = (0, 0, 0, 0);
    let mut clear_s = 0.0;
    for (i, &(t, h)) in trace.iter().enumerate() {
        if faults.iter().any(|f| f.contains(t)) {
            fault_epochs += 1;
            fault_alarms += usize::from(alarms(h));
        } else if clear(t) {
            clear_epochs += 1;
            clear_alarms += usize::from(alarms(h));
            if let Some(&(next, _)) = trace.get(i + 1) {
                clear_s += next - t;
            }
        }
    }
    let logged = |severity| {
        run.entries
            .iter()
            .filter(|&&(t, s)| s == severity && clear(t))
            .count()
    };
    let ratio = |a: usize, n: usize| (n > 0).then(|| a as f64 / n as f64);
    let true_positive_rate = ratio(fault_alarms, fault_epochs);
    let delays = &recovery.delays;
    Scorecard {
        detector: detector.to_owned(),
        policy: policy.to_owned(),
        epochs: trace.len(),
        fault_epochs,
        clear_epochs,
        true_positive_rate,
        false_alarm_rate: ratio(clear_alarms, clear_epochs),
        missed_detection_rate: true_positive_rate.map(|r| 1.0 - r),
        faults: faults.len(),
        detected: delays.len(),
        mean_delay_s: (!delays.is_empty())
            .then(|| delays.iter().sum::<f64>() / delays.len() as f64),
        max_delay_s: delays.iter().copied().reduce(f64::max),
        recovery_s: recovery.recovery_s,
        recoveries_censored: recovery.censored,
        time_per_epoch_s,
        clear_hours: clear_s / 3600.0,
        clear_alarms: logged(Severity::Alarm),
        clear_warnings: logged(Severity::Warning),
        p_fa: None,
        clear_bursts: bursts(trace, clear),
    }
}

/// The runs of consecutive alarming epochs among those `clear` accepts (module doc); a
/// gap in time longer than twice the trace's shortest step ends a run.
fn bursts(trace: &[(f64, Health)], clear: impl Fn(f64) -> bool) -> Vec<usize> {
    let step = trace
        .windows(2)
        .map(|w| w[1].0 - w[0].0)
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    let (mut out, mut run, mut last_t) = (Vec::new(), 0usize, f64::NEG_INFINITY);
    for &(t, h) in trace {
        let continues = t - last_t <= 2.0 * step;
        if run > 0 && !(continues && clear(t) && alarms(h)) {
            out.push(run);
            run = 0;
        }
        if clear(t) && alarms(h) {
            run += 1;
        }
        last_t = t;
    }
    if run > 0 {
        out.push(run);
    }
    out
}

/// An epoch *alarms* when its health is not healthy.
fn alarms(h: Health) -> bool {
    h != Health::Healthy
}

/// The fault windows that intersect the trace, in time order.
fn faults_in(trace: &[(f64, Health)], faults: &[FaultWindow]) -> Vec<FaultWindow> {
    let mut faults: Vec<FaultWindow> = faults.iter().copied().filter(|f| f.end > f.start).collect();
    faults.sort_by(|a, b| a.start.total_cmp(&b.start));
    let (t_first, t_last) = match (trace.first(), trace.last()) {
        (Some(a), Some(b)) => (a.0, b.0),
        _ => (f64::NAN, f64::NAN),
    };
    faults.retain(|f| f.start <= t_last && f.end > t_first);
    faults
}

/// Detection delays, recovery times and recovery tails of the faults of a trace.
struct Recoveries {
    delays: Vec<f64>,
    recovery_s: Vec<Option<f64>>,
    censored: usize,
    /// From each fault's end to the first healthy epoch after it (or the next start).
    tails: Vec<FaultWindow>,
}

fn recoveries(trace: &[(f64, Health)], faults: &[FaultWindow], run_starts: &[f64]) -> Recoveries {
    let t_last = trace.last().map_or(f64::NAN, |x| x.0);
    let mut r = Recoveries {
        delays: Vec::new(),
        recovery_s: Vec::new(),
        censored: 0,
        tails: Vec::new(),
    };
    for (i, f) in faults.iter().enumerate() {
        if let Some(&(t, _)) = trace.iter().find(|(t, h)| f.contains(*t) && alarms(*h)) {
            r.delays.push(t - f.start);
        }
        if f.end > t_last {
            continue;
        }
        let next_fault = faults.get(i + 1).map_or(f64::INFINITY, |n| n.start);
        let next_run = run_starts
            .iter()
            .copied()
            .filter(|&s| s > f.end)
            .fold(f64::INFINITY, f64::min);
        let next_start = next_fault.min(next_run);
        let back = trace
            .iter()
            .find(|(t, h)| *t >= f.end && *t < next_start && !alarms(*h));
        let end = match back {
            Some(&(t, _)) => {
                r.recovery_s.push(Some(t - f.end));
                t
            }
            None if next_start <= t_last => {
                r.censored += 1;
                next_start
            }
            None => {
                r.recovery_s.push(None);
                next_start
            }
        };
        r.tails.push(FaultWindow { start: f.end, end });
    }
    r
}

fn pct(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_owned(), |v| format!("{:.2} %", 100.0 * v))
}

fn per_hour(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_owned(), |v| format!("{v:.2}"))
}

fn secs(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_owned(), |v| format!("{v:.1}"))
}

/// Renders scorecards as a fixed-width text table.
pub fn render(cards: &[Scorecard]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<8} {:<16} {:>9} {:>9} {:>8} {:>11} {:>11} {:>8} {:>7} {:>9} {:>8} {:>10} {:>9} {:>12} {:>9}",
        "test",
        "policy",
        "TPR",
        "FAR",
        "FAR/p_fa",
        "burst m/p99",
        "indep m/p99",
        "alarms/h",
        "warn/h",
        "MDR",
        "detected",
        "delay mean",
        "delay max",
        "recover s",
        "µs/epoch"
    );
    for c in cards {
        let mut recover = if c.recovery_s.is_empty() {
            "—".to_owned()
        } else {
            c.recovery_s
                .iter()
                .map(|r| r.map_or_else(|| "never".to_owned(), |r| format!("{r:.0}")))
                .collect::<Vec<_>>()
                .join("/")
        };
        if c.recoveries_censored > 0 {
            recover.push_str(&format!(" (+{} cut)", c.recoveries_censored));
        }
        let _ = writeln!(
            s,
            "{:<8} {:<16} {:>9} {:>9} {:>8} {:>11} {:>11} {:>8} {:>7} {:>9} {:>8} {:>10} {:>9} {:>12} {:>9}",
            c.detector,
            c.policy,
            pct(c.true_positive_rate),
            pct(c.false_alarm_rate),
            c.far_over_p_fa()
                .map_or_else(|| "—".to_owned(), |v| format!("{v:.2}×")),
            match (c.burst_mean(), c.burst_p99()) {
                (Some(m), Some(p)) => format!("{m:.2}/{p}"),
                _ => "—".to_owned(),
            },
            c.independent_bursts()
                .map_or_else(|| "—".to_owned(), |(m, p)| format!("{m:.2}/{p}")),
            per_hour(c.alarms_per_hour()),
            per_hour(c.warnings_per_hour()),
            pct(c.missed_detection_rate),
            format!("{}/{}", c.detected, c.faults),
            secs(c.mean_delay_s),
            secs(c.max_delay_s),
            recover,
            c.time_per_epoch_s
                .map_or_else(|| "—".to_owned(), |v| format!("{:.2}", v * 1e6)),
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use Health::{Healthy as H, Isolated as I, Suspect as S};

    /// Epochs at t = 0..20 s with the given health letters.
    fn trace(states: &str) -> Vec<(f64, Health)> {
        states
            .chars()
            .enumerate()
            .map(|(i, c)| {
                let h = match c {
                    's' => S,
                    'i' => I,
                    _ => H,
                };
                (i as f64, h)
            })
            .collect()
    }

    #[test]
    fn bursts_are_the_runs_of_clear_alarms_beside_the_geometric_law() {
        let c = score("y", "classic", &trace("ss.iii..s"), &[], None);
        assert_eq!(c.clear_bursts, vec![2, 3, 1]);
        assert_eq!(c.burst_mean(), Some(2.0));
        assert_eq!(c.burst_p99(), Some(3));
        // q = 6/9: mean 1/(1 − q) = 3, p99 ⌈ln 0.01 / ln(2/3)⌉ = ⌈11.36⌉ = 12.
        let (mean, p99) = c.independent_bursts().unwrap();
        assert!((mean - 3.0).abs() < 1e-12);
        assert_eq!(p99, 12);
        // A fault splits a run, and so does a gap in time (two draws laid end to end).
        let cut = score(
            "y",
            "classic",
            &trace("sss.ss"),
            &[FaultWindow {
                start: 2.0,
                end: 3.0,
            }],
            None,
        );
        assert_eq!(cut.clear_bursts, vec![2, 2]);
        let mut pooled = trace("ss");
        pooled.extend(trace("ss").into_iter().map(|(t, h)| (t + 100.0, h)));
        let gap = score("y", "classic", &pooled, &[], None);
        assert_eq!(gap.clear_bursts, vec![2, 2]);
    }

    #[test]
    fn hand_made_trace_gives_the_counted_figures() {
        //          0123456789012345678901
        let tr = trace("..i.....ssii..s.......");
        // Fault [7, 12): alarms at 8..=11 (4 of 5 epochs); ends at 12, healthy at 12.
        let c = score(
            "gnss",
            "counters",
            &tr,
            &[FaultWindow {
                start: 7.0,
                end: 12.0,
            }],
            Some(2e-6),
        );
        assert_eq!(c.epochs, 22);
        assert_eq!(c.fault_epochs, 5);
        assert_eq!(c.clear_epochs, 17);
        assert!((c.true_positive_rate.unwrap() - 0.8).abs() < 1e-12);
        assert!((c.missed_detection_rate.unwrap() - 0.2).abs() < 1e-12);
        // Clear alarms at t = 2 and t = 14.
        assert!((c.false_alarm_rate.unwrap() - 2.0 / 17.0).abs() < 1e-12);
        assert_eq!((c.faults, c.detected), (1, 1));
        assert_eq!(c.mean_delay_s, Some(1.0));
        assert_eq!(c.max_delay_s, Some(1.0));
        assert_eq!(c.recovery_s, vec![Some(0.0)]);
        // Clear entries: isolated at 2, suspect at 14; 17 clear epochs of 1 s, the last
        // has no successor.
        assert_eq!((c.clear_alarms, c.clear_warnings), (1, 1));
        assert!((c.clear_hours - 16.0 / 3600.0).abs() < 1e-15);
        assert!((c.alarms_per_hour().unwrap() - 3600.0 / 16.0).abs() < 1e-9);
        let c = c.with_p_fa(0.01);
        assert!((c.far_over_p_fa().unwrap() - 200.0 / 17.0).abs() < 1e-9);
    }

    #[test]
    fn slow_recovery_is_time_not_false_alarms() {
        //          0123456789012345
        let tr = trace("...iiiiiiii.....");
        let c = score(
            "gnss",
            "classic",
            &tr,
            &[FaultWindow {
                start: 3.0,
                end: 6.0,
            }],
            None,
        );
        // Fault epochs 3,4,5 all alarm; the tail 6..=10 alarms, healthy again at 11.
        assert_eq!(c.true_positive_rate, Some(1.0));
        assert_eq!(c.recovery_s, vec![Some(5.0)]);
        assert_eq!(c.max_recovery_s(), Some(5.0));
        assert_eq!(c.clear_epochs, 16 - 3 - 5);
        assert_eq!(c.false_alarm_rate, Some(0.0));
        assert_eq!(c.mean_delay_s, Some(0.0));
    }

    #[test]
    fn missed_and_unfinished_faults_are_reported_as_such() {
        let tr = trace("..........iiiiii");
        let faults = [
            FaultWindow {
                start: 2.0,
                end: 5.0,
            },
            FaultWindow {
                start: 9.0,
                end: f64::INFINITY,
            },
        ];
        let c = score("dvl", "classic", &tr, &faults, None);
        assert_eq!((c.faults, c.detected), (2, 1));
        assert_eq!(c.mean_delay_s, Some(1.0));
        // The first fault ended (healthy at once); the second never ends in the run.
        assert_eq!(c.recovery_s, vec![Some(0.0)]);
        assert_eq!(c.fault_epochs, 3 + 7);
        assert!((c.true_positive_rate.unwrap() - 6.0 / 10.0).abs() < 1e-12);
    }

    #[test]
    fn a_recovery_cut_short_by_the_next_fault_is_not_never() {
        //          0123456789012345678
        let tr = trace("..iiiiiiii....iii..");
        let faults = [
            FaultWindow {
                start: 2.0,
                end: 4.0,
            },
            FaultWindow {
                start: 6.0,
                end: 8.0,
            },
            FaultWindow {
                start: 14.0,
                end: f64::INFINITY,
            },
        ];
        let c = score("range", "counters", &tr, &faults, None);
        // Fault 1's recovery is cut by fault 2, which recovers at 10 (2 s); fault 3 lasts.
        assert_eq!(c.recoveries_censored, 1);
        assert_eq!(c.recovery_s, vec![Some(2.0)]);
        // A test that never comes back before the run ends still reads `None`.
        let tr = trace("..iiiiiiiiiiii");
        let c = score("range", "c", &tr, &faults[..1], None);
        assert_eq!(
            (c.recovery_s.clone(), c.recoveries_censored),
            (vec![None], 0)
        );
        assert!(render(&[c]).contains("never"));
    }

    #[test]
    fn a_recovery_is_not_looked_for_in_the_next_run() {
        // Two runs laid end to end (the second from t = 10): the fault at the end of
        // the first has not recovered when its run ends; that is not "never".
        //          0123456789012345
        let tr = trace("......iiii......");
        let faults = [FaultWindow {
            start: 7.0,
            end: 9.0,
        }];
        let c = score_runs("range", "counters", &tr, &faults, None, &[0.0, 10.0]);
        assert_eq!((c.recovery_s.clone(), c.recoveries_censored), (vec![], 1));
        // Without the boundary the first healthy epoch of the next run would count.
        let c = score("range", "counters", &tr, &faults, None);
        assert_eq!(c.recovery_s, vec![Some(1.0)]);
    }

    #[test]
    fn fault_free_run_has_only_a_false_alarm_rate() {
        let tr = trace("....i...........................................s...");
        let c = score("cns", "counters", &tr, &[], None);
        assert_eq!(c.true_positive_rate, None);
        assert_eq!(c.missed_detection_rate, None);
        assert!((c.false_alarm_rate.unwrap() - 2.0 / tr.len() as f64).abs() < 1e-12);
        assert_eq!(c.max_recovery_s(), None);
        let text = render(&[c]);
        assert!(text.lines().count() == 2 && text.contains("cns"), "{text}");
    }
}
