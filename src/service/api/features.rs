//! `POST /api/v1/features`: the feature vectors the `rimu` and `tacan` monitors
//! compute (wavelet-packet energies of a signal window, TACAN window features of
//! two range series), so analysts can build training sets with the same code.

use axum::Json;
use axum::body::Bytes;
use axum::extract::State;
use axum::extract::rejection::BytesRejection;
use axum::http::HeaderMap;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};

use super::models::{json_body, numbers, object};
use crate::service::app::AppState;
use crate::service::error::ApiError;
use navguard_core::features::FeatureError;
use navguard_core::features::tacan::{TacanFeatureParams, series_features};
use navguard_core::features::wavelet::{WaveletPacketParams, packet_energies};

/// The answer: one feature vector per window.
#[derive(Debug, Serialize)]
pub struct FeaturesResponse {
    features: Vec<Vec<f64>>,
}

/// `POST /api/v1/features` with `kind` `wavelet-packet` (`signal`, `wavelet`,
/// `level`, `normalize`) or `tacan-window` (`ins_range_m`, `tacan_range_m`,
/// `window`, `crest`).
pub async fn compute(
    State(state): State<AppState>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Json<FeaturesResponse>, ApiError> {
    let body = json_body(&headers, body)?;
    let max = state.config.limits.max_training_values;
    let kind = body.get("kind").and_then(Value::as_str).map(str::to_owned);
    let features = match kind.as_deref() {
        Some("wavelet-packet") => {
            let mut body = object(
                body,
                "",
                &["kind", "signal", "wavelet", "level", "normalize"],
            )?;
            let signal = required(&mut body, "signal").and_then(|v| numbers(&v, "signal", max))?;
            let params: WaveletPacketParams = rest(body)?;
            // A signal window is short; compute inline.
            vec![packet_energies(&signal, &params).map_err(feature_error)?]
        }
        Some("tacan-window") => {
            let allowed = ["kind", "ins_range_m", "tacan_range_m", "window", "crest"];
            let mut body = object(body, "", &allowed)?;
            let ins =
                required(&mut body, "ins_range_m").and_then(|v| numbers(&v, "ins_range_m", max))?;
            let tacan = required(&mut body, "tacan_range_m")
                .and_then(|v| numbers(&v, "tacan_range_m", max))?;
            let params: TacanFeatureParams = rest(body)?;
            // A long series is O(n × window): off the async executor.
            tokio::task::spawn_blocking(move || series_features(&ins, &tacan, &params))
                .await
                .map_err(|e| ApiError::Internal(format!("features task: {e}")))?
                .map_err(feature_error)?
        }
        Some(other) => {
            return Err(ApiError::invalid(
                "kind",
                format!("unknown feature kind '{other}'; one of wavelet-packet, tacan-window"),
            ));
        }
        None => {
            return Err(ApiError::invalid(
                "kind",
                "required: wavelet-packet or tacan-window",
            ));
        }
    };
    finite_features(&features, kind.as_deref())?;
    Ok(Json(FeaturesResponse { features }))
}

/// Refuses input so large that a feature overflows (squares of 1e200 are
/// infinite): a 422 rather than a `null` in the answer, which JSON would carry
/// for a non-finite number.
fn finite_features(features: &[Vec<f64>], kind: Option<&str>) -> Result<(), ApiError> {
    let Some(window) = features
        .iter()
        .position(|f| f.iter().any(|v| !v.is_finite()))
    else {
        return Ok(());
    };
    Err(match kind {
        Some("wavelet-packet") => ApiError::invalid(
            "signal",
            "its energies overflow: the values are too large for finite energies",
        ),
        _ => ApiError::Invalid {
            field: None,
            message: format!(
                "the features of window {window} (samples {window}.. of ins_range_m and \
                 tacan_range_m) overflow: the ranges are too large for finite features"
            ),
        },
    })
}

fn required(body: &mut Map<String, Value>, key: &str) -> Result<Value, ApiError> {
    body.remove(key)
        .ok_or_else(|| ApiError::invalid(key, "required"))
}

/// The remaining keys (all but `kind`) as the feature parameters. Every
/// parameter has a default, so a key that fails on its own is the bad one.
fn rest<T: DeserializeOwned>(mut body: Map<String, Value>) -> Result<T, ApiError> {
    body.remove("kind");
    let all = Value::Object(body.clone());
    serde_json::from_value(all).map_err(|e| {
        let field = body.iter().find_map(|(k, v)| {
            let alone = Value::Object(Map::from_iter([(k.clone(), v.clone())]));
            serde_json::from_value::<T>(alone)
                .is_err()
                .then(|| k.clone())
        });
        ApiError::Invalid {
            field,
            message: e.to_string(),
        }
    })
}

fn feature_error(e: FeatureError) -> ApiError {
    ApiError::invalid(e.field, e.reason)
}
