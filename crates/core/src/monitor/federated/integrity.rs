//! Integrity availability of the federated solution (docs/methods.md §M24): a state of
//! the solution, not a fault of a sensor, reported with every INS epoch as
//! [`crate::monitor::Integrity`].
//!
//! - **Converging** from a (re)start (the stream's first INS epoch, a reset, or a restart
//!   after a long gap) until the first epoch whose protection level is within the alert
//!   limit (`HPL ≤ HAL`), or until `converge_max_s` have passed since the restart,
//!   whichever comes first: a filter that has not converged by then counts as converged
//!   anyway, so a solution that never gets within the limit is reported unavailable, not
//!   converging for ever.
//! - Then, every epoch: **available** when `HPL ≤ HAL`, **unavailable** otherwise; a loss
//!   in mid-run is reported at the epoch it happens, and a return at the epoch it happens.

use serde::{Deserialize, Serialize};

use crate::monitor::{Availability, Integrity};

/// The convergence tracker of one monitor (serde: a checkpoint saves it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(super) struct Convergence {
    /// The cap, s.
    max_s: f64,
    /// Time of the last (re)start, once an epoch has been judged.
    start_t: Option<f64>,
    /// The protection level has been within the limit (or the cap passed) since then.
    converged: bool,
}

impl Convergence {
    /// A tracker that has seen no epoch, with a cap of `max_s` seconds.
    pub(super) fn new(max_s: f64) -> Self {
        Convergence {
            max_s,
            start_t: None,
            converged: false,
        }
    }

    /// The integrity at epoch `t` (`restart`: the filter restarted at this epoch) with
    /// protection level `hpl` against `hal`, and the tracker after it, to commit with the
    /// monitor's step.
    pub(super) fn judge(&self, t: f64, restart: bool, hpl: f64, hal: f64) -> (Integrity, Self) {
        let mut next = *self;
        if restart || next.start_t.is_none() {
            next.start_t = Some(t);
            next.converged = false;
        }
        let within = hpl <= hal;
        let since = t - next.start_t.unwrap_or(t);
        if !next.converged && (within || since >= self.max_s) {
            next.converged = true;
        }
        let state = match (next.converged, within) {
            (false, _) => Availability::Converging,
            (true, true) => Availability::Available,
            (true, false) => Availability::Unavailable,
        };
        let integrity = Integrity {
            state,
            protection_level: hpl,
            alert_limit: hal,
        };
        (integrity, next)
    }

    /// `saved` (read from a checkpoint) as this tracker's state: the same cap, bit for bit;
    /// the reason otherwise.
    pub(super) fn restored(&self, saved: Convergence) -> Result<Convergence, String> {
        if saved.max_s.to_bits() != self.max_s.to_bits() {
            return Err(format!(
                "convergence cap {} s, the monitor's is {} s",
                saved.max_s, self.max_s
            ));
        }
        Ok(saved)
    }

    /// Back to a tracker that has seen no epoch (a new stream).
    pub(super) fn reset(&mut self) {
        *self = Convergence::new(self.max_s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `(t, restart, hpl)` epochs through a tracker with cap 100 s and HAL 25 m.
    fn states(epochs: &[(f64, bool, f64)]) -> Vec<Availability> {
        let mut c = Convergence::new(100.0);
        epochs
            .iter()
            .map(|&(t, restart, hpl)| {
                let (i, next) = c.judge(t, restart, hpl, 25.0);
                assert_eq!((i.protection_level, i.alert_limit), (hpl, 25.0));
                c = next;
                i.state
            })
            .collect()
    }

    #[test]
    fn converging_until_the_first_hpl_within_the_limit_then_per_epoch() {
        use Availability::{Available as A, Converging as C, Unavailable as U};
        let s = states(&[
            (0.0, true, 33.0),
            (1.0, false, 27.0),
            (2.0, false, 25.0),
            (3.0, false, 26.0),
            (4.0, false, 10.0),
        ]);
        assert_eq!(s, vec![C, C, A, U, A], "a mid-run loss is reported at once");
    }

    #[test]
    fn the_cap_ends_convergence_and_a_restart_begins_it_again() {
        use Availability::{Available as A, Converging as C, Unavailable as U};
        let s = states(&[
            (0.0, true, 90.0),
            (99.9, false, 90.0),
            (100.0, false, 90.0),
            (101.0, false, 20.0),
            (5000.0, true, 40.0),
            (5001.0, false, 20.0),
        ]);
        assert_eq!(s, vec![C, C, U, A, C, A]);
        let mut c = Convergence::new(100.0);
        c = c.judge(0.0, false, 5.0, 25.0).1;
        c.reset();
        assert_eq!(
            c.judge(7.0, false, 30.0, 25.0).0.state,
            C,
            "a reset starts afresh"
        );
    }
}
