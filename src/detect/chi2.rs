//! TEMPORARY STUB (replaced by helper)
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Chi2Error {
    #[error("dof")] InvalidDof(u32),
    #[error("p {0}")] InvalidProbability(f64),
    #[error("t {0}")] InvalidThreshold(f64),
    #[error("l {0}")] InvalidNoncentrality(f64),
    #[error("u")] Unreachable { p_md: f64, threshold: f64, max: f64 },
}
pub fn threshold(dof: u32, p_fa: f64) -> Result<f64, Chi2Error> { use statrs::distribution::{ChiSquared, ContinuousCDF}; if !(p_fa>0.0&&p_fa<1.0){return Err(Chi2Error::InvalidProbability(p_fa))} Ok(ChiSquared::new(dof as f64).unwrap().inverse_cdf(1.0-p_fa)) }
pub fn false_alarm_probability(dof: u32, t: f64) -> Result<f64, Chi2Error> { use statrs::distribution::{ChiSquared, ContinuousCDF}; Ok(ChiSquared::new(dof as f64).unwrap().sf(t)) }
pub fn missed_detection(_dof: u32, _t: f64, _l: f64) -> Result<f64, Chi2Error> { Ok(0.5) }
pub fn noncentrality_for_missed_detection(_dof: u32, _t: f64, _p: f64) -> Result<f64, Chi2Error> { Ok(1.0) }
