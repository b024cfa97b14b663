//! The exit codes of `tessera`, one per kind of failure a script may want to tell apart:
//!
//! | code | meaning |
//! |---|---|
//! | 0 | success |
//! | 1 | any other failure (a render that failed, a file that cannot be written, ...) |
//! | 2 | invalid input: arguments, a scene that does not load, settings the coordinator refuses |
//! | 3 | not found: no such job (or no output of that kind) |
//! | 4 | unauthorised: the coordinator refused the token |
//! | 5 | unreachable: no coordinator answers at the URL |
//! | 6 | the job failed or was cancelled (`submit --wait`, `wait`, `download`) |

use super::client::{Refused, Unreachable};
use super::fetch::JobEnded;
use crate::options::InvalidInput;
use tonic::Code;

/// Any other failure.
pub const FAILURE: u8 = 1;
/// Invalid input (clap's usage errors exit with it too).
pub const INVALID_INPUT: u8 = 2;
/// No such job.
pub const NOT_FOUND: u8 = 3;
/// The token was refused.
pub const UNAUTHORISED: u8 = 4;
/// No coordinator answers.
pub const UNREACHABLE: u8 = 5;
/// The job failed or was cancelled.
pub const JOB_FAILED: u8 = 6;

/// The exit code for `e`, by the first cause in its chain that says which kind it is.
pub fn code(e: &anyhow::Error) -> u8 {
    for cause in e.chain() {
        if let Some(r) = cause.downcast_ref::<Refused>() {
            return match r.code {
                Code::NotFound => NOT_FOUND,
                Code::Unauthenticated | Code::PermissionDenied => UNAUTHORISED,
                Code::Unavailable => UNREACHABLE,
                Code::InvalidArgument | Code::OutOfRange => INVALID_INPUT,
                _ => FAILURE,
            };
        }
        if cause.is::<Unreachable>() {
            return UNREACHABLE;
        }
        if cause.is::<JobEnded>() {
            return JOB_FAILED;
        }
        if cause.is::<InvalidInput>()
            || cause.is::<tessera_common::scene::SceneError>()
            || cause.is::<tessera_common::settings::SettingsError>()
        {
            return INVALID_INPUT;
        }
    }
    FAILURE
}
