//! The one error-code table: every domain error maps to an [`ErrorCode`], and each code has
//! exactly one HTTP status and one gRPC code. Client-facing messages name the field, file and
//! line at fault; internal failures are logged in full once and reported without details.

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
}
