//! One error type for every handler, mapped to an HTTP status and the JSON body
//! `{"error": {"code", "message", "field"?}}` (docs/architecture.md §A5). 5xx bodies carry no
//! internal detail; the detail goes to the log.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde_json::json;

use crate::service::session::SessionError;
use crate::service::store::StoreError;
use navguard_core::monitor::BuildError;

/// An error a handler returns.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    /// 400: the request cannot be parsed (bad JSON, bad query string).
    #[error("{0}")]
    BadRequest(String),
    /// 401: the bearer token is missing or wrong.
    #[error("missing or invalid bearer token")]
    Unauthorized,
    /// 403 `forbidden`: a valid token without the scope the route needs, or limited to
    /// other sessions; `scope` names the scope the route needs.
    #[error("{message}")]
    Forbidden {
        /// The scope the route needs.
        scope: crate::service::tokens::Scope,
        /// Why (the token's name and what it lacks; never the secret).
        message: String,
    },
    /// 404: no such session, monitor, model or route.
    #[error("{0}")]
    NotFound(String),
    /// 405: the route exists but not with this method; carries the allowed ones.
    #[error("method not allowed; this route allows {}", .0.join(", "))]
    MethodNotAllowed(&'static [&'static str]),
    /// 409: the request conflicts with the current state (duplicate id, stream already attached).
    #[error("{0}")]
    Conflict(String),
    /// 413: the request is over a configured limit.
    #[error("{0}")]
    TooLarge(String),
    /// 426: a socket route was requested without a WebSocket upgrade.
    #[error("{0}")]
    UpgradeRequired(String),
    /// 415: the body is not `application/json`.
    #[error("{0}")]
    UnsupportedMediaType(String),
    /// 422: well-formed but invalid; `field` names the offending field.
    #[error("{message}")]
    Invalid {
        /// Path of the offending field, e.g. `monitors[0].config.q`.
        field: Option<String>,
        /// Why.
        message: String,
    },
    /// 409 `not_owner`: another node owns the session and keeps it (its ingest stream is
    /// attached there); `location` is that node's address for the same path.
    #[error("{message}")]
    NotOwner {
        /// Why.
        message: String,
        /// The owning node's id.
        owner: String,
        /// The same request's URL on the owner.
        location: String,
    },
    /// 503: the session did not answer in time or the server is shutting down.
    #[error("{0}")]
    Unavailable(String),
    /// 500: a server fault (store failure); logged, never detailed to the client.
    #[error("internal error")]
    Internal(String),
}

impl ApiError {
    /// A 422 naming a field.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        ApiError::Invalid {
            field: Some(field.into()),
            message: message.into(),
        }
    }

    fn status_and_code(&self) -> (StatusCode, &'static str) {
        match self {
            ApiError::BadRequest(_) => (StatusCode::BAD_REQUEST, "bad_request"),
            ApiError::Unauthorized => (StatusCode::UNAUTHORIZED, "unauthorized"),
            ApiError::Forbidden { .. } => (StatusCode::FORBIDDEN, "forbidden"),
            ApiError::NotFound(_) => (StatusCode::NOT_FOUND, "not_found"),
            ApiError::MethodNotAllowed(_) => (StatusCode::METHOD_NOT_ALLOWED, "method_not_allowed"),
            ApiError::UpgradeRequired(_) => (StatusCode::UPGRADE_REQUIRED, "upgrade_required"),
            ApiError::Conflict(_) => (StatusCode::CONFLICT, "conflict"),
            ApiError::NotOwner { .. } => (StatusCode::CONFLICT, "not_owner"),
            ApiError::TooLarge(_) => (StatusCode::PAYLOAD_TOO_LARGE, "too_large"),
            ApiError::UnsupportedMediaType(_) => {
                (StatusCode::UNSUPPORTED_MEDIA_TYPE, "unsupported_media_type")
            }
            ApiError::Invalid { .. } => (StatusCode::UNPROCESSABLE_ENTITY, "invalid"),
            ApiError::Unavailable(_) => (StatusCode::SERVICE_UNAVAILABLE, "unavailable"),
            ApiError::Internal(_) => (StatusCode::INTERNAL_SERVER_ERROR, "internal"),
        }
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        match e {
            // Another node took the session while this one served the request: retry.
            e @ StoreError::Fenced(_) => ApiError::Unavailable(e.to_string()),
            e => ApiError::Internal(e.to_string()),
        }
    }
}

impl From<SessionError> for ApiError {
    fn from(e: SessionError) -> Self {
        match e {
            SessionError::Build { index, source } => build_error(index, source),
            SessionError::Invalid { field, reason } => ApiError::Invalid {
                field,
                message: reason,
            },
            SessionError::TooLarge(m) => ApiError::TooLarge(m),
            e @ (SessionError::AlreadyAttached(_) | SessionError::Exists(_)) => {
                ApiError::Conflict(e.to_string())
            }
            SessionError::Unavailable(m) => ApiError::Unavailable(m),
            e @ (SessionError::NoMonitor { .. } | SessionError::Stopped(_)) => {
                ApiError::NotFound(e.to_string())
            }
            e @ (SessionError::Busy(_) | SessionError::Moved(_)) => {
                ApiError::Unavailable(e.to_string())
            }
            SessionError::Store(e) => ApiError::Internal(e),
        }
    }
}

/// The 422 of monitor `index`'s build error, naming the field from the request body's root.
fn build_error(index: usize, e: BuildError) -> ApiError {
    let prefix = format!("monitors[{index}]");
    match e {
        BuildError::Config(c) if c.field.is_empty() => {
            ApiError::invalid(format!("{prefix}.config"), c.reason)
        }
        BuildError::Config(c) => {
            ApiError::invalid(format!("{prefix}.config.{}", c.field), c.reason)
        }
        BuildError::ModelNotFound { field, id } => ApiError::invalid(
            format!("{prefix}.config.{field}"),
            format!("no stored model '{id}'"),
        ),
        BuildError::Policy(p) => ApiError::invalid(format!("{prefix}.policy"), p.to_string()),
        BuildError::Threshold(t) => ApiError::invalid(prefix, t.to_string()),
        BuildError::Unsupported(kind) => ApiError::invalid(
            format!("{prefix}.type"),
            format!("monitor type '{kind}' is not implemented yet"),
        ),
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let (status, code) = self.status_and_code();
        if let ApiError::Internal(detail) = &self {
            tracing::error!(%detail, "internal error");
        }
        let mut error = json!({ "code": code, "message": self.to_string() });
        if let ApiError::Invalid {
            field: Some(field), ..
        } = &self
        {
            error["field"] = json!(field);
        }
        if let ApiError::Forbidden { scope, .. } = &self {
            error["scope"] = json!(scope.as_str());
        }
        if let ApiError::NotOwner {
            owner, location, ..
        } = &self
        {
            error["owner"] = json!(owner);
            error["location"] = json!(location);
        }
        let mut response = (status, Json(json!({ "error": error }))).into_response();
        let headers = response.headers_mut();
        match &self {
            ApiError::Unauthorized => {
                headers.insert(
                    axum::http::header::WWW_AUTHENTICATE,
                    axum::http::HeaderValue::from_static("Bearer"),
                );
            }
            ApiError::MethodNotAllowed(methods) => {
                if let Ok(allow) = axum::http::HeaderValue::from_str(&methods.join(", ")) {
                    headers.insert(axum::http::header::ALLOW, allow);
                }
            }
            ApiError::UpgradeRequired(_) => {
                headers.insert(
                    axum::http::header::UPGRADE,
                    axum::http::HeaderValue::from_static("websocket"),
                );
            }
            _ => {}
        }
        response
    }
}
