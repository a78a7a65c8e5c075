//! Per-satellite health for the `gnss` monitor (docs/methods.md §M27): each satellite
//! carries the monitor's decision policy, stepped once per epoch it is seen, so seed
//! 004's counters apply per satellite. A satellite is *admitted* to the solution while
//! it is healthy, under every policy; one flagged goes `suspect`, then `isolated` under
//! counters, is tested against the others' solution while out, and is admitted again
//! once its policy is healthy.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::detect::{Decision, Health, PolicyConfig, PolicyState};
use crate::epoch::SatId;

/// The policy state of every satellite not at its initial state (a satellite never
/// flagged, or recovered to a fresh state, holds no entry).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SatHealth {
    states: BTreeMap<SatId, PolicyState>,
}

impl SatHealth {
    /// Whether `id` takes part in this epoch's solution: it is healthy.
    pub fn admitted(&self, id: SatId) -> bool {
        self.states.get(&id).is_none_or(|s| s.idle().update)
    }

    /// The health of `id` after the last epoch it was seen.
    pub fn health(&self, id: SatId) -> Health {
        self.states
            .get(&id)
            .map_or(Health::Healthy, PolicyState::health)
    }

    /// Steps the policy of `id` (under `policy` for a satellite first seen) with this
    /// epoch's exceedance; returns the decision. A satellite back at its initial state
    /// is forgotten, so the map holds only satellites with history.
    pub fn step(&mut self, id: SatId, exceeds: bool, policy: PolicyConfig) -> Decision {
        let state = self
            .states
            .entry(id)
            .or_insert_with(|| PolicyState::new(policy));
        let decision = state.step(exceeds);
        // Healthy with t1 = 0 (so t3 = 0) behaves as a fresh state whatever t2 holds:
        // the next exceedance restarts t2 at N1.
        if state.health() == Health::Healthy && state.counters().0 == 0 {
            self.states.remove(&id);
        }
        decision
    }

    /// The decision for an epoch on which `id` could not be tested: nothing changes.
    pub fn idle(&self, id: SatId) -> Decision {
        self.states.get(&id).map_or(
            PolicyState::new(PolicyConfig::Classic).idle(),
            PolicyState::idle,
        )
    }

    /// Follows a live change of the monitor's policy: satellites under another policy
    /// restart their counters under `policy` ([`SatHealth::set_policy`]).
    pub fn follow(&mut self, policy: PolicyConfig) {
        if self.states.values().any(|s| s.config() != policy) {
            self.set_policy(policy);
        }
    }

    /// A live policy change: every satellite's counters restart under `policy`, keeping
    /// its health until its next epoch decides afresh.
    pub fn set_policy(&mut self, policy: PolicyConfig) {
        for state in self.states.values_mut() {
            state.set_config(policy);
        }
    }

    /// Forgets every satellite (a new stream).
    pub fn clear(&mut self) {
        self.states.clear();
    }

    /// The satellites with history and their states, for a checkpoint.
    pub fn saved(&self) -> Vec<(String, PolicyState)> {
        self.states
            .iter()
            .map(|(id, s)| (id.to_string(), s.clone()))
            .collect()
    }

    /// Rebuilds from [`SatHealth::saved`], checking every id and counter.
    pub fn restored(saved: Vec<(String, PolicyState)>) -> Result<Self, String> {
        let mut states = BTreeMap::new();
        for (id, state) in saved {
            let id = SatId::parse(&id).map_err(|e| format!("satellite '{id}': {e}"))?;
            state.check_saved()?;
            states.insert(id, state);
        }
        Ok(SatHealth { states })
    }

    /// The number of satellites with history.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    /// Whether no satellite has history.
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }
}

/// The health states as the wire names them, per satellite with history.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SatHealthView {
    /// Satellite id (`G05`).
    pub id: String,
    /// Its health.
    pub health: Health,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn g(prn: u8) -> SatId {
        SatId::parse(&format!("G{prn:02}")).unwrap()
    }

    #[test]
    fn under_counters_a_flagged_satellite_is_out_until_n1_clean_epochs() {
        let policy = PolicyConfig::Counters { n1: 3, n2: 1 };
        let mut h = SatHealth::default();
        assert!(h.admitted(g(5)));
        assert_eq!(h.step(g(5), true, policy).health, Health::Suspect);
        assert!(!h.admitted(g(5)));
        assert_eq!(h.step(g(5), true, policy).health, Health::Isolated);
        // t1 = 2: two clean epochs bring it back (t1 counts down), before the N1 timeout.
        assert_eq!(h.step(g(5), false, policy).health, Health::Isolated);
        assert!(!h.admitted(g(5)));
        assert_eq!(h.step(g(5), false, policy).health, Health::Healthy);
        assert!(h.admitted(g(5)));
        assert!(h.is_empty(), "a recovered satellite is forgotten");
        assert!(h.admitted(g(7)) && h.health(g(7)) == Health::Healthy);
    }

    #[test]
    fn under_classic_a_satellite_is_out_exactly_while_it_exceeds() {
        let mut h = SatHealth::default();
        h.step(g(1), true, PolicyConfig::Classic);
        assert!(!h.admitted(g(1)));
        assert_eq!(h.health(g(1)), Health::Isolated);
        h.step(g(1), false, PolicyConfig::Classic);
        assert!(h.admitted(g(1)));
    }

    #[test]
    fn the_saved_states_round_trip_and_bad_ids_are_refused() {
        let policy = PolicyConfig::counters_default();
        let mut h = SatHealth::default();
        h.step(g(3), true, policy);
        let e11 = SatId::parse("E11").unwrap();
        h.step(e11, true, policy);
        let back = SatHealth::restored(h.saved()).unwrap();
        assert_eq!(back, h);
        assert_eq!(back.len(), 2);
        assert!(SatHealth::restored(vec![("X01".into(), PolicyState::new(policy))]).is_err());
    }
}
