//! `/api/v1/sessions/{id}/monitors/{name}/threshold`: read and change a
//! monitor's threshold and policy, applied to the live session at once and persisted.

use axum::Json;
use axum::extract::{Path, State};

use crate::service::app::AppState;
use crate::service::error::ApiError;
use crate::service::extract::ApiJson;
use crate::service::wire::{ThresholdUpdate, ThresholdView};

/// `GET …/threshold`
pub async fn get(
    State(state): State<AppState>,
    Path((id, name)): Path<(String, String)>,
) -> Result<Json<ThresholdView>, ApiError> {
    let handle = state
        .registry
        .get(&id)
        .ok_or_else(|| ApiError::NotFound(format!("no session '{id}'")))?;
    Ok(Json(handle.threshold(&name).await?))
}

/// `PUT …/threshold` with `p_fa` or `threshold`, and/or `policy`.
pub async fn put(
    State(state): State<AppState>,
    Path((id, name)): Path<(String, String)>,
    ApiJson(update): ApiJson<ThresholdUpdate>,
) -> Result<Json<ThresholdView>, ApiError> {
    let handle = state
        .registry
        .get(&id)
        .ok_or_else(|| ApiError::NotFound(format!("no session '{id}'")))?;
    // The actor stores the change before it answers, in the order changes are applied.
    Ok(Json(handle.set_threshold(&name, update).await?))
}
