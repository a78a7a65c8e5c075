//! Extractors whose rejections are `ApiError`s, so a bad body or query string
//! gets the same JSON error shape as everything else (never axum's plain text),
//! and the edge's reading of JSON numbers and `null` (docs/architecture.md §A5).

use axum::extract::rejection::{JsonRejection, QueryRejection};
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::StatusCode;
use axum::http::request::Parts;
use serde::Deserialize;
use serde::de::{self, DeserializeOwned, Deserializer};
use serde_json::Value;

use super::error::ApiError;

/// A JSON body as a `Value`, with JSON errors: 400 syntax, 413 over the body
/// limit, 415 content type.
#[derive(Debug, Clone, Default)]
pub struct JsonBody(pub Value);

impl<S> FromRequest<S> for JsonBody
where
    S: Send + Sync,
{
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        match axum::Json::<Value>::from_request(req, state).await {
            Ok(axum::Json(value)) => Ok(JsonBody(value)),
            Err(rejection) => Err(json_rejection(rejection)),
        }
    }
}

/// Deserialises a body, a 422 whose message names the path of the bad field.
pub fn from_value<T: DeserializeOwned>(value: Value) -> Result<T, ApiError> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        ApiError::Invalid {
            field: None,
            message: if path == "." {
                format!("Failed to deserialize the JSON body into the target type: {inner}")
            } else {
                format!("Failed to deserialize the JSON body into the target type: {path}: {inner}")
            },
        }
    })
}

/// Refuses `null` anywhere in a session or threshold body (422 naming its
/// path): every optional field there is left out for its default, and the
/// contract declares none nullable, so `null` is refused rather than read as
/// "absent" by some fields and as an error by others.
pub fn refuse_nulls(value: &Value) -> Result<(), ApiError> {
    refuse_nulls_at(value, "")
}

/// [`refuse_nulls`] for a part of a body found at `prefix` (e.g. `params`).
pub fn refuse_nulls_at(value: &Value, prefix: &str) -> Result<(), ApiError> {
    fn walk(value: &Value, path: &mut String) -> Result<(), ApiError> {
        match value {
            Value::Null => Err(ApiError::invalid(
                if path.is_empty() {
                    "body"
                } else {
                    path.as_str()
                },
                "null is not accepted: leave the field out for its default",
            )),
            Value::Array(items) => items.iter().enumerate().try_for_each(|(i, v)| {
                let len = path.len();
                path.push_str(&format!("[{i}]"));
                let r = walk(v, path);
                path.truncate(len);
                r
            }),
            Value::Object(map) => map.iter().try_for_each(|(k, v)| {
                let len = path.len();
                if !path.is_empty() {
                    path.push('.');
                }
                path.push_str(k);
                let r = walk(v, path);
                path.truncate(len);
                r
            }),
            _ => Ok(()),
        }
    }
    walk(value, &mut prefix.to_owned())
}

/// Rewrites every integral float (`117932.0`, `1.5e3`) as the integer it is:
/// JSON Schema counts such numbers as integers, so integer fields (`dof`,
/// `n1`, `window`, `folds`, …) accept them as the contract says. A float field
/// reads the integer back as the same float, so nothing else changes.
pub fn integral_numbers(value: &mut Value) {
    match value {
        Value::Number(n) => {
            if let Some(f) = n.as_f64().filter(|_| n.is_f64())
                && f.fract() == 0.0
            {
                // Exact: an integral f64 below 2^64 (or above -2^63) converts without loss.
                if (0.0..18_446_744_073_709_551_616.0).contains(&f) {
                    *n = (f as u64).into();
                } else if (-9_223_372_036_854_775_808.0..0.0).contains(&f) {
                    *n = (f as i64).into();
                }
            }
        }
        Value::Array(items) => items.iter_mut().for_each(integral_numbers),
        Value::Object(map) => map.values_mut().for_each(integral_numbers),
        _ => {}
    }
}

fn json_rejection(rejection: JsonRejection) -> ApiError {
    let text = rejection.body_text();
    match rejection.status() {
        StatusCode::PAYLOAD_TOO_LARGE => {
            ApiError::TooLarge("request body is over the size limit".into())
        }
        StatusCode::UNSUPPORTED_MEDIA_TYPE => ApiError::UnsupportedMediaType(text),
        StatusCode::UNPROCESSABLE_ENTITY => ApiError::Invalid {
            field: None,
            message: text,
        },
        _ => ApiError::BadRequest(text),
    }
}

/// `Query<T>` with a JSON 400 on a bad query string.
#[derive(Debug, Clone, Copy, Default)]
pub struct ApiQuery<T>(pub T);

impl<S, T> FromRequestParts<S> for ApiQuery<T>
where
    T: DeserializeOwned,
    S: Send + Sync,
{
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        match axum::extract::Query::<T>::from_request_parts(parts, state).await {
            Ok(axum::extract::Query(value)) => Ok(ApiQuery(value)),
            Err(rejection) => Err(query_rejection(rejection)),
        }
    }
}

fn query_rejection(rejection: QueryRejection) -> ApiError {
    ApiError::BadRequest(rejection.body_text())
}

/// `deserialize_with` for an integer in a query string, read as JSON Schema
/// reads integers: `117932`, `117932.0` and `1.17932e5` are the same integer;
/// `1.5`, or a value outside `T`, is refused (400).
pub fn query_integer<'de, D, T>(deserializer: D) -> Result<T, D::Error>
where
    D: Deserializer<'de>,
    T: TryFrom<i128>,
{
    let text = String::deserialize(deserializer)?;
    let text = text.trim();
    let n = match text.parse::<i128>() {
        Ok(n) => n,
        Err(_) => match text.parse::<f64>() {
            Ok(f) if f.fract() == 0.0 && f.abs() < 1e38 => f as i128,
            _ => {
                return Err(de::Error::custom(format!("`{text}` is not an integer")));
            }
        },
    };
    T::try_from(n).map_err(|_| {
        de::Error::custom(format!(
            "{n} is out of range for a {}",
            std::any::type_name::<T>()
        ))
    })
}

/// [`query_integer`] for an optional parameter (with `#[serde(default)]`).
pub fn query_integer_opt<'de, D, T>(deserializer: D) -> Result<Option<T>, D::Error>
where
    D: Deserializer<'de>,
    T: TryFrom<i128>,
{
    query_integer(deserializer).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[derive(Debug, Deserialize)]
    struct Q {
        #[serde(deserialize_with = "query_integer")]
        dof: u32,
        #[serde(default, deserialize_with = "query_integer_opt")]
        limit: Option<i64>,
    }

    fn query(s: &str) -> Result<Q, String> {
        let uri: axum::http::Uri = format!("/q?{s}").parse().unwrap();
        axum::extract::Query::<Q>::try_from_uri(&uri)
            .map(|q| q.0)
            .map_err(|e| e.body_text())
    }

    #[test]
    fn query_integers_may_be_written_as_integral_floats() {
        assert_eq!(query("dof=117932.0").unwrap().dof, 117_932);
        assert_eq!(query("dof=1.5e1&limit=-2.0").unwrap().limit, Some(-2));
        assert_eq!(query("dof=3").unwrap().limit, None);
        assert!(query("dof=1.5").unwrap_err().contains("not an integer"));
        assert!(query("dof=-1").unwrap_err().contains("out of range"));
        assert!(
            query("dof=4294967296")
                .unwrap_err()
                .contains("out of range")
        );
        assert!(query("dof=abc").is_err());
    }

    #[test]
    fn integral_floats_in_bodies_become_integers_and_the_rest_stays() {
        let mut v = json!({"n1": 97619.0, "x": [1.5, -3.0, 1e300, 1e19], "s": "1.0", "k": 7});
        integral_numbers(&mut v);
        assert_eq!(v["n1"], json!(97619));
        assert!(v["n1"].is_u64());
        assert_eq!(v["x"][0], json!(1.5));
        assert!(v["x"][1].is_i64());
        assert!(
            v["x"][2].is_f64(),
            "too large for an integer type: left as it is"
        );
        assert!(v["x"][3].is_u64());
        assert_eq!(v["s"], json!("1.0"));
    }

    #[test]
    fn nulls_are_refused_with_their_path() {
        let field = |v: Value| match refuse_nulls(&v) {
            Err(ApiError::Invalid { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            field(json!({"monitors": [{"name": "a"}, {"p_fa": null}]})),
            Some("monitors[1].p_fa".into())
        );
        assert_eq!(field(json!(null)), Some("body".into()));
        assert!(refuse_nulls(&json!({"a": [1, "x", {"b": false}]})).is_ok());
    }
}
