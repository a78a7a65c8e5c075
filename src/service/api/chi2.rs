//! `/api/v1/chi2/*`: χ² thresholds and missed-detection probabilities (docs/methods.md §M1).

use axum::Json;
use serde::{Deserialize, Serialize};

use crate::service::error::ApiError;
use crate::service::extract::{ApiQuery, query_integer};
use navguard_core::detect::chi2;

/// Query of `GET /api/v1/chi2/threshold`.
#[derive(Debug, Deserialize)]
pub struct ThresholdQuery {
    #[serde(deserialize_with = "query_integer")]
    dof: u32,
    p_fa: f64,
}

/// Answer of `GET /api/v1/chi2/threshold`.
#[derive(Debug, Serialize)]
pub struct ThresholdAnswer {
    dof: u32,
    p_fa: f64,
    threshold: f64,
}

fn invalid(e: chi2::Chi2Error, field: &str) -> ApiError {
    ApiError::invalid(field, e.to_string())
}

/// `T_D = F⁻¹_{χ²(dof)}(1 − p_fa)`.
pub async fn threshold(
    ApiQuery(q): ApiQuery<ThresholdQuery>,
) -> Result<Json<ThresholdAnswer>, ApiError> {
    if q.dof == 0 {
        return Err(ApiError::invalid("dof", "must be at least 1"));
    }
    let threshold = chi2::threshold(q.dof, q.p_fa).map_err(|e| invalid(e, "p_fa"))?;
    Ok(Json(ThresholdAnswer {
        dof: q.dof,
        p_fa: q.p_fa,
        threshold,
    }))
}

/// Query of `GET /api/v1/chi2/missed-detection`: the threshold as `threshold`
/// or `p_fa`; the fault as `noncentrality` (gives `p_md`) or `p_md` (gives the
/// non-centrality that reaches it).
#[derive(Debug, Deserialize)]
pub struct MissedDetectionQuery {
    #[serde(deserialize_with = "query_integer")]
    dof: u32,
    threshold: Option<f64>,
    p_fa: Option<f64>,
    noncentrality: Option<f64>,
    p_md: Option<f64>,
}

/// Answer of `GET /api/v1/chi2/missed-detection`.
#[derive(Debug, Serialize)]
pub struct MissedDetectionAnswer {
    dof: u32,
    threshold: f64,
    p_fa: f64,
    noncentrality: f64,
    p_md: f64,
}

/// `P_MD = F_{χ²(dof, λ)}(T_D)` (seed 000 eq. 18), or its inverse in λ.
pub async fn missed_detection(
    ApiQuery(q): ApiQuery<MissedDetectionQuery>,
) -> Result<Json<MissedDetectionAnswer>, ApiError> {
    if q.dof == 0 {
        return Err(ApiError::invalid("dof", "must be at least 1"));
    }
    let threshold = match (q.threshold, q.p_fa) {
        (Some(t), None) => {
            chi2::false_alarm_probability(q.dof, t).map_err(|e| invalid(e, "threshold"))?;
            t
        }
        (None, Some(p)) => chi2::threshold(q.dof, p).map_err(|e| invalid(e, "p_fa"))?,
        _ => {
            return Err(ApiError::invalid(
                "threshold",
                "give exactly one of `threshold` or `p_fa`",
            ));
        }
    };
    let p_fa =
        chi2::false_alarm_probability(q.dof, threshold).map_err(|e| invalid(e, "threshold"))?;
    let (noncentrality, p_md) = match (q.noncentrality, q.p_md) {
        (Some(lambda), None) => (
            lambda,
            chi2::missed_detection(q.dof, threshold, lambda)
                .map_err(|e| invalid(e, "noncentrality"))?,
        ),
        (None, Some(p_md)) => (
            chi2::noncentrality_for_missed_detection(q.dof, threshold, p_md)
                .map_err(|e| invalid(e, "p_md"))?,
            p_md,
        ),
        _ => {
            return Err(ApiError::invalid(
                "noncentrality",
                "give exactly one of `noncentrality` or `p_md`",
            ));
        }
    };
    Ok(Json(MissedDetectionAnswer {
        dof: q.dof,
        threshold,
        p_fa,
        noncentrality,
        p_md,
    }))
}
