//! Jobs of many frames (`--frames`). A sequence is one job to its client, and one job per
//! frame to the model: frame N is a job like any other (its own driver, tiles, EMIS state,
//! outputs), with the frame parameter in its defines (and the seed plus N when the seed varies
//! per frame), so it renders the bits `tessera render SCENE -D frame=N` renders. Frames are
//! planned lazily, [`FRAMES_IN_FLIGHT`] at a time in frame order, so ten thousand queued
//! frames cost a list of numbers; the service loads each frame's scene before it plans it
//! (`Event::PlanFrame`), and a frame whose scene does not load fails alone
//! (`Event::RefuseFrame`).
//!
//! Frames of one sequence share its submission order and rank among themselves by frame, so
//! workers take the earliest frames' tiles first and move on to the next frame while the last
//! tiles of one are out: frames and tiles interleave.
//! Why it is built so, with its measurements: docs/decisions/0071-frames-are-jobs-planned-lazily.md.

use super::super::spec::WarmStart;
use super::{Changes, Job, JobSpec, JobState, JobsModel, TransitionError, join, touch};
use serde::{Deserialize, Serialize};
use tessera_common::settings::RenderSettings;

/// Frames of one sequence planned and not ended at once: enough to keep a farm's workers busy
/// across frame ends, few enough that planning them costs little.
pub const FRAMES_IN_FLIGHT: usize = 16;

/// Which frame of which sequence a job renders.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameRef {
    /// The sequence.
    pub sequence: String,
    /// The frame's position in the sequence's list.
    pub index: usize,
    /// The frame number.
    pub number: u32,
    /// Its scene did not load when it was planned: requeueing cannot mend it.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub refused: bool,
}

/// What a sequence renders, fixed at submission.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SequenceSpec {
    /// Display name.
    pub name: String,
    /// Higher runs first.
    pub priority: i32,
    /// The settings as submitted (each frame resolves its own from its scene).
    pub settings: RenderSettings,
    /// The frame numbers, in order.
    pub frames: Vec<u32>,
    /// The scene parameter that carries the frame number.
    pub frame_param: String,
    /// Frame N renders with seed S + N.
    pub seed_per_frame: bool,
    /// EMIS: frame N+1 starts from frame N's decision, and is planned once it is made.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub warm_start: bool,
    /// The scene's path in the bundle; runs of `#` are the frame number.
    pub scene_path: String,
    /// Digest of the bundle that holds every frame's files.
    pub bundle_digest: String,
    /// Jobs that must be done before the first frame starts.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub after: Vec<String>,
    /// Tags a worker must have.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub require_tags: Vec<String>,
}

impl SequenceSpec {
    /// The job id of frame `index` of sequence `id`.
    pub fn frame_id(id: &str, index: usize) -> String {
        format!("{id}-{index:06}")
    }

    /// Frame `index`'s scene path and settings ([`tessera_link::frames::FrameRule`]).
    pub fn frame(&self, index: usize) -> (String, RenderSettings) {
        let rule = tessera_link::frames::FrameRule {
            scene: &self.scene_path,
            param: &self.frame_param,
            seed_per_frame: self.seed_per_frame,
        };
        rule.frame(&self.settings, self.frames[index])
    }
}

/// A sequence and how far its planning got.
#[derive(Clone, Debug, PartialEq)]
pub struct Sequence {
    /// Unique id.
    pub id: String,
    /// Submission order (its frames share it).
    pub seq: u64,
    /// What it renders.
    pub spec: SequenceSpec,
    /// Submission time.
    pub created_ms: u64,
    /// Frames planned so far: `spec.frames[..planned]` have jobs.
    pub planned: usize,
    /// Cancelled by a client: no more frames are planned.
    pub cancelled: bool,
    /// Paused by a client since then: its frames are paused, those planned meanwhile too.
    pub paused_ms: Option<u64>,
}

impl Sequence {
    /// The ids of its planned frames' jobs, in order.
    pub fn frame_ids(&self) -> impl Iterator<Item = String> + '_ {
        (0..self.planned).map(|i| SequenceSpec::frame_id(&self.id, i))
    }
}

impl JobsModel {
    /// The next seq number, over jobs and sequences.
    pub(super) fn next_seq(&self) -> u64 {
        let jobs = self.jobs.values().map(|j| j.seq + 1).max().unwrap_or(0);
        jobs.max(self.sequences.values().map(|s| s.seq + 1).max().unwrap_or(0))
    }

    pub(super) fn submit_sequence(
        &mut self,
        id: &str,
        spec: SequenceSpec,
        now_ms: u64,
    ) -> Result<Changes, TransitionError> {
        if self.jobs.contains_key(id) || self.sequences.contains_key(id) {
            return Err(TransitionError::DuplicateJob(id.to_string()));
        }
        let seq = self.next_seq();
        let sequence = Sequence {
            id: id.to_string(),
            seq,
            spec,
            created_ms: now_ms,
            planned: 0,
            cancelled: false,
            paused_ms: None,
        };
        self.sequences.insert(id.to_string(), sequence);
        let mut changes = Changes::new();
        touch(&mut changes, id, None);
        Ok(changes)
    }

    /// The frames each sequence may plan now: up to [`FRAMES_IN_FLIGHT`] not ended, in order;
    /// with a warm start, the next once the frame before it decided or ended.
    pub fn frames_due(&self) -> Vec<(String, Vec<usize>)> {
        let mut due = Vec::new();
        for s in self.sequences.values().filter(|s| !s.cancelled && s.planned < s.spec.frames.len()) {
            let active = s.frame_ids().filter(|id| self.jobs.get(id).is_some_and(|j| !j.state.is_terminal())).count();
            let mut room = FRAMES_IN_FLIGHT.saturating_sub(active).min(s.spec.frames.len() - s.planned);
            if s.spec.warm_start {
                // one at a time: each waits for the one before it
                let before = s.planned.checked_sub(1).and_then(|i| self.jobs.get(&SequenceSpec::frame_id(&s.id, i)));
                let ready = before.is_none_or(|j| j.decided.is_some() || j.state.is_terminal());
                room = room.min(usize::from(ready));
            }
            if room > 0 {
                due.push((s.id.clone(), (s.planned..s.planned + room).collect()));
            }
        }
        due
    }

    /// Adds frame `index` of `sequence` as a job of `spec` (the service loaded its scene);
    /// `error`: its scene did not load, and the frame fails with it.
    pub(super) fn plan_frame(
        &mut self,
        sequence: &str,
        index: usize,
        spec: JobSpec,
        error: Option<String>,
        now_ms: u64,
    ) -> Result<Changes, TransitionError> {
        let s = self.sequences.get(sequence).ok_or_else(|| TransitionError::UnknownJob(sequence.to_string()))?;
        if s.cancelled || s.planned != index || index >= s.spec.frames.len() {
            return Err(TransitionError::NotPlanning { sequence: sequence.to_string(), index });
        }
        let id = SequenceSpec::frame_id(sequence, index);
        let (seq, s_paused) = (s.seq, s.paused_ms);
        let number = s.spec.frames[index];
        let frame = FrameRef { sequence: sequence.to_string(), index, number, refused: error.is_some() };
        let spec = JobSpec { frame: Some(frame), ..spec };
        let mut changes = self.submit(&id, spec, now_ms)?;
        let job = self.jobs.get_mut(&id).expect("invariant: just submitted");
        job.seq = seq;
        job.paused_ms = s_paused;
        if let Some(error) = error {
            join(&mut changes, self.fail(&id, error, now_ms));
        }
        self.sequences.get_mut(sequence).expect("invariant: found above").planned += 1;
        touch(&mut changes, sequence, None);
        Ok(changes)
    }

    /// The decision a warm-started frame `index` of `sequence` starts from: the frame before's,
    /// if it made one.
    pub fn warm_start_of(&self, sequence: &str, index: usize) -> Option<WarmStart> {
        let s = self.sequences.get(sequence).filter(|s| s.spec.warm_start && index > 0)?;
        self.jobs.get(&SequenceSpec::frame_id(&s.id, index - 1))?.decided.clone()
    }

    /// A job's EMIS updates ended on `decision` ([`super::Event::Decided`]).
    pub(super) fn decided(&mut self, job: &str, decision: WarmStart) -> Result<Changes, TransitionError> {
        let j = self.jobs.get_mut(job).ok_or_else(|| TransitionError::UnknownJob(job.to_string()))?;
        let mut changes = Changes::new();
        if j.decided.as_ref() != Some(&decision) {
            j.decided = Some(decision);
            touch(&mut changes, job, None);
        }
        Ok(changes)
    }

    /// Cancels a sequence: no more frames are planned, and its frames that have not ended are
    /// cancelled.
    pub(super) fn cancel_sequence(&mut self, id: &str, now_ms: u64) -> Result<Changes, TransitionError> {
        let s = self.sequences.get_mut(id).ok_or_else(|| TransitionError::UnknownJob(id.to_string()))?;
        let mut changes = Changes::new();
        if !s.cancelled && s.planned < s.spec.frames.len() {
            s.cancelled = true;
            touch(&mut changes, id, None);
        }
        let frames: Vec<String> = self.sequences[id].frame_ids().filter(|f| self.jobs.contains_key(f)).collect();
        for frame in &frames {
            join(&mut changes, self.cancel(frame, now_ms)?);
        }
        Ok(changes)
    }

    /// The frames of a sequence, planned so far.
    pub fn frames_of(&self, id: &str) -> Vec<&Job> {
        self.sequences.get(id).map_or(Vec::new(), |s| s.frame_ids().filter_map(|f| self.jobs.get(&f)).collect())
    }

    /// A sequence's state: ended once every frame is planned (or it was cancelled) and every
    /// planned frame ended — done if all are, failed if one failed, else cancelled; otherwise
    /// queued until a frame starts, then final.
    pub fn sequence_state(&self, id: &str) -> Option<JobState> {
        let s = self.sequences.get(id)?;
        let frames = self.frames_of(id);
        let all_planned = s.cancelled || s.planned == s.spec.frames.len();
        if all_planned && frames.iter().all(|j| j.state.is_terminal()) {
            return Some(if frames.iter().all(|j| j.state == JobState::Done) && !s.cancelled {
                JobState::Done
            } else if frames.iter().any(|j| j.state == JobState::Failed) {
                JobState::Failed
            } else {
                JobState::Cancelled
            });
        }
        let started = frames.iter().any(|j| j.state != JobState::Queued);
        Some(if started { JobState::Final } else { JobState::Queued })
    }
}

impl JobsModel {
    /// Adds a sequence loaded from storage, after its frames' jobs: it planned as many frames as
    /// there are.
    pub fn restore_sequence(&mut self, mut s: Sequence) {
        let frames = self.jobs.values().filter_map(|j| j.spec.frame.as_ref()).filter(|f| f.sequence == s.id);
        s.planned = frames.map(|f| f.index + 1).max().unwrap_or(0);
        self.sequences.insert(s.id.clone(), s);
    }

    /// Lets a cancelled sequence plan its remaining frames again (its ended frames are
    /// requeued one by one).
    pub(super) fn resume_planning(&mut self, id: &str) -> Result<Changes, TransitionError> {
        let s = self.sequences.get_mut(id).ok_or_else(|| TransitionError::UnknownJob(id.to_string()))?;
        let mut changes = Changes::new();
        if s.cancelled {
            s.cancelled = false;
            touch(&mut changes, id, None);
        }
        Ok(changes)
    }

    /// Pauses (`Some(now)`) or resumes (`None`) a sequence: its frames that have not ended,
    /// and those it plans meanwhile.
    pub(super) fn pause_sequence(
        &mut self,
        id: &str,
        paused: Option<u64>,
        now_ms: u64,
    ) -> Result<Changes, TransitionError> {
        let s = self.sequences.get_mut(id).ok_or_else(|| TransitionError::UnknownJob(id.to_string()))?;
        let mut changes = Changes::new();
        if s.paused_ms.is_some() != paused.is_some() {
            s.paused_ms = paused;
            touch(&mut changes, id, None);
        }
        let frames: Vec<String> = s.frame_ids().collect();
        for f in &frames {
            if self.jobs.get(f).is_some_and(|j| !j.state.is_terminal()) {
                join(
                    &mut changes,
                    match paused {
                        Some(_) => self.pause(f, now_ms)?,
                        None => self.resume_paused(f, now_ms)?,
                    },
                );
            }
        }
        Ok(changes)
    }

    /// Removes an ended sequence (its frames' jobs are removed by the caller).
    pub fn remove_sequence(&mut self, id: &str) -> Result<Sequence, TransitionError> {
        let state = self.sequence_state(id).ok_or_else(|| TransitionError::UnknownJob(id.to_string()))?;
        if !state.is_terminal() {
            return Err(TransitionError::Unfinished { job: id.to_string(), state: state.as_str() });
        }
        Ok(self.sequences.remove(id).expect("invariant: its state was found"))
    }
}
