//! Decision policies (docs/methods.md §M3): turn each epoch's exceedance of a test into
//! a health state and into what the filter may do this epoch (update, take part
//! in fusion, be reset). `classic` is a per-epoch gate on the residual χ² test;
//! `traditional` is seed 004's traditional ("no recursion") method, which keeps updating
//! the guarded filter and only leaves it out of fusion; `counters` is seed 004 §2's
//! improved test with the three counters t1, t2, t3.

use serde::{Deserialize, Serialize};

/// Health of one test (and of the filter or sensor it guards).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Health {
    /// Measurements are used; the filter predicts and updates.
    #[default]
    Healthy,
    /// Counters policy only: the filter predicts without updating, still fused.
    Suspect,
    /// Left out of fusion. The measurement is not used, except under `traditional`,
    /// whose local filter still updates with it (seed 004's "no recursion" method).
    Isolated,
}

impl Health {
    /// The lower-case name used on the wire and in the store.
    pub fn as_str(self) -> &'static str {
        match self {
            Health::Healthy => "healthy",
            Health::Suspect => "suspect",
            Health::Isolated => "isolated",
        }
    }

    /// Parses the wire name.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "healthy" => Some(Health::Healthy),
            "suspect" => Some(Health::Suspect),
            "isolated" => Some(Health::Isolated),
            _ => None,
        }
    }
}

/// Error for a policy configuration that cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolicyError {
    /// With `n1 = 0` the t2 timeout fires every epoch and nothing is ever detected.
    #[error("n1 must be at least 1 (with n1 = 0 the counter t1 is cleared every epoch)")]
    ZeroN1,
}

/// Which policy a test uses and its parameters, as the REST API states it:
/// `{"kind": "classic"}`, `{"kind": "traditional"}` or
/// `{"kind": "counters", "n1": 10, "n2": 5}`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum PolicyConfig {
    /// λ > T_D rejects the measurement for this epoch (isolated for one epoch).
    #[default]
    Classic,
    /// Seed 004's traditional method: λ > T_D leaves the filter out of fusion for this
    /// epoch (isolated) but its local filter still updates with the measurement; no
    /// reset on readmission. For a monitor without fusion (`linear`) the test only
    /// reports: the filter always updates.
    Traditional,
    /// Seed 004 §2 counters. `n1`: epochs without exceedance after which t1 is
    /// cleared; `n2`: exceedances tolerated as *suspect* before *isolated*.
    Counters {
        /// t2's restart value (default 10 epochs).
        #[serde(default = "default_n1")]
        n1: u32,
        /// t3's limit (default 5 epochs).
        #[serde(default = "default_n2")]
        n2: u32,
    },
}

fn default_n1() -> u32 {
    10
}

fn default_n2() -> u32 {
    5
}

impl PolicyConfig {
    /// The counters policy with seed 004's defaults N1 = 10, N2 = 5.
    pub fn counters_default() -> Self {
        PolicyConfig::Counters {
            n1: default_n1(),
            n2: default_n2(),
        }
    }

    /// The wire name of the kind: `classic`, `traditional` or `counters`.
    pub fn kind_name(&self) -> &'static str {
        match self {
            PolicyConfig::Classic => "classic",
            PolicyConfig::Traditional => "traditional",
            PolicyConfig::Counters { .. } => "counters",
        }
    }

    /// Validates the parameters.
    pub fn check(&self) -> Result<(), PolicyError> {
        match *self {
            PolicyConfig::Counters { n1: 0, .. } => Err(PolicyError::ZeroN1),
            _ => Ok(()),
        }
    }
}

/// What the policy decided for one epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decision {
    /// The health state after this epoch.
    pub health: Health,
    /// The filter may update with this epoch's measurement.
    pub update: bool,
    /// The filter takes part in fusion this epoch.
    pub fuse: bool,
    /// The test just returned to healthy from isolated: a federated local
    /// filter is reset from the master solution (seed 004 §2).
    pub reset: bool,
}

impl Decision {
    fn for_health(health: Health, previous: Health, policy: PolicyConfig) -> Self {
        Decision {
            health,
            // seed 004 §2, traditional ("no recursion") method: the sub-filter keeps
            // filtering the measurement; only the master fusion leaves it out.
            update: health == Health::Healthy || policy == PolicyConfig::Traditional,
            fuse: health != Health::Isolated,
            reset: matches!(policy, PolicyConfig::Counters { .. })
                && previous == Health::Isolated
                && health == Health::Healthy,
        }
    }
}

/// The running state of one test's policy: its counters and current health (serde: a
/// monitor checkpoint saves it, its configuration with it).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PolicyState {
    config: PolicyConfig,
    t1: u32,
    t2: u32,
    t3: u32,
    health: Health,
}

impl PolicyState {
    /// A fresh state: healthy, `t1 = 0`, `t2 = N1`, `t3 = 0`.
    pub fn new(config: PolicyConfig) -> Self {
        let t2 = match config {
            PolicyConfig::Counters { n1, .. } => n1,
            PolicyConfig::Classic | PolicyConfig::Traditional => 0,
        };
        PolicyState {
            config,
            t1: 0,
            t2,
            t3: 0,
            health: Health::Healthy,
        }
    }

    /// The policy in force.
    pub fn config(&self) -> PolicyConfig {
        self.config
    }

    /// Checks a state read from a checkpoint: a valid configuration, counters that the
    /// policy can reach (zero outside `counters`, `t2 ≤ N1`) and room for the next
    /// exceedance; the reason otherwise.
    pub fn check_saved(&self) -> Result<(), String> {
        self.config.check().map_err(|e| e.to_string())?;
        let (t1, t2, t3) = (self.t1, self.t2, self.t3);
        let reachable = match self.config {
            PolicyConfig::Classic | PolicyConfig::Traditional => (t1, t2, t3) == (0, 0, 0),
            PolicyConfig::Counters { n1, .. } => {
                t2 <= n1 && (t1 > 0 || t3 == 0) && t1 < u32::MAX && t3 < u32::MAX
            }
        };
        if reachable {
            Ok(())
        } else {
            Err(format!(
                "policy counters ({t1}, {t2}, {t3}) cannot occur under {}",
                self.config.kind_name()
            ))
        }
    }

    /// The health after the last epoch.
    pub fn health(&self) -> Health {
        self.health
    }

    /// The counters `(t1, t2, t3)`; all zero for the classic and traditional policies.
    pub fn counters(&self) -> (u32, u32, u32) {
        (self.t1, self.t2, self.t3)
    }

    /// Replaces the policy (a live change from the REST API). The counters
    /// restart from their initial values; the current health is kept until the
    /// next epoch decides afresh.
    pub fn set_config(&mut self, config: PolicyConfig) {
        let health = self.health;
        *self = PolicyState::new(config);
        self.health = health;
    }

    /// The decision for an epoch whose test did not run (no measurement):
    /// the filter predicts only; the state and counters are unchanged.
    pub fn idle(&self) -> Decision {
        Decision {
            health: self.health,
            update: false,
            fuse: self.health != Health::Isolated,
            reset: false,
        }
    }

    /// Advances one epoch given whether the statistic exceeded its threshold.
    pub fn step(&mut self, exceeds: bool) -> Decision {
        let previous = self.health;
        self.health = match self.config {
            PolicyConfig::Classic | PolicyConfig::Traditional => {
                if exceeds {
                    Health::Isolated
                } else {
                    Health::Healthy
                }
            }
            PolicyConfig::Counters { n1, n2 } => {
                // seed 004 §2: an exceedance counts in t1 and t3 and restarts t2 at N1.
                if exceeds {
                    self.t1 += 1;
                    self.t3 += 1;
                    self.t2 = n1;
                } else {
                    self.t1 = self.t1.saturating_sub(1);
                    self.t2 = self.t2.saturating_sub(1);
                }
                // t2 is the timeout: N1 quiet epochs clear t1 whatever its value.
                if self.t2 == 0 {
                    self.t1 = 0;
                }
                if self.t1 == 0 {
                    // t3 is cleared only here, on the way through healthy.
                    self.t3 = 0;
                    Health::Healthy
                } else if self.t3 <= n2 {
                    Health::Suspect
                } else {
                    Health::Isolated
                }
            }
        };
        Decision::for_health(self.health, previous, self.config)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counters(n1: u32, n2: u32) -> PolicyState {
        PolicyState::new(PolicyConfig::Counters { n1, n2 })
    }

    #[test]
    fn classic_policy_isolates_exactly_the_exceeding_epochs() {
        let mut p = PolicyState::new(PolicyConfig::Classic);
        let d = p.step(true);
        assert_eq!(
            d,
            Decision {
                health: Health::Isolated,
                update: false,
                fuse: false,
                reset: false
            }
        );
        let d = p.step(false);
        assert_eq!(
            d,
            Decision {
                health: Health::Healthy,
                update: true,
                fuse: true,
                reset: false
            }
        );
    }

    #[test]
    fn traditional_policy_keeps_updating_but_leaves_an_exceeding_epoch_out_of_fusion() {
        let mut p = PolicyState::new(PolicyConfig::Traditional);
        assert_eq!(p.counters(), (0, 0, 0));
        let d = p.step(true);
        assert_eq!(
            d,
            Decision {
                health: Health::Isolated,
                update: true,
                fuse: false,
                reset: false
            }
        );
        // Readmitted at the next quiet epoch, without a reset (the local filter carries
        // its own, possibly contaminated, estimate back into the fusion).
        let d = p.step(false);
        assert_eq!(
            d,
            Decision {
                health: Health::Healthy,
                update: true,
                fuse: true,
                reset: false
            }
        );
        // An epoch without data: predict only, fused as the health says.
        p.step(true);
        let idle = p.idle();
        assert_eq!((idle.update, idle.fuse), (false, false));
    }

    #[test]
    fn counter_policy_starts_with_t2_at_n1() {
        let p = counters(10, 5);
        assert_eq!(p.counters(), (0, 10, 0));
        assert_eq!(p.health(), Health::Healthy);
    }

    #[test]
    fn counter_policy_walks_healthy_suspect_isolated_healthy() {
        let mut p = counters(3, 2);
        // First exceedance: t1 = 1, t3 = 1 <= N2 -> suspect, predict only, still fused.
        let d = p.step(true);
        assert_eq!(p.counters(), (1, 3, 1));
        assert_eq!(
            d,
            Decision {
                health: Health::Suspect,
                update: false,
                fuse: true,
                reset: false
            }
        );
        // Second: t3 = 2 <= N2 -> still suspect.
        assert_eq!(p.step(true).health, Health::Suspect);
        // Third: t3 = 3 > N2 -> isolated, out of fusion.
        let d = p.step(true);
        assert_eq!(p.counters(), (3, 3, 3));
        assert_eq!(
            d,
            Decision {
                health: Health::Isolated,
                update: false,
                fuse: false,
                reset: false
            }
        );
        // Quiet epochs: t1 and t2 count down; t3 stays, so still isolated.
        assert_eq!(p.step(false).health, Health::Isolated);
        assert_eq!(p.counters(), (2, 2, 3));
        assert_eq!(p.step(false).health, Health::Isolated);
        assert_eq!(p.counters(), (1, 1, 3));
        // t1 reaches 0 (and t2 too): healthy, t3 cleared, reset from the master.
        let d = p.step(false);
        assert_eq!(p.counters(), (0, 0, 0));
        assert_eq!(
            d,
            Decision {
                health: Health::Healthy,
                update: true,
                fuse: true,
                reset: true
            }
        );
    }

    #[test]
    fn t2_timeout_clears_t1_even_when_t1_is_still_positive() {
        // Five exceedances push t1 to 5; N1 = 2 quiet epochs then clear it
        // although only two decrements happened.
        let mut p = counters(2, 10);
        for _ in 0..5 {
            p.step(true);
        }
        assert_eq!(p.counters(), (5, 2, 5));
        assert_eq!(p.step(false).health, Health::Suspect);
        assert_eq!(p.counters(), (4, 1, 5));
        let d = p.step(false);
        assert_eq!(p.counters(), (0, 0, 0));
        assert_eq!(d.health, Health::Healthy);
        assert!(!d.reset, "suspect -> healthy is not a reset");
    }

    #[test]
    fn exceedance_restarts_the_t2_timeout() {
        let mut p = counters(3, 10);
        p.step(true);
        p.step(false);
        p.step(false);
        // t1 reached 0 by decrements before t2 ran out: healthy, t3 cleared.
        assert_eq!(p.health(), Health::Healthy);
        assert_eq!(p.counters(), (0, 1, 0));
        p.step(true);
        assert_eq!(p.counters(), (1, 3, 1), "an exceedance sets t2 back to N1");
    }

    #[test]
    fn t3_is_reset_only_when_healthy() {
        // Alternating exceedances keep t1 > 0, so t3 accumulates across quiet
        // epochs until it passes N2, although no two exceedances are adjacent.
        let mut p = counters(10, 2);
        p.step(true); // t1 1, t3 1
        p.step(true); // t1 2, t3 2
        p.step(false); // t1 1, t3 2 (not healthy: t3 kept)
        assert_eq!(p.counters(), (1, 9, 2));
        assert_eq!(p.health(), Health::Suspect);
        p.step(true); // t1 2, t3 3 > 2
        assert_eq!(p.health(), Health::Isolated);
        p.step(false);
        p.step(false); // t1 0 -> healthy, t3 cleared
        assert_eq!(p.health(), Health::Healthy);
        assert_eq!(p.counters().2, 0);
        p.step(true);
        assert_eq!(p.counters().2, 1, "t3 restarted from zero after healthy");
        assert_eq!(p.health(), Health::Suspect);
    }

    #[test]
    fn n2_zero_isolates_on_the_first_exceedance() {
        let mut p = counters(10, 0);
        assert_eq!(p.step(true).health, Health::Isolated);
    }

    #[test]
    fn suspect_decision_predicts_without_updating_but_is_fused() {
        let mut p = counters(10, 5);
        let d = p.step(true);
        assert_eq!(d.health, Health::Suspect);
        assert!(!d.update);
        assert!(d.fuse);
    }

    #[test]
    fn idle_epoch_keeps_state_and_counters() {
        let mut p = counters(4, 1);
        p.step(true);
        let before = p.clone();
        let d = p.idle();
        assert_eq!(p, before);
        assert_eq!(d.health, Health::Suspect);
        assert!(!d.update);
    }

    #[test]
    fn zero_n1_is_rejected() {
        assert_eq!(
            PolicyConfig::Counters { n1: 0, n2: 5 }.check(),
            Err(PolicyError::ZeroN1)
        );
        assert!(PolicyConfig::counters_default().check().is_ok());
    }

    #[test]
    fn policy_config_reads_the_wire_forms() {
        let c: PolicyConfig = serde_json::from_str(r#"{"kind":"counters","n1":7}"#).unwrap();
        assert_eq!(c, PolicyConfig::Counters { n1: 7, n2: 5 });
        let c: PolicyConfig = serde_json::from_str(r#"{"kind":"classic"}"#).unwrap();
        assert_eq!(c, PolicyConfig::Classic);
        let c: PolicyConfig = serde_json::from_str(r#"{"kind":"traditional"}"#).unwrap();
        assert_eq!(c, PolicyConfig::Traditional);
        assert_eq!(
            serde_json::to_value(c).unwrap(),
            serde_json::json!({"kind": "traditional"})
        );

        assert!(serde_json::from_str::<PolicyConfig>(r#"{"kind":"vote"}"#).is_err());
        assert!(serde_json::from_str::<PolicyConfig>(r#"{"kind":"counters","n3":1}"#).is_err());
    }
}
