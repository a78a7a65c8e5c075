//! The channel experiments' library functions at reduced size (seeds 000 and 001):
//! real properties of the LS-SVM channel monitor on the papers' scenarios.

use navguard_sim::experiment::{seed000, seed001};

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
    // 4 faults × 2 methods × 2 variances.
    assert_eq!(cases.len(), 16);
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
fn seed_001_faults_are_detected_and_the_stuck_test_catches_a_freeze_within_ten_samples() {
    let p = seed001::Seed001Params {
        seeds: 3,
        ..Default::default()
    };
    let cases = seed001::cases(&p);
    // The calibrated monitor under counters (the monitor's defaults otherwise).
    let case = cases.iter().find(|c| c.label == "BM counters").unwrap();
    let rows = seed001::faults_case(&p, case).unwrap();
    for row in &rows {
        // The stuck test never fires on healthy data.
        assert_eq!(row.stuck_false_alarms, 0, "{}", row.fault);
        match row.fault {
            "none" => {}
            "stuck" | "failure" => {
                // Both freeze the output: the k = 8th repeated difference is flagged.
                assert!(
                    row.stuck_delays.iter().all(|d| d.is_some_and(|d| d <= 10)),
                    "{}: {:?}",
                    row.fault,
                    row.stuck_delays
                );
            }
            _ => {
                assert!(
                    row.delays.iter().all(|d| d.is_some_and(|d| d <= 8)),
                    "{}: {:?}",
                    row.fault,
                    row.delays
                );
            }
        }
    }
    let gain = rows.iter().find(|r| r.fault == "gain").unwrap();
    assert!(
        gain.card.true_positive_rate.unwrap() > 0.9,
        "{:?}",
        gain.card
    );
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
