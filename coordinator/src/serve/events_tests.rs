//! The event stream's comparison of snapshots: what becomes which event.

use super::*;
use crate::serve::job::model::JobState;
use crate::serve::job::view::FrameView;

fn job(id: &str, state: JobState, tiles_done: u64) -> JobView {
    JobView {
        id: id.into(),
        name: format!("name of {id}"),
        state,
        phase: String::new(),
        progress: tiles_done as f64 / 4.0,
        tiles_done,
        tiles_total: 4,
        samples_done: tiles_done * 16,
        eta_s: Some(10.0),
        error: None,
        priority: 0,
        settings: Default::default(),
        width: 8,
        height: 8,
        created_ms: 0,
        scene_digest: String::new(),
        strategy: None,
        frames_total: 0,
        frames: Vec::new(),
    }
}

fn worker(id: &str, leases: usize, last_seen_s_ago: f64) -> WorkerView {
    let (name, threads, tags) = (id.to_string(), 2, Vec::new());
    WorkerView { id: id.into(), name, threads, last_seen_s_ago, leases, state: "busy", tags }
}

fn kinds(changes: &[Change]) -> Vec<(&'static str, Option<&str>, bool)> {
    changes.iter().map(|(kind, job, _, ends, _)| (*kind, job.as_deref(), *ends)).collect()
}

#[test]
fn new_jobs_state_changes_progress_and_deletions_become_events() {
    let a = Snapshot::of(&[job("j1", JobState::Final, 1), job("j2", JobState::Queued, 0)], &[]);
    let b = Snapshot::of(&[job("j1", JobState::Final, 2), job("j3", JobState::Queued, 0)], &[]);
    let c = Snapshot::of(&[job("j1", JobState::Done, 4), job("j3", JobState::Queued, 0)], &[]);
    assert_eq!(
        kinds(&a.changes(&b)),
        [("job.progress", Some("j1"), false), ("job.state", Some("j3"), false), ("job.deleted", Some("j2"), true)]
    );
    assert_eq!(kinds(&b.changes(&c)), [("job.state", Some("j1"), true)]);
    assert!(c.changes(&c).is_empty(), "nothing changed, nothing sent");
    let data: serde_json::Value = serde_json::from_str(&b.changes(&c)[0].4).unwrap();
    assert_eq!((data["state"].as_str(), data["tiles_done"].as_u64()), (Some("done"), Some(4)));
}

#[test]
fn the_clock_alone_sends_nothing() {
    let mut later = job("j1", JobState::Final, 1);
    later.eta_s = Some(9.5);
    let before = Snapshot::of(&[job("j1", JobState::Final, 1)], &[worker("w1", 1, 0.5)]);
    let after = Snapshot::of(&[later], &[worker("w1", 1, 3.0)]);
    assert!(before.changes(&after).is_empty());
}

#[test]
fn frames_and_workers_become_events() {
    let mut seq = job("s1", JobState::Final, 0);
    seq.frames_total = 2;
    let frame =
        |state| FrameView { number: 7, job_id: "s1-0007".into(), state, progress: 0.0, eta_s: None, error: None };
    seq.frames = vec![frame(JobState::Final)];
    let a = Snapshot::of(&[seq.clone()], &[worker("w1", 0, 0.0), worker("w2", 1, 0.0)]);
    seq.frames = vec![frame(JobState::Done)];
    let b = Snapshot::of(&[seq], &[worker("w1", 1, 0.0)]);
    let changes = a.changes(&b);
    assert_eq!(
        kinds(&changes),
        [
            ("job.progress", Some("s1"), false),
            ("frame.state", Some("s1"), true),
            ("worker", None, false),
            ("worker.gone", None, false)
        ]
    );
    assert_eq!(changes[1].2.as_deref(), Some("s1-0007"), "a frame's events name its own job too");
    // the frame's stream ends with it, its job of frames' stream does not
    let hub = Hub::default();
    let mut rx = hub.subscribe();
    hub.publish(vec![changes[1].clone()]);
    let done = rx.try_recv().unwrap();
    assert!(done.ends("s1-0007") && !done.ends("s1"));
    let frame: serde_json::Value = serde_json::from_str(&changes[1].4).unwrap();
    assert_eq!((frame["frame"].as_u64(), frame["state"].as_str()), (Some(7), Some("done")));
    let job: serde_json::Value = serde_json::from_str(&changes[0].4).unwrap();
    assert_eq!(job["frames_done"], 1);
}

#[tokio::test]
async fn subscribers_get_each_event_once_and_numbered() {
    let hub = Hub::default();
    let mut rx = hub.subscribe();
    let a = Snapshot::default();
    let b = Snapshot::of(&[job("j1", JobState::Queued, 0)], &[]);
    hub.publish(a.changes(&b));
    hub.publish(b.changes(&b));
    let e = rx.recv().await.unwrap();
    assert_eq!((e.kind, e.concerns("j1"), e.concerns("j2")), ("job.state", true, false));
    assert!(rx.try_recv().is_err(), "one event");
    let next = hub.single("job.state", &JobLine::of(&job("j1", JobState::Done, 4)));
    assert!(next.id > e.id && next.ends_job);
}
