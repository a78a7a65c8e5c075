//! The tests of one monitor: names, dof, thresholds and policy states, shared
//! by every monitor kind so thresholds and policies behave the same everywhere.

use crate::detect::{
    Decision, Health, PolicyConfig, PolicyState, Statistic, ThresholdError, ThresholdSpec,
};

/// One test's running state.
#[derive(Debug, Clone)]
pub struct TestSlot {
    /// Test name as on the wire (`residual`, `gnss`, `parity`, …).
    pub name: &'static str,
    /// Degrees of freedom of its statistic.
    pub dof: u32,
    /// Effective threshold, resolved from the monitor's spec.
    pub threshold: f64,
    /// Decision policy and counters.
    pub policy: PolicyState,
}

/// The outcome of one test for one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TestOutcome {
    /// Which test (index into the monitor's bank).
    pub index: usize,
    /// Test name.
    pub name: &'static str,
    /// Statistic, threshold, dof.
    pub statistic: Statistic,
    /// The policy's decision.
    pub decision: Decision,
    /// Health before this epoch.
    pub previous: Health,
}

/// A monitor's tests.
#[derive(Debug, Clone)]
pub struct TestBank {
    spec: ThresholdSpec,
    policy: PolicyConfig,
    slots: Vec<TestSlot>,
}

impl TestBank {
    /// Creates a bank with the given `(name, dof)` tests, all under one
    /// threshold spec and policy.
    pub fn new(
        tests: &[(&'static str, u32)],
        spec: ThresholdSpec,
        policy: PolicyConfig,
    ) -> Result<Self, ThresholdError> {
        let slots = tests
            .iter()
            .map(|&(name, dof)| {
                Ok(TestSlot {
                    name,
                    dof,
                    threshold: spec.resolve(dof)?,
                    policy: PolicyState::new(policy),
                })
            })
            .collect::<Result<Vec<_>, ThresholdError>>()?;
        Ok(TestBank {
            spec,
            policy,
            slots,
        })
    }

    /// The tests.
    pub fn slots(&self) -> &[TestSlot] {
        &self.slots
    }

    /// The threshold spec in force.
    pub fn spec(&self) -> ThresholdSpec {
        self.spec
    }

    /// The policy in force.
    pub fn policy(&self) -> PolicyConfig {
        self.policy
    }

    /// Applies a new threshold spec to every test; on error nothing changes.
    pub fn set_spec(&mut self, spec: ThresholdSpec) -> Result<(), ThresholdError> {
        let thresholds = self
            .slots
            .iter()
            .map(|s| spec.resolve(s.dof))
            .collect::<Result<Vec<_>, _>>()?;
        for (slot, threshold) in self.slots.iter_mut().zip(thresholds) {
            slot.threshold = threshold;
        }
        self.spec = spec;
        Ok(())
    }

    /// Applies a new policy to every test (counters restart, health kept).
    pub fn set_policy(&mut self, policy: PolicyConfig) {
        for slot in &mut self.slots {
            slot.policy.set_config(policy);
        }
        self.policy = policy;
    }

    /// Restarts every policy from its initial counters, healthy.
    pub fn reset(&mut self) {
        for slot in &mut self.slots {
            slot.policy = PolicyState::new(self.policy);
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
            name: slot.name,
            statistic,
            decision,
            previous,
        }
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
