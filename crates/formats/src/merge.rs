//! The last step before the wire: IMU samples and GNSS fixes of one drive, each already
//! on GPS time, into one time-ordered stream of ingest epochs.
//!
//! # Rule
//! Every IMU sample is an epoch `{t, imu}`. Each GNSS fix rides on the IMU epoch nearest
//! in time (ties to the later one) when that epoch carries no fix yet and is within the
//! tolerance: half the median IMU interval, or, for a fix between two samples no
//! further apart than 1.5 median intervals, half their interval. The epoch's `t` stays
//! the IMU's (the fix is at most half a sample away, about 5 ms at 100 Hz). The
//! widening matters for loggers whose interval jitters: on the drive of tests/data/drive
//! (8–11 ms around 10 ms), half the median alone would leave 30 of 2,184 fixes that
//! fall mid-way in an 11 ms interval standing alone. A fix in a real gap, or outside the
//! IMU's span, is an epoch of its own, placed in time order (after IMU epochs of the
//! same time). One forward pass over both inputs:
//! O(n) when they are sorted (they are sorted stably by time first when not), and
//! epochs of equal time keep their input order.

use navguard_core::epoch::Epoch;

/// The merged stream and how the fixes went into it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Merged {
    /// IMU and GNSS epochs, time non-decreasing.
    pub epochs: Vec<Epoch>,
    /// Fixes that ride on an IMU epoch.
    pub attached: usize,
    /// Fixes written as epochs of their own.
    pub standalone: usize,
    /// Half the median IMU interval, s: the attach tolerance (widened between close
    /// samples, module docs).
    pub tolerance_s: f64,
}

/// Half the median interval between consecutive epochs (0 with fewer than two).
fn half_median_interval(epochs: &[Epoch]) -> f64 {
    let mut dts: Vec<f64> = epochs.windows(2).map(|w| w[1].t - w[0].t).collect();
    if dts.is_empty() {
        return 0.0;
    }
    let mid = dts.len() / 2;
    let (_, m, _) = dts.select_nth_unstable_by(mid, f64::total_cmp);
    *m / 2.0
}

fn sort_by_time(epochs: &mut [Epoch]) {
    if !epochs.is_sorted_by(|a, b| a.t <= b.t) {
        epochs.sort_by(|a, b| a.t.total_cmp(&b.t));
    }
}

/// The index of the IMU epoch `t` is to ride on, if any: `j` is the first IMU epoch at
/// or after `t`, `tol` half the median interval (module docs).
fn nearest(imu: &[Epoch], j: usize, t: f64, tol: f64) -> Option<usize> {
    let after = imu.get(j).map(|e| (j, e.t - t));
    let before = j.checked_sub(1).map(|i| (i, t - imu[i].t));
    let (best, tol) = match (before, after) {
        (Some(b), Some(a)) => {
            let gap = b.1 + a.1;
            let tol = if gap <= 3.0 * tol {
                tol.max(gap / 2.0)
            } else {
                tol
            };
            (Some(if b.1 < a.1 { b } else { a }), tol)
        }
        (b, a) => (a.or(b), tol),
    };
    best.filter(|&(_, d)| d <= tol).map(|(i, _)| i)
}

/// Merges `imu` epochs (each with an `imu` block) and `gnss` epochs (each with a `gnss`
/// block) by the module's rule.
pub fn merge(mut imu: Vec<Epoch>, mut gnss: Vec<Epoch>) -> Merged {
    sort_by_time(&mut imu);
    sort_by_time(&mut gnss);
    let tol = half_median_interval(&imu);
    let mut standalone = Vec::new();
    let mut attached = 0;
    let mut j = 0;
    for g in gnss {
        while j < imu.len() && imu[j].t < g.t {
            j += 1;
        }
        match nearest(&imu, j, g.t, tol).filter(|&i| imu[i].gnss.is_none()) {
            Some(i) => {
                imu[i].gnss = g.gnss;
                attached += 1;
            }
            None => standalone.push(g),
        }
    }
    let n_standalone = standalone.len();
    let mut epochs = Vec::with_capacity(imu.len() + n_standalone);
    let mut alone = standalone.into_iter().peekable();
    for e in imu {
        while let Some(g) = alone.next_if(|g| g.t < e.t) {
            epochs.push(g);
        }
        epochs.push(e);
    }
    epochs.extend(alone);
    Merged {
        epochs,
        attached,
        standalone: n_standalone,
        tolerance_s: tol,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navguard_core::epoch::{GnssBlock, ImuBlock};

    fn imu(t: f64) -> Epoch {
        Epoch {
            t,
            imu: Some(ImuBlock::default()),
            ..Epoch::default()
        }
    }

    fn fix(t: f64, h: f64) -> Epoch {
        Epoch {
            t,
            gnss: Some(GnssBlock {
                h,
                ..GnssBlock::default()
            }),
            ..Epoch::default()
        }
    }

    #[test]
    fn a_fix_rides_on_the_nearest_sample_and_ties_go_to_the_later_one() {
        // Samples every 0.25 s (exact in binary, so the tie is a tie): tolerance 0.125 s.
        let m = merge(
            (0..5).map(|k| imu(f64::from(k) * 0.25)).collect(),
            vec![fix(0.3, 1.0), fix(0.625, 2.0)],
        );
        assert_eq!(m.tolerance_s, 0.125);
        assert_eq!((m.attached, m.standalone), (2, 0));
        assert_eq!(m.epochs.len(), 5);
        assert_eq!(m.epochs[1].gnss.as_ref().unwrap().h, 1.0);
        assert_eq!(m.epochs[3].gnss.as_ref().unwrap().h, 2.0);
        assert_eq!(m.epochs[3].t, 0.75);
    }

    #[test]
    fn fixes_outside_the_samples_or_in_a_gap_stand_alone_in_time_order() {
        let samples = vec![imu(1.0), imu(1.01), imu(1.02), imu(1.2), imu(1.21)];
        let m = merge(
            samples,
            vec![fix(0.5, 1.0), fix(1.1, 2.0), fix(1.0, 3.0), fix(2.0, 4.0)],
        );
        assert_eq!((m.attached, m.standalone), (1, 3));
        let times: Vec<f64> = m.epochs.iter().map(|e| e.t).collect();
        assert_eq!(times, [0.5, 1.0, 1.01, 1.02, 1.1, 1.2, 1.21, 2.0]);
        assert_eq!(m.epochs[1].gnss.as_ref().unwrap().h, 3.0);
    }

    #[test]
    fn a_fix_mid_way_in_a_long_but_normal_interval_still_rides() {
        // Median interval 0.25 s; 0.375 s between the last two is within 1.5 medians.
        let samples = vec![imu(0.0), imu(0.25), imu(0.5), imu(0.875)];
        let m = merge(samples, vec![fix(0.6875, 1.0)]);
        assert_eq!((m.attached, m.standalone), (1, 0));
        assert!(m.epochs[3].gnss.is_some());
    }

    #[test]
    fn a_second_fix_on_the_same_sample_stands_alone() {
        let m = merge(vec![imu(0.0), imu(1.0)], vec![fix(0.9, 1.0), fix(1.1, 2.0)]);
        assert_eq!((m.attached, m.standalone), (1, 1));
        assert_eq!(m.epochs.len(), 3);
        assert_eq!(m.epochs[2].t, 1.1);
    }
}
