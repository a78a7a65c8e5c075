//! Pseudorange faults for the RAIM experiment: a step or a ramp added to chosen
//! satellites from a start time on.

use navguard_core::epoch::{Epoch, SatId};

/// The shape of a fault.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultKind {
    /// A constant bias, m.
    Step(f64),
    /// A bias growing from zero at the start, m/s.
    Ramp(f64),
}

/// A fault case: its shape and how many satellites carry it (each draw picks them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    /// Step or ramp.
    pub kind: FaultKind,
    /// Satellites faulted at once (1 or 2).
    pub satellites: usize,
}

impl Fault {
    /// Steps of 5, 10, 20, 50 and 100 m and ramps of 0.1, 0.5, 1 and 2 m/s on one
    /// satellite, and a 50 m step on two.
    pub fn standard_cases() -> Vec<Fault> {
        let one = |kind| Fault {
            kind,
            satellites: 1,
        };
        let mut v: Vec<Fault> = [5.0, 10.0, 20.0, 50.0, 100.0]
            .into_iter()
            .map(|m| one(FaultKind::Step(m)))
            .collect();
        v.extend(
            [0.1, 0.5, 1.0, 2.0]
                .into_iter()
                .map(|r| one(FaultKind::Ramp(r))),
        );
        v.push(Fault {
            kind: FaultKind::Step(50.0),
            satellites: 2,
        });
        v
    }

    /// The case's label in the tables: `step 50 m`, `ramp 1 m/s`, `step 50 m ×2`.
    pub fn label(&self) -> String {
        let shape = match self.kind {
            FaultKind::Step(m) => format!("step {m} m"),
            FaultKind::Ramp(r) => format!("ramp {r} m/s"),
        };
        if self.satellites > 1 {
            format!("{shape} ×{}", self.satellites)
        } else {
            shape
        }
    }

    /// The bias at `dt` seconds after the start.
    pub fn bias(&self, dt: f64) -> f64 {
        match self.kind {
            FaultKind::Step(m) => m,
            FaultKind::Ramp(r) => r * dt,
        }
    }
}

/// `epochs` with `fault` added to the pseudoranges of `sats` at and after `start_t`.
pub(super) fn apply(epochs: &[Epoch], fault: &Fault, sats: &[SatId], start_t: f64) -> Vec<Epoch> {
    epochs
        .iter()
        .map(|e| {
            let mut e = e.clone();
            if e.t >= start_t {
                if let Some(b) = e.gnss_raw.as_mut() {
                    for s in b.sats.iter_mut().filter(|s| sats.contains(&s.id)) {
                        s.pr += fault.bias(e.t - start_t);
                    }
                }
            }
            e
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use navguard_core::epoch::{GnssRawBlock, SatObs};

    fn sat(id: &str) -> SatObs {
        SatObs {
            id: SatId::parse(id).unwrap(),
            pr: 2e7,
            pos: [2.6e7, 0.0, 0.0],
            clk: 0.0,
            iono: None,
            tropo: None,
            sigma: None,
            cn0: None,
            el: None,
            az: None,
        }
    }

    #[test]
    fn a_ramp_starts_at_zero_and_only_the_chosen_satellites_move() {
        let epochs: Vec<Epoch> = (0..4)
            .map(|k| Epoch {
                t: 30.0 * k as f64,
                gnss_raw: Some(GnssRawBlock {
                    sats: vec![sat("G01"), sat("G02")],
                    truth: None,
                }),
                ..Epoch::default()
            })
            .collect();
        let fault = Fault {
            kind: FaultKind::Ramp(0.5),
            satellites: 1,
        };
        let out = apply(&epochs, &fault, &[SatId::parse("G02").unwrap()], 30.0);
        let pr = |k: usize, i: usize| out[k].gnss_raw.as_ref().unwrap().sats[i].pr - 2e7;
        assert_eq!(
            [pr(0, 1), pr(1, 1), pr(2, 1), pr(3, 1)],
            [0.0, 0.0, 15.0, 30.0]
        );
        assert_eq!([pr(0, 0), pr(3, 0)], [0.0, 0.0]);
        assert_eq!(Fault::standard_cases().len(), 10);
        assert_eq!(Fault::standard_cases()[9].label(), "step 50 m ×2");
    }
}
