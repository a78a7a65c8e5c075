//! Fault injection on the aid channels (docs/methods.md §M19): step and ramp (seed 000
//! eq. 25), stuck, constant gain, constant bias and complete failure (seed 001
//! §1), plus a missing block, each on one component of one aid channel over a
//! time interval. Sits between `sensors` (which produce the healthy, noisy
//! readings) and the epochs a scenario emits.
//!
//! A channel is a small vector in the aid's native units, in ENU order:
//! - `gnss.position` and `cns.position`: `[lon (rad), lat (rad), h (m)]` (CNS has no h);
//!   additive magnitudes (step, ramp rate, bias) are given in **metres** east,
//!   north, up and converted with the radii at the reading
//!   (`Δλ = d_e / ((R_N + h) cos L)`, `ΔL = d_n / (R_M + h)`);
//! - `gnss.velocity`: `[v_e, v_n, v_u]` (m/s); `dvl.velocity`: body `[x, y, z]` (m/s).
//!
//! Kinds, with `u` the healthy reading and `t₁` the start: step `u + value`
//! and bias `u + M` (the same transformation, named after seed 000 and seed 001
//! respectively), ramp `u + rate·(t − t₁)`, stuck `C` = the reading at the first
//! sample inside the interval, gain `K·u` (in native units, so meant for velocity
//! channels — on a position it scales the raw coordinate), failure `0`, missing:
//! the block (GNSS position: the whole fix) is absent. A fault is active on
//! `start_s ≤ t < end_s` (`end_s` absent: to the end). Several faults on one
//! channel apply in list order.

use serde::{Deserialize, Serialize};

use super::SimError;
use navguard_core::geo;

/// The aiding sensors: the federated monitor's aids.
use navguard_core::epoch::Aid;

/// A channel of an aid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Channel {
    /// Position (GNSS, CNS).
    Position,
    /// Velocity (GNSS ENU, DVL body).
    Velocity,
}

/// Number of components of an aid's channel, `None` if the aid has no such channel.
pub fn channel_dims(aid: Aid, channel: Channel) -> Option<usize> {
    match (aid, channel) {
        (Aid::Gnss, _) | (Aid::Dvl, Channel::Velocity) => Some(3),
        (Aid::Cns, Channel::Position) => Some(2),
        (Aid::Dvl, Channel::Position) | (Aid::Cns, Channel::Velocity) => None,
    }
}

/// How a fault transforms the reading `u` (module doc for units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum FaultKind {
    /// `u + value` (seed 000's step).
    Step {
        /// Added value (metres for positions, m/s for velocities).
        value: f64,
    },
    /// `u + rate·(t − start_s)` (seed 000 eq. 25).
    Ramp {
        /// Drift rate (m/s for positions, m/s² for velocities).
        rate: f64,
    },
    /// `C`: the reading at the first sample inside the interval, held.
    Stuck,
    /// `K·u`.
    Gain {
        /// The gain K.
        k: f64,
    },
    /// `u + M` (seed 001's constant bias).
    Bias {
        /// The bias M (metres for positions, m/s for velocities).
        m: f64,
    },
    /// `0`.
    Failure,
    /// The block is absent (the component is ignored).
    Missing,
}

/// One fault: what, where and when.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Fault {
    /// The faulty aid.
    pub aid: Aid,
    /// Its channel.
    pub channel: Channel,
    /// Component index in ENU / body-xyz order (0 east or x, 1 north or y, 2 up or z).
    pub component: usize,
    /// The transformation.
    pub kind: FaultKind,
    /// Onset, s.
    pub start_s: f64,
    /// End (exclusive), s; `None` lasts to the end of the run.
    pub end_s: Option<f64>,
}

impl Fault {
    /// Whether the fault acts at time `t` (`start_s ≤ t < end_s`).
    pub fn is_active(&self, t: f64) -> bool {
        t >= self.start_s && self.end_s.is_none_or(|e| t < e)
    }

    /// Checks the aid/channel pair, the component, the interval and the parameters.
    pub fn check(&self) -> Result<(), String> {
        let dims = channel_dims(self.aid, self.channel)
            .ok_or_else(|| format!("{} has no {:?} channel", self.aid.as_str(), self.channel))?;
        if self.component >= dims {
            return Err(format!(
                "component {} out of range (channel has {dims})",
                self.component
            ));
        }
        if !(self.start_s.is_finite() && self.start_s >= 0.0) {
            return Err(format!(
                "start_s must be finite and ≥ 0, got {}",
                self.start_s
            ));
        }
        if let Some(e) = self.end_s {
            if !(e.is_finite() && e > self.start_s) {
                return Err(format!("end_s must be finite and > start_s, got {e}"));
            }
        }
        let param = match self.kind {
            FaultKind::Step { value: p }
            | FaultKind::Ramp { rate: p }
            | FaultKind::Gain { k: p }
            | FaultKind::Bias { m: p } => p,
            FaultKind::Stuck | FaultKind::Failure | FaultKind::Missing => 0.0,
        };
        if !param.is_finite() {
            return Err(format!("fault parameter must be finite, got {param}"));
        }
        Ok(())
    }
}

/// Metres per arc-minute of (longitude, latitude) at latitude `lat` (rad) and
/// height `h` (m): `((R_N + h) cos L, R_M + h) · π / 10 800`.
pub fn arcmin_to_metres(lat: f64, h: f64) -> (f64, f64) {
    let r = geo::radii(lat);
    let arcmin = std::f64::consts::PI / 10_800.0;
    (
        (r.prime_vertical + h) * lat.cos() * arcmin,
        (r.meridian + h) * arcmin,
    )
}

/// Applies a list of faults to the channels as readings are produced; remembers
/// each stuck fault's held value.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultInjector {
    faults: Vec<Fault>,
    held: Vec<Option<f64>>,
}

impl FaultInjector {
    /// Validates the faults.
    ///
    /// # Errors
    /// [`SimError::InvalidFault`] with the index of the first bad fault.
    pub fn new(faults: Vec<Fault>) -> Result<Self, SimError> {
        for (index, f) in faults.iter().enumerate() {
            f.check()
                .map_err(|reason| SimError::InvalidFault { index, reason })?;
        }
        let held = vec![None; faults.len()];
        Ok(FaultInjector { faults, held })
    }

    /// The faults, in order.
    pub fn faults(&self) -> &[Fault] {
        &self.faults
    }

    /// Transforms the reading `values` of `aid`'s `channel` at time `t` in place;
    /// `metres_per_unit[i]` converts component i's additive magnitudes (1 for
    /// velocities). Returns `false` when a `missing` fault removes the block.
    pub fn apply(
        &mut self,
        aid: Aid,
        channel: Channel,
        t: f64,
        values: &mut [f64],
        metres_per_unit: &[f64],
    ) -> bool {
        let mut present = true;
        for (fault, held) in self.faults.iter().zip(self.held.iter_mut()) {
            if fault.aid != aid || fault.channel != channel || !fault.is_active(t) {
                continue;
            }
            let c = fault.component;
            let (Some(u), Some(&scale)) = (values.get(c).copied(), metres_per_unit.get(c)) else {
                continue;
            };
            values[c] = match fault.kind {
                FaultKind::Step { value } => u + value / scale,
                FaultKind::Bias { m } => u + m / scale,
                FaultKind::Ramp { rate } => u + rate * (t - fault.start_s) / scale,
                FaultKind::Stuck => *held.get_or_insert(u),
                FaultKind::Gain { k } => k * u,
                FaultKind::Failure => 0.0,
                FaultKind::Missing => {
                    present = false;
                    u
                }
            };
        }
        present
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn fault(kind: FaultKind) -> Fault {
        Fault {
            aid: Aid::Dvl,
            channel: Channel::Velocity,
            component: 1,
            kind,
            start_s: 10.0,
            end_s: Some(20.0),
        }
    }

    /// Runs one fault over t = 0..30 s on a reading u(t) = [1, 5 + 0.1 t, 3].
    fn run(kind: FaultKind) -> Vec<(f64, [f64; 3], bool)> {
        let mut inj = FaultInjector::new(vec![fault(kind)]).unwrap();
        (0..30)
            .map(|i| {
                let t = f64::from(i);
                let mut v = [1.0, 5.0 + 0.1 * t, 3.0];
                let present = inj.apply(Aid::Dvl, Channel::Velocity, t, &mut v, &[1.0; 3]);
                (t, v, present)
            })
            .collect()
    }

    #[test]
    fn each_kind_transforms_the_component_on_its_interval_only() {
        let kinds = [
            FaultKind::Step { value: 2.0 },
            FaultKind::Ramp { rate: 0.5 },
            FaultKind::Stuck,
            FaultKind::Gain { k: 1.5 },
            FaultKind::Bias { m: -0.7 },
            FaultKind::Failure,
            FaultKind::Missing,
        ];
        for kind in kinds {
            for (t, v, present) in run(kind) {
                let u = 5.0 + 0.1 * t;
                assert_eq!(
                    (v[0], v[2]),
                    (1.0, 3.0),
                    "{kind:?}: other components untouched"
                );
                if !(10.0..20.0).contains(&t) {
                    assert_eq!(v[1], u, "{kind:?} at {t}");
                    assert!(present);
                    continue;
                }
                let want = match kind {
                    FaultKind::Step { value } => u + value,
                    FaultKind::Ramp { rate } => u + rate * (t - 10.0),
                    FaultKind::Stuck => 6.0,
                    FaultKind::Gain { k } => k * u,
                    FaultKind::Bias { m } => u + m,
                    FaultKind::Failure => 0.0,
                    FaultKind::Missing => u,
                };
                assert_relative_eq!(v[1], want, epsilon = 1e-12);
                assert_eq!(present, kind != FaultKind::Missing, "{kind:?} at {t}");
            }
        }
    }

    #[test]
    fn other_channels_are_untouched_and_metres_convert() {
        let mut inj = FaultInjector::new(vec![Fault {
            aid: Aid::Gnss,
            channel: Channel::Position,
            component: 1,
            kind: FaultKind::Step { value: 30.0 },
            start_s: 0.0,
            end_s: None,
        }])
        .unwrap();
        let mut vel = [1.0, 2.0, 3.0];
        assert!(inj.apply(Aid::Gnss, Channel::Velocity, 5.0, &mut vel, &[1.0; 3]));
        assert_eq!(vel, [1.0, 2.0, 3.0]);
        let mut pos = [2.0, 0.5, 10.0];
        inj.apply(
            Aid::Gnss,
            Channel::Position,
            5.0,
            &mut pos,
            &[6.0e6, 6.3e6, 1.0],
        );
        assert_relative_eq!(pos[1], 0.5 + 30.0 / 6.3e6, epsilon = 1e-15);
    }

    #[test]
    fn arcminutes_at_30n_are_37_m_north_and_32_m_east() {
        let (east, north) = arcmin_to_metres(30f64.to_radians(), 0.0);
        assert_relative_eq!(0.02 * north, 36.95, epsilon = 0.01);
        assert_relative_eq!(0.02 * east, 32.17, epsilon = 0.01);
    }

    #[test]
    fn invalid_faults_are_refused_with_their_index() {
        let ok = fault(FaultKind::Stuck);
        let bad_component = Fault {
            aid: Aid::Cns,
            channel: Channel::Position,
            component: 2,
            ..ok
        };
        let bad_channel = Fault {
            aid: Aid::Dvl,
            channel: Channel::Position,
            ..ok
        };
        let bad_interval = Fault {
            end_s: Some(5.0),
            ..ok
        };
        for bad in [bad_component, bad_channel, bad_interval] {
            assert!(matches!(
                FaultInjector::new(vec![ok, bad]),
                Err(SimError::InvalidFault { index: 1, .. })
            ));
        }
    }

    #[test]
    fn faults_serialise_for_the_cli() {
        let f = Fault {
            end_s: None,
            ..fault(FaultKind::Ramp { rate: 0.5 })
        };
        let json = serde_json::to_value(f).unwrap();
        assert_eq!(
            json,
            serde_json::json!({"aid": "dvl", "channel": "velocity", "component": 1,
                "kind": {"type": "ramp", "rate": 0.5}, "start_s": 10.0, "end_s": null})
        );
        assert_eq!(serde_json::from_value::<Fault>(json).unwrap(), f);
    }
}
