//! One epoch of the `gnss` monitor: admit, solve, test, exclude, bound, and step every
//! satellite's health (the module doc of [`super`] has the order and its reasons).

use std::collections::BTreeMap;
use std::sync::Arc;

use nalgebra::Vector3;

use super::GnssMonitor;
use super::config::ProtectionKind;
use super::outputs::{Dops, GnssOutputs, GnssPosition, SatOutput};
use crate::epoch::{GnssRawBlock, SatObs};
use crate::filter::kalman::FilterError;
use crate::geo::{self, Lla, ecef_to_enu_rotation};
use crate::gnss::araim::AraimModel;
use crate::gnss::correct::{az_el, corrected_pseudorange, saastamoinen, sagnac_rotate};
use crate::gnss::raim::{self, FdeOutcome, RaimError};
use crate::gnss::wls::{WlsError, WlsSolution};
use crate::monitor::{Availability, Integrity, MonitorReport, Outputs, StepError};

/// The per-satellite exceedance test of a satellite left out: `|w| > k` with
/// `k² = χ²₁` threshold at the `raim` test's p_fa for dof 1 (a two-sided normal test).
fn satellite_threshold(p_fa: f64) -> Result<f64, StepError> {
    Ok(raim::threshold(1, p_fa)
        .map_err(|_| FilterError::NonFinite("per-satellite threshold"))?
        .sqrt())
}

/// A satellite's residual against a fix it is not part of, and that residual normalised
/// by `sqrt(σ² + e_losᵀ P e_los)` (the position covariance; the clock's variance is
/// left out, which makes `|w|` slightly larger: a satellite is re-admitted a little
/// later, never sooner). `None` when the fix has no clock for its constellation.
fn predicted_residual(
    obs: &SatObs,
    sol: &WlsSolution,
    monitor: &GnssMonitor,
) -> Option<(f64, f64, f64, f64)> {
    let clock = sol.clock(obs.id.constellation)?;
    let sat = sagnac_rotate(&Vector3::from(obs.pos), &sol.ecef);
    let ae = az_el(&sol.ecef, &sol.lla, &sat);
    let el = obs.el.unwrap_or(ae.el);
    let tropo = saastamoinen(sol.lla.lat, sol.lla.h, el, monitor.config.wls.rel_humidity);
    let range = (sat - sol.ecef).norm();
    let residual = corrected_pseudorange(obs, tropo) - range - clock;
    let sigma = monitor.config.wls.sigma_model.sigma(obs, el) * monitor.config.wls.sigma_scale;
    let los_enu = ecef_to_enu_rotation(sol.lla.lat, sol.lla.lon) * ((sat - sol.ecef) / range);
    let var = sigma * sigma + (los_enu.transpose() * sol.cov_enu * los_enu)[(0, 0)];
    Some((residual, residual / var.sqrt(), obs.az.unwrap_or(ae.az), el))
}

/// The solve with fault exclusion, from the last fix and, if that fails, from the
/// Earth's centre. `Ok(None)`: no fix this epoch (too few satellites, a singular
/// geometry, no convergence); `Err`: non-finite numbers.
fn solve(
    monitor: &GnssMonitor,
    admitted: &[SatObs],
    p_fa: f64,
) -> Result<Option<FdeOutcome>, StepError> {
    let params = monitor.fde_params(p_fa);
    let mut wls = monitor.config.wls.clone();
    wls.initial_ecef = monitor.last_fix.map(Vector3::from);
    let mut result = raim::fde(admitted, &wls, &params);
    if result.is_err() && wls.initial_ecef.is_some() {
        wls.initial_ecef = None;
        result = raim::fde(admitted, &wls, &params);
    }
    match result {
        Ok(outcome) => Ok(Some(outcome)),
        Err(RaimError::Wls(WlsError::NonFinite)) => {
            Err(FilterError::NonFinite("gnss least squares").into())
        }
        Err(RaimError::Wls(WlsError::InvalidParams(what))) => {
            Err(FilterError::NonFinite(what).into())
        }
        Err(_) => Ok(None),
    }
}

/// The protection levels of the final fix by the configured method; `None` when they
/// cannot be computed (no redundancy, a geometry ARAIM refuses).
fn protection(monitor: &GnssMonitor, outcome: &FdeOutcome, p_fa: f64) -> Option<(f64, f64)> {
    let sol = &outcome.solution;
    if let (ProtectionKind::Araim, Some(model)) = (monitor.config.protection, &outcome.araim) {
        return Some((model.hpl(), model.vpl()));
    }
    match monitor.config.protection {
        ProtectionKind::Slope => raim::slope_protection_levels(sol, p_fa, monitor.config.p_md)
            .ok()
            .map(|p| (p.hpl_m, p.vpl_m)),
        ProtectionKind::Araim => {
            let (sats, _) = raim::araim_inputs(sol, &monitor.config.araim);
            let model = AraimModel::fit(&sats, &monitor.config.araim.araim).ok()?;
            Some((model.hpl(), model.vpl()))
        }
    }
}

/// Availability: both levels within their limits (the vertical one when configured),
/// and the final fix consistent: a fix whose own χ² test still fails after exclusion
/// (a fault detected and not excluded) is not protected by its levels.
fn integrity(monitor: &GnssMonitor, levels: Option<(f64, f64)>, unresolved: bool) -> Integrity {
    let (hpl, vpl) = levels.unwrap_or((f64::INFINITY, f64::INFINITY));
    let vertical_ok = monitor.config.val_m.is_none_or(|val| vpl <= val);
    let state = if hpl <= monitor.config.hal_m && vertical_ok && !unresolved {
        Availability::Available
    } else {
        Availability::Unavailable
    };
    Integrity {
        state,
        // Unknown (no fix, or the budget used up by unmonitored modes): NaN, null on the wire.
        protection_level: if hpl.is_finite() { hpl } else { f64::NAN },
        alert_limit: monitor.config.hal_m,
    }
}

/// Horizontal and vertical errors of `sol` against the epoch's truth.
fn errors(sol: &WlsSolution, truth: Option<[f64; 3]>) -> (Option<f64>, Option<f64>) {
    let Some([lat, lon, h]) = truth else {
        return (None, None);
    };
    let d = geo::local_offset(&sol.lla, &Lla { lat, lon, h });
    (Some(d.x.hypot(d.y)), Some(d.z.abs()))
}

/// The epoch's step; commits only once every number is computed.
pub(super) fn step(
    monitor: &mut GnssMonitor,
    block: &GnssRawBlock,
) -> Result<MonitorReport, StepError> {
    let policy = monitor.bank.policy();
    let (admitted, left_out): (Vec<SatObs>, Vec<SatObs>) = block
        .sats
        .iter()
        .cloned()
        .partition(|s| monitor.health.admitted(s.id));
    let slot = &monitor.bank.slots()[0];
    let spec = slot.own_spec.unwrap_or(monitor.bank.spec());
    // The exclusion tests run at the p_fa of the test's threshold for the epoch's dof.
    let dof_guess = admitted.len().saturating_sub(4).max(1) as u32;
    // A raw threshold far out (calibration's) gives a p_fa that underflows: keep the
    // exclusion tests' quantiles finite.
    let p_fa = spec.p_fa(dof_guess)?.clamp(1e-15, 0.5);
    let outcome = solve(monitor, &admitted, p_fa)?;
    let k = satellite_threshold(p_fa)?;

    let mut tests = Vec::new();
    let mut pending = None;
    if let Some(test) = outcome.as_ref().and_then(|o| o.all_in_view) {
        let (o, state) = monitor.bank.preview(0, test.wssr, test.dof)?;
        tests.push(o);
        pending = Some(state);
    }
    let sol = outcome.as_ref().map(|o| &o.solution);
    let levels = outcome.as_ref().and_then(|o| protection(monitor, o, p_fa));
    let mut health = monitor.health.clone();
    health.follow(policy);
    let satellites = satellite_outputs(
        monitor,
        &mut health,
        block,
        outcome.as_ref(),
        &left_out,
        k,
        policy,
    );
    let outputs = outputs_of(monitor, outcome.as_ref(), levels, satellites, block.truth);
    let unresolved = outcome
        .as_ref()
        .is_some_and(|o| o.test.is_some_and(|t| !t.passed));
    let integrity = integrity(monitor, levels, unresolved);

    // Commit.
    if let Some(state) = pending {
        monitor.bank.commit(0, state);
    }
    monitor.health = health;
    if let Some(s) = sol {
        monitor.last_fix = Some([s.ecef.x, s.ecef.y, s.ecef.z]);
    }
    monitor.outputs = Arc::new(outputs);
    Ok(MonitorReport {
        tests,
        outputs: Outputs::Gnss(monitor.outputs.clone()),
        integrity: Some(integrity),
    })
}

/// The epoch's outputs: the final fix, its levels and errors, and every satellite.
fn outputs_of(
    monitor: &GnssMonitor,
    outcome: Option<&FdeOutcome>,
    levels: Option<(f64, f64)>,
    satellites: Vec<SatOutput>,
    truth: Option<[f64; 3]>,
) -> GnssOutputs {
    let (hal, val) = (monitor.config.hal_m, monitor.config.val_m);
    let Some(o) = outcome else {
        return GnssOutputs::without_solution(hal, val, satellites);
    };
    let s = &o.solution;
    let (hpe, vpe) = errors(s, truth);
    GnssOutputs {
        position: Some(GnssPosition {
            lat: s.lla.lat.to_degrees(),
            lon: s.lla.lon.to_degrees(),
            h: s.lla.h,
        }),
        clocks: s
            .clocks
            .iter()
            .map(|(c, v)| (c.letter().to_string(), *v))
            .collect::<BTreeMap<_, _>>(),
        dop: Some(Dops {
            gdop: s.dops.gdop,
            pdop: s.dops.pdop,
            hdop: s.dops.hdop,
            vdop: s.dops.vdop,
        }),
        hpl: levels.map(|l| l.0),
        vpl: levels.map(|l| l.1),
        hal,
        val,
        hpe,
        vpe,
        satellites,
        excluded: o.excluded.iter().map(|id| id.to_string()).collect(),
    }
}

/// Steps every satellite's policy and describes it: a used satellite by its post-fit
/// residual, an excluded or left-out one by its residual predicted from the final fix.
fn satellite_outputs(
    monitor: &GnssMonitor,
    health: &mut super::SatHealth,
    block: &GnssRawBlock,
    outcome: Option<&FdeOutcome>,
    left_out: &[SatObs],
    k: f64,
    policy: crate::detect::PolicyConfig,
) -> Vec<SatOutput> {
    let deg = |x: f64| x.to_degrees();
    block
        .sats
        .iter()
        .map(|obs| {
            let used = outcome.and_then(|o| o.solution.sats.iter().find(|s| s.id == obs.id));
            let excluded = outcome.is_some_and(|o| o.excluded.contains(&obs.id));
            let was_out = left_out.iter().any(|s| s.id == obs.id);
            let (residual, w, az, el, exceeds) = match (used, outcome) {
                (Some(s), _) => (
                    Some(s.residual_m),
                    Some(s.normalised),
                    Some(s.az_el.az),
                    Some(s.az_el.el),
                    false,
                ),
                (None, Some(o)) => match predicted_residual(obs, &o.solution, monitor) {
                    Some((r, w, az, el)) => {
                        let flagged = excluded || (was_out && w.abs() > k);
                        (Some(r), Some(w), Some(az), Some(el), flagged)
                    }
                    None => (None, None, obs.az, obs.el, excluded),
                },
                (None, None) => (None, None, obs.az, obs.el, false),
            };
            // Without a fix nothing can be tested: the satellite's state stands still.
            let decision = if outcome.is_some() {
                health.step(obs.id, exceeds, policy)
            } else {
                health.idle(obs.id)
            };
            SatOutput {
                id: obs.id.to_string(),
                el: el.map(deg),
                az: az.map(deg),
                residual,
                w,
                used: used.is_some(),
                health: decision.health,
            }
        })
        .collect()
}
