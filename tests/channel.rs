//! The channel experiments' library functions at reduced size (seeds 000 and 001):
//! real properties of the LS-SVM channel monitor on the papers' scenarios.

use navguard::sim::experiment::{seed000, seed001};

#[test]
fn locally_weighted_lssvm_predicts_the_seed_000_height_better_than_plain() {
    // Part (a) as the experiment runs it (same γ, σ² for both, as the paper compares them).
    let p = seed000::Seed000Params::default();
    let r = seed000::prediction(&p).unwrap();
    assert_eq!(r.t.len(), 100);
    let (plain, lw) = r.rmse_truth();
    assert!(lw <= plain, "LW {lw} vs plain {plain}");
    // Both predict well below the 15 m + 5 m wander of the height: they follow it.
    assert!(plain < 4.0 && lw < 4.0, "{plain} {lw}");
}

#[test]
fn seed_000_faults_are_detected_and_the_false_alarm_tail_is_short() {
    let p = seed000::Seed000Params {
        runs: 2,
        threads: 1,
        ..Default::default()
    };
    let (cases, example) = seed000::monte_carlo(&p).unwrap();
    assert_eq!(cases.len(), 8);
    assert!(example.is_some());
    for c in &cases {
        assert_eq!(c.card.detected, c.card.faults, "{} {}", c.fault, c.method);
        // Steps are flagged at once; ramps within 15 s.
        let max_delay = c.card.max_delay_s.unwrap();
        let bound = if c.fault.contains("step") { 1.0 } else { 15.0 };
        assert!(max_delay <= bound, "{} {}: {max_delay}", c.fault, c.method);
        // Epoch-wise missed detection well below 10 %.
        assert!(c.card.missed_detection_rate.unwrap() < 0.1, "{c:?}");
        // Every run returns to healthy after the fault.
        assert!(c.card.recovery_s.iter().all(Option::is_some), "{c:?}");
    }
}

#[test]
fn seed_001_gain_bias_and_failure_are_detected_within_three_samples() {
    let p = seed001::Seed001Params::default();
    let rows = seed001::faults(&p).unwrap();
    for row in &rows {
        assert_eq!(row.false_alarms, 0, "{}", row.fault);
        if row.fault != "stuck" {
            let d = row.delay_samples.unwrap_or(usize::MAX);
            assert!(d <= 3, "{}: {d}", row.fault);
        }
    }
}

#[test]
fn seed_001_online_recursion_matches_batch_and_beats_the_global_model() {
    let p = seed001::Seed001Params {
        reps: 1,
        ..Default::default()
    };
    let rows = seed001::predictors(&p).unwrap();
    let (online, batch, global) = (&rows[0], &rows[1], &rows[2]);
    assert!((online.rmse - batch.rmse).abs() < 1e-6 * batch.rmse.max(1.0));
    assert!(online.rmse < global.rmse, "{rows:?}");
}

#[test]
fn seed_001_outlier_filter_lowers_the_rmse_with_spikes() {
    let p = seed001::Seed001Params::default();
    let (without, with, replaced, spikes) = seed001::outliers(&p).unwrap();
    assert!(with < without, "{with} vs {without}");
    assert!(replaced as usize >= spikes, "{replaced} of {spikes}");
}
