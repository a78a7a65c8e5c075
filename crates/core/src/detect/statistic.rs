//! The one shape every detector yields per epoch (`Statistic`) and how a user
//! states a threshold (`ThresholdSpec`: a false-alarm probability or a raw value).

use serde::{Deserialize, Serialize};

use super::chi2::{self, Chi2Error};

/// One test's outcome for one epoch: the statistic, the threshold it is
/// compared with, and the χ² degrees of freedom that threshold was derived for.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Statistic {
    /// The test statistic (e.g. λ = rᵀS⁻¹r).
    pub value: f64,
    /// The effective threshold T_D.
    pub threshold: f64,
    /// Degrees of freedom of the statistic's χ² distribution under no fault.
    pub dof: u32,
}

impl Statistic {
    /// `value / threshold`: above 1 the test fails. The one number an operator
    /// can read across detectors (docs/architecture.md §A6).
    pub fn test_ratio(&self) -> f64 {
        self.value / self.threshold
    }

    /// True when the statistic exceeds its threshold (strictly, seed 004 §2).
    pub fn exceeds(&self) -> bool {
        self.value > self.threshold
    }
}

/// Error for a threshold specification that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ThresholdError {
    /// Both `p_fa` and `threshold` were given, or neither made sense.
    #[error("give exactly one of `p_fa` or `threshold`")]
    Ambiguous,
    /// The probability or raw value is out of range.
    #[error(transparent)]
    Chi2(#[from] Chi2Error),
}

/// How a monitor's threshold is stated: as a false-alarm probability (the
/// threshold then follows each test's dof) or as a raw value used for every test.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ThresholdSpec {
    /// `T_D = F⁻¹_{χ²(dof)}(1 − p_fa)` per test (docs/methods.md §M1).
    PFa(f64),
    /// A fixed threshold, whatever the dof (seed 004 uses 13 and 20).
    Threshold(f64),
}

impl Default for ThresholdSpec {
    /// p_fa = 0.002, the value of seed 000's Table 1.
    fn default() -> Self {
        ThresholdSpec::PFa(0.002)
    }
}

impl ThresholdSpec {
    /// Builds a spec from the optional `p_fa` / `threshold` pair of the wire
    /// format; neither gives the default, both is an error.
    pub fn from_parts(p_fa: Option<f64>, threshold: Option<f64>) -> Result<Self, ThresholdError> {
        let spec = match (p_fa, threshold) {
            (Some(_), Some(_)) => return Err(ThresholdError::Ambiguous),
            (Some(p), None) => ThresholdSpec::PFa(p),
            (None, Some(t)) => ThresholdSpec::Threshold(t),
            (None, None) => ThresholdSpec::default(),
        };
        spec.check()?;
        Ok(spec)
    }

    /// Validates the spec independently of any dof.
    pub fn check(&self) -> Result<(), ThresholdError> {
        match *self {
            ThresholdSpec::PFa(p) => {
                if !(p > 0.0 && p < 1.0) {
                    return Err(Chi2Error::InvalidProbability(p).into());
                }
            }
            ThresholdSpec::Threshold(t) => {
                if !(t.is_finite() && t > 0.0) {
                    return Err(Chi2Error::InvalidThreshold(t).into());
                }
            }
        }
        Ok(())
    }

    /// The effective threshold for a test with `dof` degrees of freedom.
    pub fn resolve(&self, dof: u32) -> Result<f64, ThresholdError> {
        match *self {
            ThresholdSpec::PFa(p) => Ok(chi2::threshold(dof, p)?),
            ThresholdSpec::Threshold(t) => {
                self.check()?;
                Ok(t)
            }
        }
    }

    /// The false-alarm probability this spec gives for `dof`: the stated one,
    /// or the χ² survival at the raw threshold.
    pub fn p_fa(&self, dof: u32) -> Result<f64, ThresholdError> {
        match *self {
            ThresholdSpec::PFa(p) => Ok(p),
            ThresholdSpec::Threshold(t) => Ok(chi2::false_alarm_probability(dof, t)?),
        }
    }

    /// The `p_fa` half of the wire pair.
    pub fn p_fa_part(&self) -> Option<f64> {
        match *self {
            ThresholdSpec::PFa(p) => Some(p),
            ThresholdSpec::Threshold(_) => None,
        }
    }

    /// The `threshold` half of the wire pair.
    pub fn threshold_part(&self) -> Option<f64> {
        match *self {
            ThresholdSpec::PFa(_) => None,
            ThresholdSpec::Threshold(t) => Some(t),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn test_ratio_is_statistic_over_threshold() {
        let s = Statistic {
            value: 30.0,
            threshold: 20.0,
            dof: 2,
        };
        assert_relative_eq!(s.test_ratio(), 1.5);
        assert!(s.exceeds());
        let at = Statistic {
            value: 20.0,
            threshold: 20.0,
            dof: 2,
        };
        assert!(!at.exceeds(), "equality does not exceed: λ > T_D is strict");
    }

    #[test]
    fn p_fa_spec_resolves_to_the_chi2_quantile_per_dof() {
        let spec = ThresholdSpec::PFa(0.002);
        assert_relative_eq!(spec.resolve(1).unwrap(), 9.5495, epsilon = 5e-5);
        assert_relative_eq!(spec.resolve(6).unwrap(), 20.7912, epsilon = 5e-5);
    }

    #[test]
    fn raw_threshold_is_used_for_every_dof_and_reports_its_p_fa() {
        let spec = ThresholdSpec::Threshold(20.0);
        assert_eq!(spec.resolve(1).unwrap(), 20.0);
        assert_eq!(spec.resolve(6).unwrap(), 20.0);
        // χ²(2) survival at 20 is exp(-10).
        assert_relative_eq!(
            spec.p_fa(2).unwrap(),
            (-10.0f64).exp(),
            max_relative = 1e-10
        );
    }

    #[test]
    fn wire_pair_must_name_at_most_one_form() {
        assert_eq!(
            ThresholdSpec::from_parts(Some(0.01), Some(3.0)),
            Err(ThresholdError::Ambiguous)
        );
        assert_eq!(
            ThresholdSpec::from_parts(None, None),
            Ok(ThresholdSpec::PFa(0.002))
        );
        assert!(ThresholdSpec::from_parts(Some(1.5), None).is_err());
        assert!(ThresholdSpec::from_parts(None, Some(-1.0)).is_err());
        assert!(ThresholdSpec::from_parts(None, Some(f64::NAN)).is_err());
    }
}
