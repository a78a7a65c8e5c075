//! The coloured grid: fault delays, and seeded cells checked against their own traces.
use super::*;

/// Two draws of 3,000 epochs, 5 steps and 3 ramps each, one thread.
fn small() -> GridParams {
    GridParams {
        base: ColouredParams {
            seeds: 2,
            epochs: 3_000,
            steps: 5,
            ..ColouredParams::default()
        },
        ramps: 3,
        train_epochs: 300,
        threads: 1,
        ..GridParams::default()
    }
}

fn cell(phi: f64, form: usize, predictor: GridPredictor, scale: ResidualScale) -> GridCell {
    GridCell {
        phi,
        form: FORMS[form],
        predictor,
        scale,
    }
}

#[test]
fn first_flags_count_from_the_onset_inside_each_fault_only() {
    let h = |t: f64, bad: bool| {
        (
            t,
            if bad {
                Health::Suspect
            } else {
                Health::Healthy
            },
        )
    };
    // Flagged at 9 (before the first fault), 12 and 31 (after the second's end).
    let trace: Vec<_> = (0..40)
        .map(|k| h(k as f64, [9, 12, 31].contains(&k)))
        .collect();
    assert_eq!(first_flags(&trace, &[10, 25], 5), vec![Some(2), None]);
    let d = [Some(0), Some(3), Some(4), None];
    assert_eq!(share_within(&d, 3), Some(0.5));
    assert_eq!(mean_delay(&d), Some(7.0 / 3.0));
    assert_eq!(fault_onsets(1_000, 4, 300, 100), vec![500, 800]);
}

/// Ramps at 1,500, 1,800 and 2,100 of 0.05 σ per epoch on each draw of `row`, run
/// here and counted from the main test's own samples: those flagged within 60 epochs.
fn ramps_flagged_within_60(p: &GridParams, row: &GridRow) -> usize {
    let onsets = [1_500, 1_800, 2_100];
    let c = &row.cell;
    let mut within = 0;
    for (draw, &sigma) in row.sigma.iter().enumerate() {
        let seed = p.base.seed + draw as u64;
        let series = coloured::signal_with(&p.base, c.phi, c.form.1, seed, |k| {
            onsets
                .iter()
                .find(|&&a| k >= a && k < a + RAMP_LEN)
                .map_or(0.0, |&a| 0.05 * sigma * (k - a + 1) as f64)
        });
        let trace = run_channel_with(
            cell_config(&p.base, c, false).unwrap(),
            &cell_models(p, c, seed).unwrap(),
            PolicyConfig::Classic,
            p.base.p_fa,
            &coloured::epochs(&series),
        )
        .unwrap();
        for &a in &onsets {
            let (start, end) = (a as f64, (a + 60) as f64);
            within += usize::from(
                trace
                    .samples
                    .iter()
                    .any(|&(t, _, h)| t >= start && t <= end && h != Health::Healthy),
            );
        }
    }
    within
}

#[test]
fn predictive_online_cell_keeps_the_binomial_bound_with_single_epoch_bursts() {
    let p = small();
    let c = cell(0.9, 0, GridPredictor::Online, ResidualScale::Predictive);
    let row = run_cell(&p, &c).unwrap();
    // Fault-free: the share of flagged clear epochs within p_fa + 4 binomial σ.
    let n = row.clear.clear_epochs as f64;
    let q = row.clear.false_alarm_rate.unwrap();
    let p_fa = p.base.p_fa;
    assert!(n > 5_000.0, "{n}");
    assert!(q <= p_fa + 4.0 * (p_fa * (1.0 - p_fa) / n).sqrt(), "{q}");
    assert!(
        row.clear.burst_p99().unwrap_or(1) <= 2,
        "{:?}",
        row.clear.clear_bursts
    );
    assert_eq!(row.ramp_delays.len(), 6);
    let within = ramps_flagged_within_60(&p, &row);
    assert_eq!(
        share_within(&row.ramp_delays, 60),
        Some(within as f64 / 6.0)
    );
}

#[test]
fn batch_cell_on_ar1_noise_predicts_to_its_innovation_sigma_and_flags_ramps_as_its_trace_says() {
    let p = small();
    let c = cell(0.5, 3, GridPredictor::Batch, ResidualScale::Raw);
    let row = run_cell(&p, &c).unwrap();
    // One-step error of the best predictor of AR(1) noise: σ_e √(1 − φ²) = 0.2598.
    let ideal = 0.3 * (1.0f64 - 0.25).sqrt();
    for &s in &row.sigma {
        assert!(s > 0.97 * ideal && s < 1.1 * ideal, "{s} vs {ideal}");
    }
    // A 4σ step shows on its onset epoch most: the next prediction carries φ of it.
    assert_eq!(row.step_delays.len(), 10);
    let at_onset = share_within(&row.step_delays, 0).unwrap();
    assert!(at_onset >= 0.7, "{:?}", row.step_delays);
    // The ramps, counted here: on white-ish noise every one is flagged within 60 epochs.
    let within = ramps_flagged_within_60(&p, &row);
    assert_eq!(within, 6, "{:?}", row.ramp_delays);
    assert_eq!(
        share_within(&row.ramp_delays, 60),
        Some(within as f64 / 6.0)
    );
}
