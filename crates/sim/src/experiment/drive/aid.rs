//! The drive's GNSS aid and its truth: the RTK reference interpolated to any time, the
//! reference decimated to the aid rate with single-point noise (seeded), outages, and the
//! injected faults (a jump, a ramp, a frozen receiver) on the aid only.

use nalgebra::Vector3;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

use navguard_core::epoch::{Epoch, GnssBlock};
use navguard_core::geo::{self, Lla};

use super::{AidNoise, FaultKind, RefFix};

/// Largest gap between two reference fixes interpolated across, s.
const MAX_REF_GAP_S: f64 = 0.6;

/// The reference (antenna) position and ENU velocity at `t`, linearly interpolated
/// between the bracketing fixes (none outside the reference or across a gap).
pub fn reference_at(reference: &[RefFix], t: f64) -> Option<(Lla, Vector3<f64>)> {
    let k = reference.partition_point(|r| r.t <= t);
    let last = reference.last()?;
    if k == reference.len() {
        return (last.t == t).then_some((last.lla, last.vel));
    }
    let (a, b) = (reference.get(k.checked_sub(1)?)?, &reference[k]);
    if b.t - a.t > MAX_REF_GAP_S {
        return None;
    }
    let w = (t - a.t) / (b.t - a.t);
    let d = geo::local_offset(&b.lla, &a.lla);
    let lla = geo::apply_offset(&a.lla, &(d * w));
    Some((lla, a.vel + (b.vel - a.vel) * w))
}

/// An injected fault on the aid: its kind over `[start, start + duration)` (times
/// relative to the drive's first IMU epoch, like the outages).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultWindow {
    /// The fault.
    pub kind: FaultKind,
    /// Start, s from the drive's start.
    pub start: f64,
    /// Length, s.
    pub duration: f64,
}

impl FaultWindow {
    fn contains(&self, rel: f64) -> bool {
        (self.start..self.start + self.duration).contains(&rel)
    }
}

/// How one run's aid is made.
#[derive(Debug, Clone, PartialEq)]
pub struct AidPlan {
    /// Noise and rate.
    pub noise: AidNoise,
    /// Outage starts, s from the drive's start; each lasts `outage_s`.
    pub outages: Vec<f64>,
    /// Outage length, s.
    pub outage_s: f64,
    /// The fault, if any.
    pub fault: Option<FaultWindow>,
    /// Noise seed.
    pub seed: u64,
}

impl AidPlan {
    /// Whether `rel` (s from the drive's start) falls in an outage.
    pub fn in_outage(&self, rel: f64) -> bool {
        self.outages
            .iter()
            .any(|&s| (s..s + self.outage_s).contains(&rel))
    }
}

/// The fault's offset of the fix at `rel` (ENU metres, from `fault.start`) for jumps and
/// ramps; a frozen receiver is handled by the caller.
fn fault_offset(fault: &FaultWindow, rel: f64) -> Vector3<f64> {
    let since = rel - fault.start;
    match fault.kind {
        FaultKind::Jump(m) => Vector3::new(m, 0.0, 0.0),
        FaultKind::Ramp(mps) => Vector3::new(mps * since, 0.0, 0.0),
        FaultKind::Frozen => Vector3::zeros(),
    }
}

/// The epochs of one run: the IMU epochs with the aid attached to the IMU epoch nearest
/// each decimated reference fix (within half an IMU interval). Returns the epochs and,
/// per fix attached, `(IMU index, the injected error in ENU metres)`.
pub fn with_aid(
    imu: &[Epoch],
    reference: &[RefFix],
    plan: &AidPlan,
) -> (Vec<Epoch>, Vec<(usize, Vector3<f64>)>) {
    let mut epochs = imu.to_vec();
    let mut injected = Vec::new();
    let Some(t0) = imu.first().map(|e| e.t) else {
        return (epochs, injected);
    };
    let mut rng = StdRng::seed_from_u64(plan.seed);
    let n = plan.noise;
    let (h, v, vel) = (
        Normal::new(0.0, n.pos_sigma_h_m).ok(),
        Normal::new(0.0, n.pos_sigma_v_m).ok(),
        Normal::new(0.0, n.vel_sigma_mps).ok(),
    );
    let (Some(h), Some(v), Some(vel)) = (h, v, vel) else {
        return (epochs, injected);
    };
    let period = 1.0 / n.rate_hz;
    let mut next_t = f64::NEG_INFINITY;
    let mut frozen: Option<GnssBlock> = None;
    for r in reference {
        if r.t + 1e-6 < next_t {
            continue;
        }
        next_t = r.t + period;
        // The noise is drawn for every decimated fix, so outages and faults leave the
        // other fixes' noise as in the fault-free run of the same seed.
        let noise = Vector3::new(h.sample(&mut rng), h.sample(&mut rng), v.sample(&mut rng));
        let vnoise = Vector3::from_fn(|_, _| vel.sample(&mut rng));
        let k = imu.partition_point(|e| e.t < r.t);
        let nearest = [k.checked_sub(1), Some(k)]
            .into_iter()
            .flatten()
            .filter(|&i| i < imu.len())
            .min_by(|&a, &b| (imu[a].t - r.t).abs().total_cmp(&(imu[b].t - r.t).abs()));
        let Some(i) = nearest else { continue };
        if (imu[i].t - r.t).abs() > 0.006 {
            continue;
        }
        let rel = r.t - t0;
        if plan.in_outage(rel) {
            continue;
        }
        let fault = plan.fault.filter(|f| f.contains(rel));
        let offset = fault.map_or_else(Vector3::zeros, |f| fault_offset(&f, rel));
        let p = geo::apply_offset(&r.lla, &(noise + offset));
        let mut block = GnssBlock {
            lat: p.lat,
            lon: p.lon,
            h: p.h,
            vel: Some((r.vel + vnoise).into()),
            pos_sigma: Some([n.pos_sigma_h_m, n.pos_sigma_h_m, n.pos_sigma_v_m]),
            vel_sigma: Some([n.vel_sigma_mps; 3]),
        };
        match (fault.map(|f| f.kind), &frozen) {
            (Some(FaultKind::Frozen), Some(held)) => block = held.clone(),
            (Some(FaultKind::Frozen), None) => frozen = Some(block.clone()),
            _ => frozen = None,
        }
        let truth = geo::apply_offset(&r.lla, &noise);
        let fixed = Lla {
            lat: block.lat,
            lon: block.lon,
            h: block.h,
        };
        let error = geo::local_offset(&fixed, &truth);
        if fault.is_some() {
            injected.push((i, error));
        }
        epochs[i].gnss = Some(block);
    }
    (epochs, injected)
}

#[cfg(test)]
mod tests {
    use super::*;
    use navguard_core::epoch::ImuBlock;

    fn reference() -> Vec<RefFix> {
        let start = Lla {
            lat: 0.7,
            lon: -1.8,
            h: 1600.0,
        };
        (0..=400)
            .map(|k| {
                let t = 1000.0 + k as f64 * 0.25;
                RefFix {
                    t,
                    lla: geo::apply_offset(&start, &Vector3::new(0.0, 10.0 * (t - 1000.0), 0.0)),
                    vel: Vector3::new(0.0, 10.0, 0.0),
                }
            })
            .collect()
    }

    fn imu() -> Vec<Epoch> {
        (0..10_000)
            .map(|k| Epoch {
                t: 1000.0 + k as f64 * 0.01,
                imu: Some(ImuBlock::default()),
                ..Epoch::default()
            })
            .collect()
    }

    #[test]
    fn the_reference_interpolates_linearly_and_stops_at_its_ends() {
        let r = reference();
        let (p, v) = reference_at(&r, 1010.1).unwrap();
        let d = geo::local_offset(&p, &r[0].lla);
        assert!((d.y - 101.0).abs() < 1e-6 && d.x.abs() < 1e-6, "{d}");
        assert_eq!(v, Vector3::new(0.0, 10.0, 0.0));
        assert!(reference_at(&r, 999.0).is_none());
        assert!(reference_at(&r, 1100.01).is_none());
    }

    #[test]
    fn the_aid_is_decimated_noisy_out_in_outages_and_faulted_only_in_its_window() {
        let (r, imu) = (reference(), imu());
        let noise = AidNoise::default();
        let plain = AidPlan {
            noise,
            outages: vec![20.0],
            outage_s: 15.0,
            fault: None,
            seed: 7,
        };
        let (epochs, injected) = with_aid(&imu, &r, &plain);
        let fixes: Vec<&Epoch> = epochs.iter().filter(|e| e.gnss.is_some()).collect();
        // 100 s of reference at 1 Hz (t = 1000 … 1099, the last fix at 1100 is past
        // the IMU), less the 15 in the outage.
        assert_eq!(fixes.len(), 100 - 15);
        assert!(injected.is_empty());
        assert!(fixes.iter().all(|e| !(1020.0..1035.0).contains(&e.t)));
        // The noise has its σ (85 samples per axis; a loose bound).
        let east: Vec<f64> = fixes
            .iter()
            .map(|e| {
                let g = e.gnss.as_ref().unwrap();
                let (truth, _) = reference_at(&r, e.t).unwrap();
                let fix = Lla {
                    lat: g.lat,
                    lon: g.lon,
                    h: g.h,
                };
                geo::local_offset(&fix, &truth).x
            })
            .collect();
        let rms = (east.iter().map(|x| x * x).sum::<f64>() / east.len() as f64).sqrt();
        assert!((1.0..2.1).contains(&rms), "east rms {rms}");
        // A 2 m/s ramp from 50 s for 10 s: injected error 2·(t − 50) east, nothing else.
        let ramp = AidPlan {
            fault: Some(FaultWindow {
                kind: FaultKind::Ramp(2.0),
                start: 50.0,
                duration: 10.0,
            }),
            ..plain.clone()
        };
        let (faulted, injected) = with_aid(&imu, &r, &ramp);
        assert_eq!(injected.len(), 10);
        for (i, err) in &injected {
            let since = imu[*i].t - 1050.0;
            // Second order of the local-plane offsets (noise plus ramp, tens of metres).
            assert!((err.x - 2.0 * since).abs() < 1e-4, "{err} at {since}");
        }
        let same = faulted
            .iter()
            .zip(&epochs)
            .filter(|(a, _)| !(1050.0..1060.0).contains(&a.t))
            .all(|(a, b)| a.gnss == b.gnss);
        assert!(same, "outside the window the aid is the fault-free run's");
        // A frozen receiver repeats its first faulted fix.
        let frozen = AidPlan {
            fault: Some(FaultWindow {
                kind: FaultKind::Frozen,
                start: 50.0,
                duration: 10.0,
            }),
            ..plain
        };
        let (held, injected) = with_aid(&imu, &r, &frozen);
        let blocks: Vec<&GnssBlock> = held
            .iter()
            .filter(|e| (1050.0..1060.0).contains(&e.t))
            .filter_map(|e| e.gnss.as_ref())
            .collect();
        assert_eq!(blocks.len(), 10);
        assert!(blocks.iter().all(|b| *b == blocks[0]));
        // At 10 m/s north, the frozen fix lags by 10 m per second.
        let last = injected.last().unwrap().1;
        assert!((last.y + 90.0).abs() < 5.0, "{last}");
    }
}
