//! Calibration from out-of-reach replays: known answers, refusals and guards.
use super::*;
use crate::detect::PolicyConfig;
use crate::monitor::linear::{LinearConfig, LinearConfigWire, LinearMonitor};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

/// A random walk seen in white noise of σ = `scale` while the model says σ = 1:
/// λ = r²/S with the model's S is `scale²`-inflated once the filter has converged.
fn run(scale: f64, epochs: usize, seed: u64) -> Vec<TestSample> {
    let config = LinearConfig::try_from(LinearConfigWire {
        f: vec![vec![1.0]],
        h: vec![vec![1.0]],
        q: vec![vec![1e-8]],
        r: vec![vec![1.0]],
        x0: vec![0.0],
        p0: vec![vec![1e-8]],
        b: None,
        drift: None,
        stuck: None,
    })
    .unwrap();
    let mut m =
        LinearMonitor::new(config, PolicyConfig::Classic, ThresholdSpec::default()).unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let data: Vec<Epoch> = (0..epochs)
        .map(|k| {
            let e: f64 = StandardNormal.sample(&mut rng);
            Epoch {
                t: k as f64,
                z: Some(vec![scale * e]),
                ..Default::default()
            }
        })
        .collect();
    sample(&mut m, &data).unwrap()
}

#[test]
fn a_mis_scaled_model_gets_the_scaled_threshold() {
    // Noise √2 × what the model says: λ ~ 2 χ²(1), so the threshold for a rate of
    // 1e-3 is 2 × 10.828 = 21.66 (the χ² one, 10.83, would fail ≈ 2.1 % of epochs).
    for seed in [1, 2, 3] {
        let samples = run(2f64.sqrt(), 100_000, seed);
        let c = calibrate(&samples[0], 1e-3, 0.95).unwrap();
        assert_eq!(c.epochs, 100_000);
        assert!((c.chi2_threshold - 10.8276).abs() < 1e-3);
        assert!((c.chi2_rate - 0.0209).abs() < 0.002, "{}", c.chi2_rate);
        let Proposal::Calibrated {
            threshold, below, ..
        } = c.proposal
        else {
            panic!("calibrated");
        };
        // The conservative order statistic sits a little above the true quantile.
        assert!(
            (21.0..24.5).contains(&threshold),
            "seed {seed}: {threshold}"
        );
        assert!(below < 100, "{below}");
    }
}

#[test]
fn too_little_data_is_refused_saying_how_much_is_needed() {
    assert_eq!(epochs_needed(1e-4, 0.95), 29_956);
    let samples = run(1.0, 1000, 4);
    let c = calibrate(&samples[0], 1e-4, 0.95).unwrap();
    assert_eq!(c.proposal, Proposal::TooShort { needed: 29_956 });
    assert_eq!(
        calibrate(&samples[0], 0.0, 0.95),
        Err(CalibrateError::Range("far"))
    );
    assert_eq!(
        calibrate(&samples[0], 0.1, 1.0),
        Err(CalibrateError::Range("confidence"))
    );
}

#[test]
fn the_proposed_level_keeps_the_rate_below_far_at_the_stated_confidence() {
    // Uniform tails (a well-tuned model): the level's true rate is the level itself.
    // Over 200 data sets of 5,000 epochs at far 0.01, at most ≈ 5 % may exceed it.
    let mut rng = StdRng::seed_from_u64(9);
    let mut over = 0;
    for _ in 0..200 {
        let tails: Vec<f64> = (0..5000)
            .map(|_| rand::Rng::random::<f64>(&mut rng))
            .collect();
        let s = TestSample {
            test: "t".into(),
            dof: 1,
            tails,
            sums: (0.0, 0.0),
            own_spec: None,
        };
        let Proposal::Calibrated { p_fa, .. } = calibrate(&s, 0.01, 0.95).unwrap().proposal else {
            panic!()
        };
        over += usize::from(p_fa > 0.01);
    }
    assert!(over <= 20, "{over} of 200 above the rate asked");
}

#[test]
fn a_guards_threshold_is_never_lowered_below_its_own() {
    // Tails uniform on (0, 1): at far 0.01 over 5,000 epochs the level is about 0.006
    // (below far: the 95 % bound on the true rate).
    let mut rng = StdRng::seed_from_u64(3);
    let tails: Vec<f64> = (0..5000)
        .map(|_| rand::Rng::random::<f64>(&mut rng))
        .collect();
    let with = |own_spec| TestSample {
        test: "c.stuck".into(),
        dof: 1,
        tails: tails.clone(),
        sums: (0.0, 0.0),
        own_spec,
    };
    let level = match calibrate(&with(None), 0.01, 0.95).unwrap().proposal {
        Proposal::Calibrated { p_fa, .. } => p_fa,
        other => panic!("{other:?}"),
    };
    assert!((0.005..0.01).contains(&level), "{level}");
    // A guard with its own p_fa 1e-6 (the stuck test's) keeps it: the data's level
    // would lower its threshold from 23.9 to about 7.6.
    let guard = ThresholdSpec::PFa(1e-6);
    let c = calibrate(&with(Some(guard)), 0.01, 0.95).unwrap();
    assert_eq!(
        c.proposal,
        Proposal::Stricter {
            p_fa: level,
            own: guard
        }
    );
    let line = CalibrationLine::from(&c);
    assert_eq!((line.p_fa, line.threshold), (None, None));
    assert!(line.refused.unwrap().starts_with("kept:"));
    // A raw threshold of its own above the data's is kept too; one below is raised.
    let high = calibrate(&with(Some(ThresholdSpec::Threshold(20.0))), 0.01, 0.95).unwrap();
    assert!(matches!(high.proposal, Proposal::Stricter { .. }));
    let low = calibrate(&with(Some(ThresholdSpec::Threshold(2.0))), 0.01, 0.95).unwrap();
    assert!(matches!(low.proposal, Proposal::Calibrated { p_fa, .. } if p_fa == level));
    // An own p_fa looser than the data's level does not stop the proposal.
    let loose = calibrate(&with(Some(ThresholdSpec::PFa(0.05))), 0.01, 0.95).unwrap();
    assert!(matches!(loose.proposal, Proposal::Calibrated { .. }));
}
