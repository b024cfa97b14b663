//! Tests of jobs of many frames in the pure model: lazy planning in a window, frame order,
//! the frame's parameter and seed, a frame that fails alone, cancel, and the sequence's state.

use super::model::calls::Calls;
use super::model::*;
use tessera_common::settings::{IntegratorName, RenderSettings};

const TTL: u64 = 1000;

fn sequence(frames: Vec<u32>, seed_per_frame: bool) -> SequenceSpec {
    SequenceSpec {
        name: "move".into(),
        priority: 0,
        settings: RenderSettings { integrator: IntegratorName::Pt, spp: Some(1), seed: Some(5), ..Default::default() },
        frames,
        frame_param: "frame".into(),
        seed_per_frame,
        warm_start: false,
        scene_path: "move.xml".into(),
        bundle_digest: "d".into(),
        after: vec![],
        require_tags: vec![],
    }
}

/// Plans every frame due, as the service does (each scene "loads" here).
fn plan(m: &mut JobsModel) {
    for (s, indices) in m.frames_due() {
        for index in indices {
            let (scene_path, settings) = m.sequences[&s].spec.frame(index);
            let spec = JobSpec { scene_path, settings, ..JobSpec::bare("f", IntegratorName::Pt, Some(1), 64, 64) };
            m.apply(Event::PlanFrame { sequence: &s, index, spec: Box::new(spec), error: None }, 1).unwrap();
        }
    }
}

/// Frames are planned at most `FRAMES_IN_FLIGHT` ahead, each with its parameter, file and
/// seed; workers get the earliest frame's tiles first; as frames end, more are planned.
#[test]
fn frames_are_planned_lazily_in_order_with_their_parameter_and_seed() {
    let mut m = JobsModel::default();
    m.apply(Event::SubmitSequence { id: "s", spec: Box::new(sequence((1..=40).collect(), true)) }, 0).unwrap();
    assert_eq!(m.sequence_state("s"), Some(JobState::Queued));
    plan(&mut m);
    assert_eq!(m.sequences["s"].planned, FRAMES_IN_FLIGHT);
    let first = &m.jobs[&SequenceSpec::frame_id("s", 0)];
    assert_eq!((first.spec.scene_path.as_str(), first.spec.settings.seed), ("move.xml", Some(6)));
    assert_eq!(first.spec.settings.defines.get("frame").map(String::as_str), Some("1"));
    // one file per frame: the file is the frame, no parameter is set
    let files = SequenceSpec { scene_path: "shot.####.xml".into(), ..sequence(vec![7], false) };
    let (path, settings) = files.frame(0);
    assert_eq!((path.as_str(), settings.defines.is_empty(), settings.seed), ("shot.0007.xml", true, Some(5)));
    let (leases, _) = m.lease("w", 1, 2, TTL);
    assert_eq!(leases[0].job, SequenceSpec::frame_id("s", 0), "the earliest frame first");
    for f in 0..4 {
        m.cancel(&SequenceSpec::frame_id("s", f), 3).unwrap();
    }
    plan(&mut m);
    assert_eq!(m.sequences["s"].planned, FRAMES_IN_FLIGHT + 4, "four frames ended: four more planned");
    assert_eq!(m.sequence_state("s"), Some(JobState::Final));
}

/// Pausing a job of frames pauses its frames, those planned meanwhile too; resuming resumes
/// them all.
#[test]
fn pausing_a_job_of_frames_pauses_its_frames_planned_and_to_come() {
    let mut m = JobsModel::default();
    m.apply(Event::SubmitSequence { id: "s", spec: Box::new(sequence((1..=20).collect(), false)) }, 0).unwrap();
    plan(&mut m);
    m.pause("s", 1).unwrap();
    assert!(m.lease("w", 4, 2, TTL).0.is_empty());
    m.cancel(&SequenceSpec::frame_id("s", 0), 3).unwrap();
    plan(&mut m);
    let last = &m.jobs[&SequenceSpec::frame_id("s", FRAMES_IN_FLIGHT)];
    assert_eq!(last.shown_state(), JobState::Paused, "planned while paused");
    m.resume("s", 4).unwrap();
    assert!(m.frames_of("s").iter().filter(|j| !j.state.is_terminal()).all(|j| j.paused_ms.is_none()));
    assert_eq!(m.lease("w", 1, 5, TTL).0.len(), 1);
}

/// With a warm start, frame N+1 is planned once frame N decided (and starts from that
/// decision) or ended without one (and starts cold); the rest of the window waits.
#[test]
fn a_warm_started_frame_waits_for_the_decision_of_the_frame_before() {
    use super::spec::{MergeSpec, WarmStart};
    let mut m = JobsModel::default();
    let spec = SequenceSpec { warm_start: true, ..sequence((1..=5).collect(), false) };
    m.apply(Event::SubmitSequence { id: "s", spec: Box::new(spec) }, 0).unwrap();
    plan(&mut m);
    plan(&mut m);
    assert_eq!(m.sequences["s"].planned, 1, "frame 2 waits for frame 1's decision");
    assert_eq!(m.warm_start_of("s", 1), None);
    let decision = WarmStart { nu: 0.5, connections: 2, connection_mask: None, merge: MergeSpec::Mask("m".into()) };
    let first = SequenceSpec::frame_id("s", 0);
    let effects = m.apply(Event::Decided { job: &first, decision: Box::new(decision.clone()) }, 2).unwrap();
    assert!(effects.changes.contains_key(&first), "the decision is written with the frame");
    assert_eq!(m.warm_start_of("s", 1), Some(decision));
    plan(&mut m);
    assert_eq!(m.sequences["s"].planned, 2);
    // a frame that ends without a decision lets the next one start cold
    m.cancel(&SequenceSpec::frame_id("s", 1), 3).unwrap();
    assert_eq!(m.warm_start_of("s", 2), None);
    plan(&mut m);
    assert_eq!(m.sequences["s"].planned, 3);
    // without a warm start, frames do not start from one another
    m.apply(Event::SubmitSequence { id: "t", spec: Box::new(sequence((1..=5).collect(), false)) }, 4).unwrap();
    plan(&mut m);
    assert_eq!(m.sequences["t"].planned, 5);
    let t0 = SequenceSpec::frame_id("t", 0);
    let decision = WarmStart { nu: 1.0, connections: 1, connection_mask: None, merge: MergeSpec::None };
    m.apply(Event::Decided { job: &t0, decision: Box::new(decision) }, 5).unwrap();
    assert_eq!(m.warm_start_of("t", 1), None);
}

/// A frame whose scene did not load fails alone and cannot be requeued; cancelling the
/// sequence plans no more and ends it; a done sequence is done.
#[test]
fn a_refused_frame_fails_alone_and_cancel_ends_the_sequence() {
    let mut m = JobsModel::default();
    m.apply(Event::SubmitSequence { id: "s", spec: Box::new(sequence(vec![3, 5], false)) }, 0).unwrap();
    let spec = JobSpec::bare("f", IntegratorName::Pt, Some(1), 64, 64);
    let refused = Event::PlanFrame { sequence: "s", index: 0, spec: Box::new(spec.clone()), error: Some("no".into()) };
    let effects = m.apply(refused, 1).unwrap();
    let frame0 = SequenceSpec::frame_id("s", 0);
    assert_eq!(effects.ended().collect::<Vec<_>>(), [(frame0.as_str(), JobState::Failed)]);
    assert_eq!(effects.changes[&frame0].len(), 1, "its tile's row is written with its failure");
    assert!(matches!(m.requeue(&frame0, 0, 2), Err(TransitionError::SceneRefused(_))));
    let late = Event::PlanFrame { sequence: "s", index: 0, spec: Box::new(spec.clone()), error: None };
    assert!(matches!(m.apply(late, 2), Err(TransitionError::NotPlanning { .. })), "planned twice");
    m.apply(Event::PlanFrame { sequence: "s", index: 1, spec: Box::new(spec), error: None }, 2).unwrap();
    for l in m.lease("w", 4, 3, TTL).0 {
        m.result("w", &l, Ok(()), 4);
    }
    m.merged(&SequenceSpec::frame_id("s", 1), 1, 5);
    assert_eq!(m.sequence_state("s"), Some(JobState::Failed), "one frame failed, the other is done");
    m.apply(Event::SubmitSequence { id: "t", spec: Box::new(sequence((1..=30).collect(), false)) }, 6).unwrap();
    plan(&mut m);
    m.cancel("t", 7).unwrap();
    assert!(m.frames_due().is_empty());
    assert_eq!(m.sequence_state("t"), Some(JobState::Cancelled));
    assert!(m.frames_of("t").iter().all(|j| j.state == JobState::Cancelled));
}

/// A job of frames survives a restart: its frames planned so far come back as jobs, it plans
/// no more than its window then, and cancelled and deleted it leaves no frame behind.
#[test]
fn a_job_of_frames_survives_a_restart_and_goes_whole() {
    use super::service::{FramesRequest, JobService};
    use super::service_tests::{CFG, cornell};
    let dir = tempfile::tempdir().unwrap();
    let (bundle, _) = cornell();
    let xml = String::from_utf8(bundle.files[0].1.clone()).unwrap();
    let xml =
        xml.replacen(r#"<scene version="3.0.0">"#, r#"<scene version="3.0.0"><default name="frame" value="0"/>"#, 1);
    let lookat = r#"<lookat origin="0, 0, 3.9" target="0, 0, 0" up="0, 1, 0"/>"#;
    let xml = xml.replacen(lookat, &format!(r#"{lookat}<rotate y="1" angle="$frame"/>"#), 1);
    let frames =
        FramesRequest { frames: (1..=40).collect(), param: "frame".into(), seed_per_frame: false, warm_start: false };
    let settings = RenderSettings { spp: Some(1), ..Default::default() };
    let id = {
        let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
        let mut upload = svc.begin_upload(u64::MAX).unwrap();
        upload.start_file("scene.xml").unwrap();
        upload.write(xml.as_bytes()).unwrap();
        let view = svc.submit_frames(upload, "scene.xml", settings, 0.into(), None, frames, 1_000).unwrap();
        assert_eq!((view.frames_total, view.frames.len()), (40, FRAMES_IN_FLIGHT));
        view.id
    };
    let svc = JobService::open(dir.path(), CFG, 2_000).unwrap();
    svc.plan_frames(2_000).unwrap();
    let view = svc.get(&id[..8], 2_000).unwrap();
    assert_eq!((view.id.as_str(), view.frames.len(), view.state), (id.as_str(), FRAMES_IN_FLIGHT, JobState::Queued));
    assert_eq!(view.frames[3].number, 4);
    assert_eq!(svc.list(2_000).unwrap().len(), 1, "one job: its frames are inside it");
    svc.cancel(&id, 3_000).unwrap();
    svc.delete(&id).unwrap();
    assert!(svc.list(3_000).unwrap().is_empty());
    let svc = JobService::open(dir.path(), CFG, 4_000).unwrap();
    assert!(svc.list(4_000).unwrap().is_empty(), "nothing came back");
}
