//! The one error-code table: every domain error maps to an [`ErrorCode`], and each code has
//! exactly one HTTP status and one gRPC code. Client-facing messages name the field, file and
//! line at fault; internal failures are logged in full once and reported without details.
//! Over HTTP every error is an RFC 9457 problem document ([`problem`]), the framework's own
//! rejections included ([`problem_json`] rewrites them).

use crate::serve::job::model::TransitionError;
use crate::serve::job::service::ServiceError;

/// API error classes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ErrorCode {
    /// Bad settings, scene, bundle or tile result.
    InvalidArgument,
    /// No such job, worker, blob or route.
    NotFound,
    /// Missing or wrong bearer token.
    Unauthenticated,
    /// A browser page of another origin tried to change state.
    PermissionDenied,
    /// The request does not fit the job's state.
    FailedPrecondition,
    /// The upload is larger than the server accepts.
    PayloadTooLarge,
    /// A bounded resource is in use; the request may succeed later.
    ResourceExhausted,
    /// The server's disk is (nearly) full; the request may succeed once space is freed.
    InsufficientStorage,
    /// Storage or another internal failure.
    Internal,
}

impl ErrorCode {
    /// The HTTP status.
    pub fn http(self) -> http::StatusCode {
        use http::StatusCode as S;
        match self {
            ErrorCode::InvalidArgument => S::BAD_REQUEST,
            ErrorCode::NotFound => S::NOT_FOUND,
            ErrorCode::Unauthenticated => S::UNAUTHORIZED,
            ErrorCode::PermissionDenied => S::FORBIDDEN,
            ErrorCode::FailedPrecondition => S::CONFLICT,
            ErrorCode::PayloadTooLarge => S::PAYLOAD_TOO_LARGE,
            ErrorCode::ResourceExhausted => S::TOO_MANY_REQUESTS,
            ErrorCode::InsufficientStorage => S::INSUFFICIENT_STORAGE,
            ErrorCode::Internal => S::INTERNAL_SERVER_ERROR,
        }
    }

    /// The gRPC code.
    pub fn grpc(self) -> tonic::Code {
        use tonic::Code as C;
        match self {
            ErrorCode::InvalidArgument => C::InvalidArgument,
            ErrorCode::NotFound => C::NotFound,
            ErrorCode::Unauthenticated => C::Unauthenticated,
            ErrorCode::PermissionDenied => C::PermissionDenied,
            ErrorCode::FailedPrecondition => C::FailedPrecondition,
            ErrorCode::PayloadTooLarge | ErrorCode::ResourceExhausted | ErrorCode::InsufficientStorage => {
                C::ResourceExhausted
            }
            ErrorCode::Internal => C::Internal,
        }
    }

    /// A short machine-readable name for JSON bodies.
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorCode::InvalidArgument => "invalid_argument",
            ErrorCode::NotFound => "not_found",
            ErrorCode::Unauthenticated => "unauthenticated",
            ErrorCode::PermissionDenied => "permission_denied",
            ErrorCode::FailedPrecondition => "failed_precondition",
            ErrorCode::PayloadTooLarge => "payload_too_large",
            ErrorCode::ResourceExhausted => "resource_exhausted",
            ErrorCode::InsufficientStorage => "insufficient_storage",
            ErrorCode::Internal => "internal",
        }
    }
}

/// An error on its way to a client.
#[derive(Clone, Debug, PartialEq)]
pub struct ApiError {
    /// Its class.
    pub code: ErrorCode,
    /// What the client is told.
    pub message: String,
}

impl ApiError {
    /// An error of class `code`.
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        ApiError { code, message: message.into() }
    }

    /// As a gRPC status.
    pub fn to_status(&self) -> tonic::Status {
        tonic::Status::new(self.code.grpc(), self.message.clone())
    }
}

impl From<ServiceError> for ApiError {
    fn from(e: ServiceError) -> Self {
        // no wildcard: a new error variant must be given its code here
        let code = match &e {
            ServiceError::InvalidArgument(_)
            | ServiceError::InvalidResult(_)
            | ServiceError::Transition(TransitionError::AmbiguousPrefix { .. }) => ErrorCode::InvalidArgument,
            ServiceError::TooLarge(_) => ErrorCode::PayloadTooLarge,
            ServiceError::ResourceExhausted(_) => ErrorCode::ResourceExhausted,
            ServiceError::InsufficientStorage(_) => ErrorCode::InsufficientStorage,
            ServiceError::Io(io) if io.kind() == std::io::ErrorKind::StorageFull => ErrorCode::InsufficientStorage,
            ServiceError::NotFound(_) | ServiceError::Transition(TransitionError::UnknownJob(_)) => ErrorCode::NotFound,
            ServiceError::FailedPrecondition(_)
            | ServiceError::Transition(
                TransitionError::Unfinished { .. }
                | TransitionError::NotOptimizing(_)
                | TransitionError::NotFinishing(_)
                | TransitionError::NotRequeueable { .. }
                | TransitionError::SceneRefused(_)
                | TransitionError::Ended { .. },
            ) => ErrorCode::FailedPrecondition,
            ServiceError::Transition(TransitionError::DuplicateJob(_) | TransitionError::NotPlanning { .. })
            | ServiceError::Corrupt { .. }
            | ServiceError::Emis { .. }
            | ServiceError::Storage(_)
            | ServiceError::Io(_)
            | ServiceError::Output(_) => ErrorCode::Internal,
        };
        if code == ErrorCode::InsufficientStorage && matches!(e, ServiceError::Io(_)) {
            tracing::error!(error = %e, "the data folder's disk is full");
            return ApiError::new(
                code,
                "the coordinator's disk is full: delete finished jobs or free space, then retry",
            );
        }
        if code == ErrorCode::Internal {
            tracing::error!(error = %e, "internal error");
            return ApiError::new(code, "internal error (see the coordinator's log)");
        }
        ApiError::new(code, e.to_string())
    }
}

/// The media type of error bodies.
pub const PROBLEM_JSON: &str = "application/problem+json";

/// An RFC 9457 problem document. `type` is `about:blank` (the status says what happened), the
/// machine-readable class is the extension member `code`, and `error` repeats `detail` for
/// clients written against the API's earlier `{code, error}` bodies.
pub fn problem(status: http::StatusCode, code: &str, detail: &str) -> serde_json::Value {
    serde_json::json!({
        "type": "about:blank",
        "title": status.canonical_reason().unwrap_or("Error"),
        "status": status.as_u16(),
        "detail": detail,
        "code": code,
        "error": detail,
    })
}

/// A problem document as a response.
pub fn problem_response(status: http::StatusCode, code: &str, detail: &str) -> axum::response::Response {
    use axum::response::IntoResponse;
    let body = problem(status, code, detail).to_string();
    (status, [(http::header::CONTENT_TYPE, PROBLEM_JSON)], body).into_response()
}

impl axum::response::IntoResponse for ApiError {
    fn into_response(self) -> axum::response::Response {
        problem_response(self.code.http(), self.code.as_str(), &self.message)
    }
}

/// The class of an error status the framework answered by itself (a rejected path, query or
/// body, an unknown method).
fn code_of_status(status: http::StatusCode) -> &'static str {
    match status.as_u16() {
        400 | 422 => ErrorCode::InvalidArgument.as_str(),
        401 => ErrorCode::Unauthenticated.as_str(),
        403 => ErrorCode::PermissionDenied.as_str(),
        404 => ErrorCode::NotFound.as_str(),
        405 => "method_not_allowed",
        409 => ErrorCode::FailedPrecondition.as_str(),
        413 => ErrorCode::PayloadTooLarge.as_str(),
        415 => "unsupported_media_type",
        429 => ErrorCode::ResourceExhausted.as_str(),
        507 => ErrorCode::InsufficientStorage.as_str(),
        _ if status.is_client_error() => "invalid_argument",
        _ => ErrorCode::Internal.as_str(),
    }
}

/// Framework rejections are short texts; anything longer is cut (it is only a message).
const MAX_REJECTION_BYTES: usize = 4096;

/// Middleware: an HTTP error response that is not yet a problem document (axum's rejections of
/// a path, query or JSON body, 405 for a wrong method) becomes one, its text the `detail`.
/// gRPC answers are left alone: their errors travel in trailers of HTTP 200 responses.
pub async fn problem_json(req: axum::extract::Request, next: axum::middleware::Next) -> axum::response::Response {
    let response = next.run(req).await;
    let status = response.status();
    let content_type = response.headers().get(http::header::CONTENT_TYPE).and_then(|v| v.to_str().ok());
    let is_problem = content_type.is_some_and(|t| t.starts_with(PROBLEM_JSON) || t.starts_with("application/grpc"));
    if !(status.is_client_error() || status.is_server_error()) || is_problem {
        return response;
    }
    let (parts, body) = response.into_parts();
    let text = match axum::body::to_bytes(body, MAX_REJECTION_BYTES).await {
        Ok(bytes) if !bytes.is_empty() => String::from_utf8_lossy(&bytes).into_owned(),
        _ => status.canonical_reason().unwrap_or("error").to_string(),
    };
    let mut rewritten = problem_response(status, code_of_status(status), text.trim());
    // keep headers such as `Allow` on a 405
    for (name, value) in parts.headers.iter() {
        if name != http::header::CONTENT_TYPE && name != http::header::CONTENT_LENGTH {
            rewritten.headers_mut().insert(name.clone(), value.clone());
        }
    }
    rewritten
}

impl From<ApiError> for tonic::Status {
    fn from(e: ApiError) -> Self {
        e.to_status()
    }
}

impl From<ServiceError> for tonic::Status {
    fn from(e: ServiceError) -> Self {
        ApiError::from(e).to_status()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_table_maps_each_code_once() {
        assert_eq!(ErrorCode::InvalidArgument.http(), 400);
        assert_eq!(ErrorCode::Unauthenticated.grpc(), tonic::Code::Unauthenticated);
        assert_eq!(ErrorCode::PayloadTooLarge.http(), 413);
        assert_eq!(ErrorCode::PermissionDenied.http(), 403);
        assert_eq!(ErrorCode::PermissionDenied.grpc(), tonic::Code::PermissionDenied);
        let e = ApiError::from(ServiceError::InvalidArgument("scene.xml:3:5: bad".into()));
        assert_eq!(e.to_status().code(), tonic::Code::InvalidArgument);
        let e = ApiError::from(ServiceError::Io(std::io::Error::other("disk /secret/path full")));
        assert!(!e.message.contains("secret"));
    }

    #[test]
    fn problems_carry_status_title_detail_and_code() {
        let p = problem(http::StatusCode::CONFLICT, "failed_precondition", "job j1 is running");
        assert_eq!(p["status"], 409);
        assert_eq!(p["title"], "Conflict");
        assert_eq!(p["detail"], "job j1 is running");
        assert_eq!(p["code"], "failed_precondition");
        assert_eq!(code_of_status(http::StatusCode::METHOD_NOT_ALLOWED), "method_not_allowed");
        assert_eq!(code_of_status(http::StatusCode::UNPROCESSABLE_ENTITY), "invalid_argument");
    }
}
