//! `/api/v1/sessions/{id}/monitors/{name}/threshold`: read and change a
//! monitor's threshold and policy, applied to the live session at once and persisted.

use axum::extract::{Path, State};
use axum::{Extension, Json};
use serde_json::{Value, json};

use crate::service::app::AppState;
use crate::service::audit::Change;
use crate::service::error::ApiError;
use crate::service::extract::{
    JsonBody, from_value, integral_numbers, refuse_nulls, refuse_nulls_at,
};
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

/// Refuses keys a policy of its `kind` does not have (422 naming `field`):
/// serde lets an internally tagged unit variant (`{"kind": "classic"}`)
/// ignore extra keys, which the contract forbids (`additionalProperties`).
pub(crate) fn check_policy_keys(policy: Option<&Value>, field: &str) -> Result<(), ApiError> {
    let Some(Value::Object(policy)) = policy else {
        return Ok(()); // absent, or not an object: the typed parse says so
    };
    let allowed: &[&str] = match policy.get("kind").and_then(Value::as_str) {
        Some("classic") | Some("traditional") => &["kind"],
        Some("counters") => &["kind", "n1", "n2"],
        _ => return Ok(()),
    };
    match policy.keys().find(|k| !allowed.contains(&k.as_str())) {
        Some(key) => Err(ApiError::invalid(
            field,
            format!(
                "unknown field `{key}`: the {} policy has {}",
                policy["kind"].as_str().unwrap_or_default(),
                allowed
                    .iter()
                    .map(|k| format!("`{k}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )),
        None => Ok(()),
    }
}

/// `PUT …/threshold` with `p_fa` or `threshold`, and/or `policy`; the audit entry
/// holds the monitor's view before and after.
pub async fn put(
    State(state): State<AppState>,
    Path((id, name)): Path<(String, String)>,
    JsonBody(mut body): JsonBody,
) -> Result<(Extension<Change>, Json<ThresholdView>), ApiError> {
    // One `null` has a meaning here: `tests: {NAME: null}` returns a test to the
    // monitor's threshold. Anywhere else it is refused.
    match body.get("tests") {
        Some(serde_json::Value::Object(tests)) => {
            for (test, spec) in tests {
                if !spec.is_null() {
                    refuse_nulls_at(spec, &format!("tests.{test}"))?;
                }
            }
            let mut rest = body.clone();
            if let Some(o) = rest.as_object_mut() {
                o.remove("tests");
            }
            refuse_nulls(&rest)?;
        }
        _ => refuse_nulls(&body)?,
    }
    check_policy_keys(body.get("policy"), "policy")?;
    integral_numbers(&mut body);
    let update: ThresholdUpdate = from_value(body)?;
    let handle = state
        .registry
        .get(&id)
        .ok_or_else(|| ApiError::NotFound(format!("no session '{id}'")))?;
    // The actor stores the change before it answers, in the order changes are applied.
    let (previous, now) = handle.set_threshold(&name, update).await?;
    let change = Change {
        session: Some(id),
        previous: json!(previous),
        new: json!(now),
    };
    Ok((Extension(change), Json(now)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_policy_kind_refuses_keys_it_does_not_have() {
        for (policy, bad) in [
            (json!({"kind": "classic", "n1": 4}), Some("n1")),
            (json!({"kind": "traditional", "n1": 4}), Some("n1")),
            (json!({"kind": "counters", "n1": 4, "n3": 1}), Some("n3")),
            (json!({"kind": "classic"}), None),
            (json!({"kind": "traditional"}), None),
            (json!({"kind": "counters", "n1": 4, "n2": 2}), None),
        ] {
            let got = check_policy_keys(Some(&policy), "policy");
            match bad {
                Some(key) => {
                    let e = got.expect_err(&policy.to_string());
                    assert!(e.to_string().contains(key), "{policy}: {e}");
                }
                None => assert!(got.is_ok(), "{policy}"),
            }
        }
    }
}
