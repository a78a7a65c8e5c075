//! `/api/v1/models`: start a training job, list, get, delete (cancelling a
//! running job) and predict (docs/architecture.md §A5). Everything checkable is checked here,
//! before the 202, so a bad training set or parameter is a 422 naming its field
//! (`kind`, `params.<f>`, `cv.<f>`, `data.x[3]`, `data.y`) and never a failed job.

use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::IntoResponse;
use axum::{Extension, Json};
use serde::Serialize;
use serde_json::{Map, Value};

use crate::service::app::AppState;
use crate::service::audit::Change;
use crate::service::config::Limits;
use crate::service::error::ApiError;
use crate::service::extract::{integral_numbers, refuse_nulls_at};
use crate::service::train::{ModelRecord, TrainJob, error_field};
use navguard_core::learn::cv::CvParams;
use navguard_core::learn::{self, Dataset, LearnError, ModelKind, ModelParams, Prediction};

/// Longest model `name`, characters.
const MAX_NAME_CHARS: usize = 200;

/// `POST /api/v1/models` → 202 with the record (status `training`) and `Location`.
pub async fn create(
    State(state): State<AppState>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<impl IntoResponse, ApiError> {
    let body = json_body(&headers, body)?;
    let job = parse_train(body, &state.config.limits)?;
    let record = state.models.start(job).await?;
    let location = format!("/api/v1/models/{}", record.id);
    let change = Change {
        session: None,
        previous: Value::Null,
        new: serde_json::json!(record),
    };
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, location)],
        Extension(change),
        Json(record),
    ))
}

/// The list answer.
#[derive(Debug, Serialize)]
pub struct ModelList {
    models: Vec<ModelRecord>,
}

/// `GET /api/v1/models`: every model, newest first.
pub async fn list(State(state): State<AppState>) -> Json<ModelList> {
    Json(ModelList {
        models: state.models.list(),
    })
}

/// `GET /api/v1/models/{id}`
pub async fn get(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<ModelRecord>, ApiError> {
    Ok(Json(state.models.record(&id)?))
}

/// `DELETE /api/v1/models/{id}` → 204, cancelling a running job. Sessions whose
/// monitors were built from the model keep their own copy.
pub async fn delete(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<(StatusCode, Extension<Change>), ApiError> {
    let previous = serde_json::json!(state.models.record(&id)?);
    state.models.delete(&id).await?;
    let change = Change {
        session: None,
        previous,
        new: Value::Null,
    };
    Ok((StatusCode::NO_CONTENT, Extension(change)))
}

/// `POST /api/v1/models/{id}/predict {"x": [[...]]}` → `{"y"}` or `{"decision", "label"}`;
/// 409 unless the model is ready.
pub async fn predict(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Json<Prediction>, ApiError> {
    let model = state.models.ready(&id)?;
    let body = json_body(&headers, body)?;
    let mut object = object(body, "", &["x"])?;
    let x = object
        .remove("x")
        .ok_or_else(|| ApiError::invalid("x", "required: the inputs, one array per sample"))?;
    let x = matrix(&x, "x", &state.config.limits)?;
    let x = Dataset::new(&x, None).map_err(|e| learn_error(e, false))?;
    // Prediction is O(rows × support vectors): off the async executor.
    let prediction = tokio::task::spawn_blocking(move || model.predict(&x))
        .await
        .map_err(|e| ApiError::Internal(format!("predict task: {e}")))?;
    Ok(Json(prediction.map_err(|e| learn_error(e, false))?))
}

/// Reads a JSON body: 415 without a JSON content type, 413 over the body limit,
/// 400 on bad syntax, 422 on `NaN`/`Infinity` (which JSON cannot carry).
pub(crate) fn json_body(
    headers: &HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Value, ApiError> {
    let content_type = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default();
    let media = content_type.split(';').next().unwrap_or_default().trim();
    let media = media.to_ascii_lowercase();
    if !(media == "application/json"
        || (media.starts_with("application/") && media.ends_with("+json")))
    {
        return Err(ApiError::UnsupportedMediaType(
            "Expected request with `Content-Type: application/json`".into(),
        ));
    }
    let bytes = body.map_err(|rejection| match rejection.status() {
        StatusCode::PAYLOAD_TOO_LARGE => {
            ApiError::TooLarge("request body is over the size limit".into())
        }
        _ => ApiError::BadRequest(rejection.body_text()),
    })?;
    let mut value: Value = serde_json::from_slice(&bytes).map_err(|e| {
        let message = e.to_string();
        if message.contains("number out of range") || (e.is_syntax() && has_non_finite(&bytes)) {
            ApiError::Invalid {
                field: None,
                message: format!(
                    "non-finite number: JSON cannot carry NaN or Infinity, send finite numbers ({message})"
                ),
            }
        } else {
            ApiError::BadRequest(format!("invalid JSON: {message}"))
        }
    })?;
    // `folds: 5.0` and `level: 2.0` are integers as the contract counts them.
    integral_numbers(&mut value);
    Ok(value)
}

/// True if `text` holds a `NaN` or `Infinity` token outside strings (what
/// Python's `json.dumps` writes for non-finite floats).
fn has_non_finite(text: &[u8]) -> bool {
    let (mut in_string, mut escaped) = (false, false);
    for (i, &c) in text.iter().enumerate() {
        if in_string {
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, b'\\') => escaped = true,
                (false, b'"') => in_string = false,
                _ => {}
            }
        } else if c == b'"' {
            in_string = true;
        } else if text[i..].starts_with(b"NaN") || text[i..].starts_with(b"Infinity") {
            return true;
        }
    }
    false
}

/// The body as an object whose keys are all in `allowed`; `at` prefixes field names.
pub(crate) fn object(
    value: Value,
    at: &str,
    allowed: &[&str],
) -> Result<Map<String, Value>, ApiError> {
    let here = |k: &str| {
        if at.is_empty() {
            k.to_owned()
        } else {
            format!("{at}.{k}")
        }
    };
    let Value::Object(map) = value else {
        let what = if at.is_empty() { "the body" } else { at };
        return Err(ApiError::Invalid {
            field: (!at.is_empty()).then(|| at.to_owned()),
            message: format!("{what} must be a JSON object"),
        });
    };
    if let Some(key) = map.keys().find(|k| !allowed.contains(&k.as_str())) {
        return Err(ApiError::invalid(
            here(key),
            format!("unknown field; expected one of {}", allowed.join(", ")),
        ));
    }
    Ok(map)
}

/// Numbers of a JSON array, naming the first bad element `field[i]`.
pub(crate) fn numbers(value: &Value, field: &str, max: usize) -> Result<Vec<f64>, ApiError> {
    let items = value
        .as_array()
        .ok_or_else(|| ApiError::invalid(field, "must be an array of numbers"))?;
    if items.len() > max {
        return Err(ApiError::TooLarge(format!(
            "{field} has {} values, the limit is {max}",
            items.len()
        )));
    }
    items
        .iter()
        .enumerate()
        .map(|(i, v)| {
            v.as_f64().filter(|v| v.is_finite()).ok_or_else(|| {
                ApiError::invalid(format!("{field}[{i}]"), "must be a finite number")
            })
        })
        .collect()
}

/// Samples of a JSON array of arrays, within the sample and value limits.
fn matrix(value: &Value, field: &str, limits: &Limits) -> Result<Vec<Vec<f64>>, ApiError> {
    let rows = value.as_array().ok_or_else(|| {
        ApiError::invalid(
            field,
            "must be an array of samples, each an array of numbers",
        )
    })?;
    if rows.len() > limits.max_training_samples {
        return Err(ApiError::TooLarge(format!(
            "{field} has {} samples, the limit is {}",
            rows.len(),
            limits.max_training_samples
        )));
    }
    let mut total = 0usize;
    rows.iter()
        .enumerate()
        .map(|(i, row)| {
            total = total.saturating_add(row.as_array().map_or(0, Vec::len));
            if total > limits.max_training_values {
                return Err(ApiError::TooLarge(format!(
                    "{field} holds more than {} numbers",
                    limits.max_training_values
                )));
            }
            numbers(row, &format!("{field}[{i}]"), usize::MAX)
        })
        .collect()
}

/// A learning error as a 422 naming the request field (`data.`-prefixed for a
/// training set, as is for a predict body).
fn learn_error(e: LearnError, training: bool) -> ApiError {
    let field = match (&e, training) {
        (LearnError::InvalidData { field, .. }, false) => Some(field.clone()),
        _ => error_field(&e),
    };
    let message = match &e {
        LearnError::InvalidParams { reason, .. } | LearnError::InvalidData { reason, .. } => {
            reason.clone()
        }
        other => other.to_string(),
    };
    ApiError::Invalid { field, message }
}

/// Parses and checks a training request up to the point where only training can fail.
fn parse_train(body: Value, limits: &Limits) -> Result<TrainJob, ApiError> {
    let mut body = object(body, "", &["kind", "params", "data", "cv", "name"])?;
    let kind = parse_kind(body.remove("kind"))?;
    let name = parse_name(body.remove("name"))?;
    // `params` and `cv` may be null (the contract says so), their fields not.
    for key in ["params", "cv"] {
        if let Some(part) = body.get(key).filter(|v| v.is_object()) {
            refuse_nulls_at(part, key)?;
        }
    }
    let params = ModelParams::from_json(kind, &body.remove("params").unwrap_or(Value::Null))
        .map_err(|e| learn_error(e, true))?;
    let cv = parse_cv(kind, body.remove("cv"))?;
    let data = parse_data(kind, body.remove("data"), limits)?;
    if kind.is_regression() && data.n() > limits.max_lssvm_samples {
        return Err(ApiError::TooLarge(format!(
            "{} samples; kind '{}' solves a dense n × n system and is limited to {}",
            data.n(),
            kind.as_str(),
            limits.max_lssvm_samples
        )));
    }
    check_folds(&params, cv.as_ref(), data.n())?;
    Ok(TrainJob {
        name,
        params,
        cv,
        data,
    })
}

/// `kind`: required, one of the four model kinds.
fn parse_kind(kind: Option<Value>) -> Result<ModelKind, ApiError> {
    let Some(Value::String(k)) = kind else {
        return Err(ApiError::invalid(
            "kind",
            "required: one of lssvm, lw-lssvm, svm, ocsvm",
        ));
    };
    serde_json::from_value::<ModelKind>(Value::String(k.clone())).map_err(|_| {
        ApiError::invalid(
            "kind",
            format!("unknown model kind '{k}'; one of lssvm, lw-lssvm, svm, ocsvm"),
        )
    })
}

/// `name`: optional, a string of at most [`MAX_NAME_CHARS`] characters and no control
/// characters U+0000–U+001F (a Postgres TEXT cannot hold U+0000, and a label for people
/// has no use for the others).
fn parse_name(name: Option<Value>) -> Result<Option<String>, ApiError> {
    match name {
        None | Some(Value::Null) => Ok(None),
        Some(Value::String(s)) if s.chars().any(|c| c < ' ') => Err(ApiError::invalid(
            "name",
            "must not contain control characters (U+0000 to U+001F)",
        )),
        Some(Value::String(s)) if s.chars().count() <= MAX_NAME_CHARS => Ok(Some(s)),
        Some(_) => Err(ApiError::invalid(
            "name",
            format!("must be a string of at most {MAX_NAME_CHARS} characters"),
        )),
    }
}

/// `cv`: optional, and only for the regression kinds.
fn parse_cv(kind: ModelKind, cv: Option<Value>) -> Result<Option<CvParams>, ApiError> {
    match cv {
        None | Some(Value::Null) => Ok(None),
        // learn::svm refuses a cv block (no hyper-parameter search for SMO yet):
        // say so now rather than fail the job.
        Some(_) if !kind.is_regression() => Err(ApiError::invalid(
            "cv",
            format!(
                "kind '{}' has no cross-validation; give its parameters",
                kind.as_str()
            ),
        )),
        Some(v) => {
            let cv: CvParams = learn::model::parse_at(&v).map_err(|(path, message)| {
                let field = if path.is_empty() {
                    "cv".to_owned()
                } else {
                    format!("cv.{path}")
                };
                ApiError::invalid(field, message)
            })?;
            cv.check().map_err(|e| learn_error(e, true))?;
            Ok(Some(cv))
        }
    }
}

/// `data`: `x` (one array per sample, within the limits) and `y` exactly when
/// the kind trains on targets or labels (labels −1/+1 for `svm`).
fn parse_data(kind: ModelKind, data: Option<Value>, limits: &Limits) -> Result<Dataset, ApiError> {
    let data =
        data.ok_or_else(|| ApiError::invalid("data", "required: {\"x\": [[...]], \"y\": [...]}"))?;
    let mut data = object(data, "data", &["x", "y"])?;
    let x = data
        .remove("x")
        .ok_or_else(|| ApiError::invalid("data.x", "required: one array per sample"))?;
    let x = matrix(&x, "data.x", limits)?;
    let y = match data.remove("y") {
        None | Some(Value::Null) => None,
        Some(y) => Some(numbers(&y, "data.y", limits.max_training_samples)?),
    };
    match (&y, kind.needs_y()) {
        (None, true) => {
            return Err(ApiError::invalid(
                "data.y",
                format!(
                    "required: kind '{}' trains on targets or labels",
                    kind.as_str()
                ),
            ));
        }
        (Some(_), false) => {
            return Err(ApiError::invalid(
                "data.y",
                format!("kind '{}' trains on x alone; leave y out", kind.as_str()),
            ));
        }
        _ => {}
    }
    let dataset = Dataset::new(&x, y.as_deref()).map_err(|e| learn_error(e, true))?;
    if kind == ModelKind::Svm {
        check_labels(y.as_deref().unwrap_or_default())?;
    }
    Ok(dataset)
}

/// Cross-validation (a `cv` block, or a hyper-parameter `"auto"`) needs at least
/// one sample per fold.
fn check_folds(params: &ModelParams, cv: Option<&CvParams>, n: usize) -> Result<(), ApiError> {
    let folds = match (cv, params.tunes(false)) {
        (Some(cv), _) => cv.folds,
        (None, true) => CvParams::default().folds,
        (None, false) => return Ok(()),
    };
    if folds <= n {
        return Ok(());
    }
    let message = format!("{folds}-fold cross-validation needs at least {folds} samples, got {n}");
    Err(match cv {
        Some(_) => ApiError::invalid("cv.folds", message),
        None => ApiError::invalid("data.x", message),
    })
}

/// `svm` labels are −1 and +1 (the positive class is "fault" in seed 002), both present.
fn check_labels(y: &[f64]) -> Result<(), ApiError> {
    if let Some(i) = y.iter().position(|&v| v != 1.0 && v != -1.0) {
        return Err(ApiError::invalid(
            format!("data.y[{i}]"),
            "svm labels must be -1 or +1",
        ));
    }
    if !(y.contains(&1.0) && y.contains(&-1.0)) {
        return Err(ApiError::invalid(
            "data.y",
            "svm needs samples of both classes (-1 and +1)",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn limits() -> Limits {
        Limits {
            max_training_samples: 4,
            max_training_values: 6,
            ..Limits::default()
        }
    }

    fn field(body: Value) -> (u16, Option<String>) {
        match parse_train(body, &limits()) {
            Ok(_) => (202, None),
            Err(ApiError::Invalid { field, .. }) => (422, field),
            Err(ApiError::TooLarge(_)) => (413, None),
            Err(other) => panic!("{other:?}"),
        }
    }

    #[test]
    fn bad_training_requests_name_their_field() {
        let ok = json!({"kind": "lssvm", "params": {"gamma": 10, "sigma2": 1},
                        "data": {"x": [[0.0], [1.0]], "y": [0.0, 1.0]}});
        assert_eq!(field(ok.clone()).0, 202);
        let with = |path: &str, v: Value| {
            let mut b = ok.clone();
            *b.pointer_mut(path).unwrap() = v;
            b
        };
        let cases = [
            (with("/kind", json!("svr")), "kind"),
            (with("/data/x", json!([])), "data.x"),
            (with("/data/x", json!([[0.0], [1.0, 2.0]])), "data.x[1]"),
            (with("/data/x", json!([[0.0], [null]])), "data.x[1][0]"),
            (with("/data/y", json!([0.0])), "data.y"),
            (with("/data/y", json!([0.0, "a"])), "data.y[1]"),
            (
                with("/params", json!({"gamma": 1, "sigma2": 1, "gama": 1})),
                "params.gama",
            ),
            (with("/params/sigma2", json!("wide")), "params.sigma2"),
            (with("/params/sigma2", json!(-1.0)), "params.sigma2"),
            (with("/params/gamma", json!(0)), "params.gamma"),
            (
                with("/params", json!({"reg": 0, "sigma2": 1})),
                "params.reg",
            ),
            (
                with("/params", json!({"reg": 1, "gamma": 1})),
                "params.gamma",
            ),
        ];
        for (body, want) in cases {
            assert_eq!(field(body.clone()), (422, Some(want.to_owned())), "{body}");
        }
        let mut cv = ok.clone();
        cv["cv"] = json!({"folds": 1});
        assert_eq!(field(cv), (422, Some("cv.folds".into())));
        cv = ok.clone();
        cv["cv"] = json!({"fold": 3});
        assert_eq!(field(cv), (422, Some("cv.fold".into())));
        cv = ok.clone();
        cv["cv"] = json!({"folds": "five"});
        assert_eq!(field(cv), (422, Some("cv.folds".into())));
        cv = ok.clone();
        cv["cv"] = json!({"gamma_range": [1.0, "x"]});
        assert_eq!(field(cv), (422, Some("cv.gamma_range[1]".into())));
        cv = ok.clone();
        cv["cv"] = json!(5);
        assert_eq!(field(cv), (422, Some("cv".into())));
        // Too few samples for the default 5 folds only when something is "auto".
        let auto = with("/params", json!({"reg": "auto", "sigma2": 1}));
        assert_eq!(field(auto), (422, Some("data.x".into())));
        let linear = with("/params", json!({"reg": 1, "kernel": "linear"}));
        assert_eq!(field(linear).0, 202);
        let mut named = ok.clone();
        named["name"] = json!(3);
        assert_eq!(field(named.clone()), (422, Some("name".into())));
        for bad in ["nul\u{0}", "tab\tname", "line\n"] {
            named["name"] = json!(bad);
            assert_eq!(field(named.clone()), (422, Some("name".into())), "{bad:?}");
        }
        let mut extra = ok.clone();
        extra["colour"] = json!(1);
        assert_eq!(field(extra), (422, Some("colour".into())));
        let big = with("/data/x", json!([[0.0], [1.0], [2.0], [3.0], [4.0]]));
        assert_eq!(field(big).0, 413);
        let wide = with(
            "/data/x",
            json!([[0.0, 1.0, 2.0], [1.0, 2.0, 3.0], [1.0, 1.0, 1.0]]),
        );
        assert_eq!(field(wide).0, 413);
        let oc_cv = json!({"kind": "ocsvm", "cv": {"folds": 2}, "data": {"x": [[0.0]]}});
        assert_eq!(field(oc_cv), (422, Some("cv".into())));
        let oc = json!({"kind": "ocsvm", "data": {"x": [[0.0]], "y": [1.0]}});
        assert_eq!(field(oc), (422, Some("data.y".into())));
        let svm = json!({"kind": "svm", "data": {"x": [[0.0], [1.0]], "y": [1.0, 0.0]}});
        assert_eq!(field(svm), (422, Some("data.y[1]".into())));
    }

    #[test]
    fn nan_tokens_outside_strings_are_found() {
        assert!(has_non_finite(br#"{"x": [[NaN]]}"#));
        assert!(has_non_finite(br#"{"x": [[-Infinity]]}"#));
        assert!(!has_non_finite(br#"{"name": "NaN \" Infinity"}"#));
    }
}
