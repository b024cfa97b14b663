//! Why the model refuses an event: each refusal names the job and what stands in the way.

/// Why a call was refused outright.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TransitionError {
    /// No such job.
    #[error("job {0} not found")]
    UnknownJob(String),
    /// A job with this id exists.
    #[error("job {0} already exists")]
    DuplicateJob(String),
    /// The job is not waiting for the optimiser.
    #[error("job {0} is not at an optimisation barrier")]
    NotOptimizing(String),
    /// The job is not waiting for its outputs (it was cancelled meanwhile).
    #[error("job {0} is not finishing")]
    NotFinishing(String),
    /// A job id prefix that more than one job has.
    #[error("job id prefix {prefix} matches {count} jobs: give more of the id")]
    AmbiguousPrefix {
        /// The prefix.
        prefix: String,
        /// How many jobs have it.
        count: usize,
    },
    /// A frame whose scene did not load: the same bundle cannot load it again.
    #[error("frame job {0} failed because its scene did not load: submit the frames again with the scene fixed")]
    SceneRefused(String),
    /// A frame planned out of turn, or of a cancelled sequence.
    #[error("sequence {sequence} is not planning frame {index}")]
    NotPlanning {
        /// The sequence.
        sequence: String,
        /// The frame's position.
        index: usize,
    },
    /// Only a failed or cancelled job can be requeued.
    #[error("job {job} is {state}: only a failed or cancelled job can be requeued")]
    NotRequeueable {
        /// The job.
        job: String,
        /// Its state.
        state: &'static str,
    },
    /// Only a job that has not ended can be paused or resumed.
    #[error("job {job} is {state}: it has ended")]
    Ended {
        /// The job.
        job: String,
        /// Its state.
        state: &'static str,
    },
    /// Only a finished, failed or cancelled job can be removed.
    #[error("job {job} is {state}: cancel it before deleting it")]
    Unfinished {
        /// The job.
        job: String,
        /// Its state.
        state: &'static str,
    },
}
