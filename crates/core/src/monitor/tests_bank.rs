//! The tests of one monitor: names, dof, thresholds and policy states, shared
//! by every monitor kind so thresholds and policies behave the same everywhere.
//!
//! Two extensions serve the federated monitor: a test whose statistic's dof changes
//! from epoch to epoch (GNSS: 6 with velocity, 3 without) keeps one threshold per dof,
//! resolved when the spec is set, never per epoch ([`TestBank::add_dofs`],
//! [`TestBank::preview`]); and a test with a fixed threshold and its own policy that the
//! monitor-wide spec and policy do not touch (the HPL against the HAL,
//! [`TestBank::add_fixed`]). [`TestBank::preview`] and [`TestBank::commit`] split an
//! evaluation so a monitor can decide, finish its numerical step, and only then commit.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::detect::consistency::Consistency;
use crate::detect::{
    Decision, Health, PolicyConfig, PolicyState, Statistic, ThresholdError, ThresholdSpec,
};

/// A test's name, shared between its slot and every outcome it yields: cloning it per
/// epoch bumps a count and allocates nothing; it is freed with the last monitor using it.
pub type TestName = Arc<str>;

/// One test's running state.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TestSlot {
    /// Test name as on the wire (`residual`, `gnss`, `parity`, …).
    pub name: TestName,
    /// Degrees of freedom of its statistic.
    pub dof: u32,
    /// Effective threshold, resolved from the monitor's spec.
    pub threshold: f64,
    /// Decision policy and counters.
    pub policy: PolicyState,
    /// Other dofs the statistic may have on some epochs, each with its resolved threshold.
    pub alt_dofs: Vec<(u32, f64)>,
    /// The test's own threshold spec (a per-test setting, or a kind's own default such as
    /// the stuck test's `p_fa`); `None` follows the monitor's. Monitor-wide spec changes
    /// leave a test with its own spec alone.
    pub own_spec: Option<ThresholdSpec>,
    /// The policy is the test's own: monitor-wide policy changes leave it alone.
    pub own_policy: bool,
    /// NIS mean and autocorrelation of the normalised innovation the monitor feeds
    /// ([`TestBank::observe`]); empty for tests fed none.
    pub consistency: Consistency,
}

impl TestSlot {
    /// The cached threshold for `dof`: the primary one or one of [`TestSlot::alt_dofs`]
    /// (a raw threshold of the test's own is the same for every dof).
    pub fn threshold_for(&self, dof: u32) -> Option<f64> {
        if dof == self.dof || matches!(self.own_spec, Some(ThresholdSpec::Threshold(_))) {
            return Some(self.threshold);
        }
        self.alt_dofs
            .iter()
            .find(|&&(d, _)| d == dof)
            .map(|&(_, t)| t)
    }
}

/// The outcome of one test for one epoch.
#[derive(Debug, Clone, PartialEq)]
pub struct TestOutcome {
    /// Which test (index into the monitor's bank).
    pub index: usize,
    /// Test name.
    pub name: TestName,
    /// Statistic, threshold, dof.
    pub statistic: Statistic,
    /// The policy's decision.
    pub decision: Decision,
    /// Health before this epoch.
    pub previous: Health,
}

/// A monitor's tests (serde: a monitor checkpoint saves the bank whole,
/// [`TestBank::restored`] checks it).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TestBank {
    spec: ThresholdSpec,
    policy: PolicyConfig,
    slots: Vec<TestSlot>,
}

impl TestBank {
    /// Creates a bank with the given `(name, dof)` tests, all under one
    /// threshold spec and policy.
    pub fn new(
        tests: &[(&str, u32)],
        spec: ThresholdSpec,
        policy: PolicyConfig,
    ) -> Result<Self, ThresholdError> {
        let slots = tests
            .iter()
            .map(|&(name, dof)| {
                Ok(TestSlot {
                    name: TestName::from(name),
                    dof,
                    threshold: spec.resolve(dof)?,
                    policy: PolicyState::new(policy),
                    alt_dofs: Vec::new(),
                    own_spec: None,
                    own_policy: false,
                    consistency: Consistency::default(),
                })
            })
            .collect::<Result<Vec<_>, ThresholdError>>()?;
        Ok(TestBank {
            spec,
            policy,
            slots,
        })
    }

    /// Lets test `index` also run with the statistic dofs `dofs`, resolving their thresholds
    /// now under the spec in force (and again on every [`TestBank::set_spec`]).
    pub fn add_dofs(&mut self, index: usize, dofs: &[u32]) -> Result<(), ThresholdError> {
        let slot = &mut self.slots[index];
        let spec = slot.own_spec.unwrap_or(self.spec);
        for &dof in dofs {
            if dof != slot.dof && slot.alt_dofs.iter().all(|&(d, _)| d != dof) {
                let threshold = spec.resolve(dof)?;
                slot.alt_dofs.push((dof, threshold));
            }
        }
        Ok(())
    }

    /// Adds a test with a fixed `threshold` and its own `policy`, which later spec and
    /// policy changes of the monitor do not touch. Returns its index.
    pub fn add_fixed(
        &mut self,
        name: &str,
        dof: u32,
        threshold: f64,
        policy: PolicyConfig,
    ) -> usize {
        self.slots.push(TestSlot {
            name: TestName::from(name),
            dof,
            threshold,
            policy: PolicyState::new(policy),
            alt_dofs: Vec::new(),
            own_spec: Some(ThresholdSpec::Threshold(threshold)),
            own_policy: true,
            consistency: Consistency::default(),
        });
        self.slots.len() - 1
    }

    /// Adds a test under the monitor's policy and, with `own_spec`, a threshold spec of
    /// its own (kept through monitor-wide spec changes); `None` follows the monitor's
    /// spec. Returns its index.
    pub fn add_test(
        &mut self,
        name: &str,
        dof: u32,
        own_spec: Option<ThresholdSpec>,
    ) -> Result<usize, ThresholdError> {
        let threshold = own_spec.unwrap_or(self.spec).resolve(dof)?;
        self.slots.push(TestSlot {
            name: TestName::from(name),
            dof,
            threshold,
            policy: PolicyState::new(self.policy),
            alt_dofs: Vec::new(),
            own_spec,
            own_policy: false,
            consistency: Consistency::default(),
        });
        Ok(self.slots.len() - 1)
    }

    /// Gives test `index` a threshold spec of its own, or with `None` returns it to the
    /// monitor's spec (thresholds of every dof resolved now); on error nothing changes.
    pub fn set_test_spec(
        &mut self,
        index: usize,
        own_spec: Option<ThresholdSpec>,
    ) -> Result<(), ThresholdError> {
        let spec = own_spec.unwrap_or(self.spec);
        let slot = &self.slots[index];
        let threshold = spec.resolve(slot.dof)?;
        let alt = slot
            .alt_dofs
            .iter()
            .map(|&(d, _)| Ok((d, spec.resolve(d)?)))
            .collect::<Result<Vec<_>, ThresholdError>>()?;
        let slot = &mut self.slots[index];
        slot.threshold = threshold;
        slot.alt_dofs = alt;
        slot.own_spec = own_spec;
        Ok(())
    }

    /// `saved` (read from a checkpoint) as this bank's running state: it must hold the same
    /// tests in the same order (name, dof, alternative dofs, whether the policy is the
    /// test's own), with valid policy states; the reason otherwise. Names keep this bank's
    /// shared [`TestName`]s.
    ///
    /// The checkpoint's thresholds, threshold specs (the monitor's and each test's) and
    /// policies replace this bank's, with the counters they go with: a change made after
    /// the checkpoint was written is the service's to re-apply through
    /// [`super::Monitor::tests_mut`] after the restore.
    pub fn restored(&self, saved: TestBank) -> Result<TestBank, String> {
        if saved.slots.len() != self.slots.len() {
            return Err(format!(
                "{} tests, the monitor has {}",
                saved.slots.len(),
                self.slots.len()
            ));
        }
        saved.spec.check().map_err(|e| format!("threshold: {e}"))?;
        saved.policy.check().map_err(|e| format!("policy: {e}"))?;
        let slots = self
            .slots
            .iter()
            .zip(saved.slots)
            .enumerate()
            .map(|(i, (mine, mut theirs))| {
                let alt = |s: &TestSlot| s.alt_dofs.iter().map(|&(d, _)| d).collect::<Vec<_>>();
                if *theirs.name != *mine.name
                    || theirs.dof != mine.dof
                    || alt(&theirs) != alt(mine)
                    || theirs.own_policy != mine.own_policy
                {
                    return Err(format!(
                        "test {i} is '{}' (dof {}), the monitor's is '{}' (dof {})",
                        theirs.name, theirs.dof, mine.name, mine.dof
                    ));
                }
                theirs
                    .policy
                    .check_saved()
                    .map_err(|e| format!("test '{}': {e}", mine.name))?;
                if let Some(spec) = theirs.own_spec {
                    spec.check()
                        .map_err(|e| format!("test '{}' threshold: {e}", mine.name))?;
                }
                theirs.consistency = mine
                    .consistency
                    .restored(theirs.consistency)
                    .map_err(|e| format!("test '{}': {e}", mine.name))?;
                theirs.name = mine.name.clone();
                Ok(theirs)
            })
            .collect::<Result<Vec<_>, String>>()?;
        Ok(TestBank {
            spec: saved.spec,
            policy: saved.policy,
            slots,
        })
    }

    /// The index of the test named `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.slots.iter().position(|s| &*s.name == name)
    }

    /// Feeds test `index`'s consistency diagnostics with this epoch's normalised
    /// innovation `nu` when the epoch's decision is healthy; otherwise the lag chain
    /// breaks (docs/methods.md §M22).
    pub fn observe(&mut self, index: usize, nu: &[f64], health: Health) {
        let c = &mut self.slots[index].consistency;
        if health == Health::Healthy {
            c.observe(nu);
        } else {
            c.interrupt();
        }
    }

    /// The tests.
    pub fn slots(&self) -> &[TestSlot] {
        &self.slots
    }

    /// The tests, mutably: for reading consistency summaries (which cache their
    /// bounds). Names, dofs and thresholds are the bank's to keep consistent; change
    /// them through the bank's methods.
    pub fn slots_mut(&mut self) -> &mut [TestSlot] {
        &mut self.slots
    }

    /// The threshold spec in force.
    pub fn spec(&self) -> ThresholdSpec {
        self.spec
    }

    /// The policy in force.
    pub fn policy(&self) -> PolicyConfig {
        self.policy
    }

    /// Applies a new threshold spec to every test but those with their own (primary and
    /// alternative dofs); on error nothing changes.
    pub fn set_spec(&mut self, spec: ThresholdSpec) -> Result<(), ThresholdError> {
        let resolved = self
            .slots
            .iter()
            .map(|s| {
                if s.own_spec.is_some() {
                    return Ok((s.threshold, s.alt_dofs.clone()));
                }
                let alt = s
                    .alt_dofs
                    .iter()
                    .map(|&(d, _)| Ok((d, spec.resolve(d)?)))
                    .collect::<Result<Vec<_>, ThresholdError>>()?;
                Ok((spec.resolve(s.dof)?, alt))
            })
            .collect::<Result<Vec<_>, ThresholdError>>()?;
        for (slot, (threshold, alt)) in self.slots.iter_mut().zip(resolved) {
            slot.threshold = threshold;
            slot.alt_dofs = alt;
        }
        self.spec = spec;
        Ok(())
    }

    /// Applies a new policy to every test but those with their own (counters restart,
    /// health kept).
    pub fn set_policy(&mut self, policy: PolicyConfig) {
        for slot in self.slots.iter_mut().filter(|s| !s.own_policy) {
            slot.policy.set_config(policy);
        }
        self.policy = policy;
    }

    /// Restarts every policy (each under its own configuration) from its initial
    /// counters, healthy, and forgets the consistency diagnostics.
    pub fn reset(&mut self) {
        for slot in &mut self.slots {
            slot.policy = PolicyState::new(slot.policy.config());
            slot.consistency.reset();
        }
    }

    /// Evaluates test `index` with statistic `value` and advances its policy.
    pub fn evaluate(&mut self, index: usize, value: f64) -> TestOutcome {
        let slot = &mut self.slots[index];
        let statistic = Statistic {
            value,
            threshold: slot.threshold,
            dof: slot.dof,
        };
        let previous = slot.policy.health();
        let decision = slot.policy.step(statistic.exceeds());
        TestOutcome {
            index,
            name: slot.name.clone(),
            statistic,
            decision,
            previous,
        }
    }

    /// Evaluates test `index` with a statistic of `dof` degrees of freedom against the
    /// threshold cached for that dof, without changing the bank: returns the outcome and the
    /// policy state to [`TestBank::commit`] once the monitor's step has succeeded. A dof with
    /// no cached threshold (not declared with [`TestBank::add_dofs`]) is resolved on the spot.
    pub fn preview(
        &self,
        index: usize,
        value: f64,
        dof: u32,
    ) -> Result<(TestOutcome, PolicyState), ThresholdError> {
        let slot = &self.slots[index];
        let threshold = match slot.threshold_for(dof) {
            Some(t) => t,
            None => slot.own_spec.unwrap_or(self.spec).resolve(dof)?,
        };
        let statistic = Statistic {
            value,
            threshold,
            dof,
        };
        let mut policy = slot.policy.clone();
        let decision = policy.step(statistic.exceeds());
        Ok((
            TestOutcome {
                index,
                name: slot.name.clone(),
                statistic,
                decision,
                previous: slot.policy.health(),
            },
            policy,
        ))
    }

    /// Commits a policy state computed by [`TestBank::preview`] for test `index`.
    pub fn commit(&mut self, index: usize, policy: PolicyState) {
        self.slots[index].policy = policy;
    }

    /// The decision for test `index` on an epoch where it does not run.
    pub fn idle(&self, index: usize) -> Decision {
        self.slots[index].policy.idle()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_spec_resolves_each_test_by_its_own_dof() {
        let mut bank = TestBank::new(
            &[("a", 1), ("b", 6)],
            ThresholdSpec::PFa(0.002),
            PolicyConfig::Classic,
        )
        .unwrap();
        assert!((bank.slots()[0].threshold - 9.5495).abs() < 1e-4);
        assert!((bank.slots()[1].threshold - 20.7912).abs() < 1e-4);
        bank.set_spec(ThresholdSpec::Threshold(13.0)).unwrap();
        assert_eq!(bank.slots()[1].threshold, 13.0);
    }

    #[test]
    fn failed_spec_change_leaves_thresholds_alone() {
        let mut bank = TestBank::new(
            &[("a", 2)],
            ThresholdSpec::Threshold(20.0),
            PolicyConfig::Classic,
        )
        .unwrap();
        assert!(bank.set_spec(ThresholdSpec::PFa(2.0)).is_err());
        assert_eq!(bank.slots()[0].threshold, 20.0);
        assert_eq!(bank.spec(), ThresholdSpec::Threshold(20.0));
    }

    #[test]
    fn alternative_dofs_keep_their_own_thresholds_through_spec_changes() {
        let mut bank = TestBank::new(
            &[("gnss", 6)],
            ThresholdSpec::PFa(0.002),
            PolicyConfig::Classic,
        )
        .unwrap();
        bank.add_dofs(0, &[3, 6]).unwrap();
        assert_eq!(
            bank.slots()[0].alt_dofs.len(),
            1,
            "the primary dof is not duplicated"
        );
        let (o, _) = bank.preview(0, 15.0, 3).unwrap();
        // dof 3 at p_fa 0.002: 14.7955 (seed 000 Table 1), so 15 exceeds; at dof 6 it does not.
        assert!((o.statistic.threshold - 14.7955).abs() < 1e-4);
        assert_eq!(o.statistic.dof, 3);
        assert!(o.statistic.exceeds());
        let (o, _) = bank.preview(0, 15.0, 6).unwrap();
        assert!((o.statistic.threshold - 20.7912).abs() < 1e-4);
        bank.set_spec(ThresholdSpec::PFa(1e-5)).unwrap();
        assert!((bank.slots()[0].threshold_for(3).unwrap() - 25.9017).abs() < 1e-4);
        // An undeclared dof is resolved on the spot: dof 2 at 1e-5 is 23.0259.
        let (o, _) = bank.preview(0, 1.0, 2).unwrap();
        assert!((o.statistic.threshold - 23.0259).abs() < 1e-4);
    }

    #[test]
    fn preview_changes_nothing_until_committed() {
        let mut bank = TestBank::new(
            &[("a", 2)],
            ThresholdSpec::Threshold(5.0),
            PolicyConfig::Classic,
        )
        .unwrap();
        let (o, state) = bank.preview(0, 7.0, 2).unwrap();
        assert_eq!(o.decision.health, Health::Isolated);
        assert_eq!(bank.slots()[0].policy.health(), Health::Healthy);
        bank.commit(0, state);
        assert_eq!(bank.slots()[0].policy.health(), Health::Isolated);
    }

    #[test]
    fn fixed_tests_ignore_monitor_wide_spec_and_policy_changes() {
        let mut bank = TestBank::new(
            &[("gnss", 3)],
            ThresholdSpec::Threshold(20.0),
            PolicyConfig::counters_default(),
        )
        .unwrap();
        let hpl = bank.add_fixed("hpl", 2, 40.0, PolicyConfig::Classic);
        assert_eq!(hpl, 1);
        bank.set_spec(ThresholdSpec::Threshold(13.0)).unwrap();
        bank.set_policy(PolicyConfig::Counters { n1: 3, n2: 1 });
        assert_eq!(bank.slots()[0].threshold, 13.0);
        assert_eq!(bank.slots()[1].threshold, 40.0);
        assert_eq!(bank.slots()[1].policy.config(), PolicyConfig::Classic);
        // Whatever dof is asked, a fixed test compares with its own threshold.
        let (o, _) = bank.preview(hpl, 41.0, 2).unwrap();
        assert_eq!(o.statistic.threshold, 40.0);
        assert_eq!(o.decision.health, Health::Isolated);
        bank.evaluate(hpl, 41.0);
        bank.reset();
        assert_eq!(bank.slots()[1].policy.health(), Health::Healthy);
        assert_eq!(bank.slots()[1].policy.config(), PolicyConfig::Classic);
    }

    #[test]
    fn a_test_with_its_own_spec_keeps_it_and_follows_the_monitor_policy() {
        let mut bank = TestBank::new(
            &[("gnss", 3)],
            ThresholdSpec::PFa(0.002),
            PolicyConfig::Classic,
        )
        .unwrap();
        let stuck = bank
            .add_test("gnss.stuck", 1, Some(ThresholdSpec::PFa(1e-5)))
            .unwrap();
        let drift = bank.add_test("gnss.drift", 3, None).unwrap();
        assert!((bank.slots()[stuck].threshold - 19.5114).abs() < 1e-4);
        assert!((bank.slots()[drift].threshold - 14.7955).abs() < 1e-4);
        bank.set_spec(ThresholdSpec::PFa(1e-5)).unwrap();
        bank.set_policy(PolicyConfig::counters_default());
        assert!((bank.slots()[drift].threshold - 25.9017).abs() < 1e-4);
        assert!((bank.slots()[stuck].threshold - 19.5114).abs() < 1e-4);
        assert_eq!(
            bank.slots()[stuck].policy.config(),
            PolicyConfig::counters_default()
        );
        // A per-test setting, then back to the monitor's.
        bank.set_test_spec(0, Some(ThresholdSpec::Threshold(30.0)))
            .unwrap();
        assert_eq!(bank.slots()[0].threshold, 30.0);
        assert!(
            bank.set_test_spec(0, Some(ThresholdSpec::PFa(3.0)))
                .is_err()
        );
        assert_eq!(bank.slots()[0].threshold, 30.0);
        bank.set_test_spec(0, None).unwrap();
        assert!((bank.slots()[0].threshold - 25.9017).abs() < 1e-4);
        assert_eq!(bank.index_of("gnss.drift"), Some(drift));
    }

    #[test]
    fn observe_feeds_consistency_only_on_healthy_epochs() {
        let mut bank = TestBank::new(
            &[("a", 1)],
            ThresholdSpec::PFa(0.002),
            PolicyConfig::Classic,
        )
        .unwrap();
        bank.observe(0, &[1.0], Health::Healthy);
        bank.observe(0, &[9.0], Health::Isolated);
        bank.observe(0, &[1.0], Health::Healthy);
        let mut c = bank.slots()[0].consistency.clone();
        let s = c.summary().unwrap();
        assert_eq!(s.samples, 2);
        assert_eq!(s.nis_mean, 1.0);
        assert_eq!(s.autocorr, None, "the isolated epoch broke the lag chain");
        bank.reset();
        assert!(bank.slots()[0].consistency.clone().summary().is_none());
    }

    #[test]
    fn evaluate_reports_previous_and_new_health() {
        let mut bank = TestBank::new(
            &[("a", 2)],
            ThresholdSpec::Threshold(5.0),
            PolicyConfig::Classic,
        )
        .unwrap();
        let o = bank.evaluate(0, 7.0);
        assert_eq!(
            (o.previous, o.decision.health),
            (Health::Healthy, Health::Isolated)
        );
        let o = bank.evaluate(0, 1.0);
        assert_eq!(
            (o.previous, o.decision.health),
            (Health::Isolated, Health::Healthy)
        );
    }
}
