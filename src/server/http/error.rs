//! One error type for the API: each variant has its status, the client gets a short JSON body
//! `{"error": …, "field": …}`, internal detail goes to the log.

use axum::Json;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde_json::json;

/// Why a request failed, with the status it answers.
#[derive(Debug)]
pub enum ApiError {
    /// 400: a query or body that cannot be used; `field` names it (JSON pointer for bodies).
    Invalid {
        /// The query parameter, or the JSON pointer into the body.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// 401: a token is required.
    Unauthorized,
    /// 404, saying what was not found.
    NotFound(String),
    /// 412: the If-Match revision is stale; carries the current one.
    Stale {
        /// The resource's current revision.
        current: u64,
    },
    /// 428: writes must say which revision they change.
    PreconditionRequired,
    /// 503: too many renders at once.
    Busy,
    /// Any other refusal with its status (403, 405, 408, 409, 413, 414, 415, 422, 431, 503):
    /// `field` names the header, parameter or body pointer at fault where there is one.
    Refused {
        /// The status answered.
        status: StatusCode,
        /// The header, parameter or body pointer at fault, where there is one.
        field: Option<String>,
        /// Why, for the client.
        reason: String,
    },
    /// 500: logged, not detailed to the client.
    Internal(String),
}

impl ApiError {
    /// A [`ApiError::Refused`] with `status`, naming `field` where there is one.
    pub fn refused(status: StatusCode, field: Option<&str>, reason: impl Into<String>) -> Self {
        ApiError::Refused {
            status,
            field: field.map(String::from),
            reason: reason.into(),
        }
    }
}

impl From<crate::Error> for ApiError {
    fn from(e: crate::Error) -> Self {
        match e {
            crate::Error::Invalid { name, reason } => ApiError::Invalid {
                field: name,
                reason,
            },
            // Only a client that went away cancels, so nobody reads this answer.
            crate::Error::Cancelled => ApiError::refused(
                StatusCode::SERVICE_UNAVAILABLE,
                None,
                "the work was cancelled",
            ),
            // Nothing was written (the transaction rolled back, or the temporary file was
            // removed): the client can retry once the operator has made room.
            other
                if matches!(
                    other.io_kind(),
                    Some(std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded)
                ) =>
            {
                tracing::error!(error = %other, "a write found the disk full");
                ApiError::refused(
                    StatusCode::INSUFFICIENT_STORAGE,
                    None,
                    "the disk holding the daemon's data is full; nothing was written",
                )
            }
            other => ApiError::Internal(other.to_string()),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let (status, body) = match &self {
            ApiError::Invalid { field, reason } => (
                StatusCode::BAD_REQUEST,
                json!({"error": reason, "field": field}),
            ),
            ApiError::Unauthorized => (
                StatusCode::UNAUTHORIZED,
                json!({"error": "a bearer token is required"}),
            ),
            ApiError::NotFound(what) => (StatusCode::NOT_FOUND, json!({"error": what})),
            ApiError::Stale { current } => (
                StatusCode::PRECONDITION_FAILED,
                json!({"error": "the resource changed since that revision", "current_revision": current}),
            ),
            ApiError::PreconditionRequired => (
                StatusCode::PRECONDITION_REQUIRED,
                json!({"error": "send If-Match with the revision you edit"}),
            ),
            ApiError::Busy => (
                StatusCode::SERVICE_UNAVAILABLE,
                json!({"error": "too many renders at once; retry shortly"}),
            ),
            ApiError::Refused {
                status,
                field,
                reason,
            } => (
                *status,
                match field {
                    Some(f) => json!({"error": reason, "field": f}),
                    None => json!({"error": reason}),
                },
            ),
            ApiError::Internal(detail) => {
                tracing::error!(%detail, "internal error");
                (
                    StatusCode::INTERNAL_SERVER_ERROR,
                    json!({"error": "internal error"}),
                )
            }
        };
        let mut resp = (status, Json(body)).into_response();
        if let ApiError::Stale { current } = self
            && let Ok(v) = HeaderValue::from_str(&format!("\"{current}\""))
        {
            resp.headers_mut().insert(header::ETAG, v);
        }
        if status == StatusCode::SERVICE_UNAVAILABLE {
            resp.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
        }
        if matches!(self, ApiError::Unauthorized) {
            resp.headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        resp
    }
}
