//! Tests of the EMIS wire encodings: round trips, other format versions and bad data refused.

use super::*;
use crate::emis::EmisMethod;

fn pilot(width: u32, height: u32, candidates: usize) -> PilotData {
    let pixels = (width * height) as usize;
    let mut moments = MomentBuffer::new(width, height, candidates);
    for (i, s) in moments.sums.iter_mut().enumerate() {
        *s = if i % 7 == 3 { f32::INFINITY } else { i as f32 * 0.25 };
    }
    moments.iterations = 2;
    let mut guides = GuideBuffer::new(width, height);
    guides.samples = 2;
    guides.albedo = (0..pixels).map(|i| [i as f32, 0.5, 0.25]).collect();
    guides.depth = (0..pixels).map(|i| i as f32 * 3.0).collect();
    let statistics = StatisticsSums {
        iterations: 2,
        camera_vertices: 10,
        light_paths: 12,
        light_vertices: 30,
        merge_queries: 8,
        photons_per_path: 0.75,
        times: WorkTimes {
            iterations: 2,
            light_vertices: 30,
            light_ns: 3,
            photons_built: 20,
            build_ns: 5,
            camera_vertices: 7,
            camera_ns: 11,
            connections: 13,
            connection_ns: 17,
            queries: 19,
            photons: 23,
            photons_squared: 29.5,
            merge_ns: 31,
            merge_ns_photons: 37.25,
            observer_ns: 41,
            path_tracing_vertices: 43,
            path_tracing_ns: 47,
        },
    };
    PilotData { moments, statistics, guides }
}

#[test]
fn uploads_carry_moments_in_half_the_bytes_and_lose_nothing_once_rounded() {
    let mut p = pilot(3, 2, 5);
    p.moments.sums[1] = 0.1;
    let exact = p.clone();
    p.moments.round_for_wire();
    let bytes = p.encode();
    assert_eq!(bytes.len(), p.encoded_len());
    assert_eq!(
        (&bytes[..4], &bytes[4..12]),
        (&PILOT_MAGIC[..], &[FORMAT_VERSION.to_le_bytes(), 1u32.to_le_bytes()].concat()[..])
    );
    assert_eq!(PilotData::decode(&bytes, 3, 2, 5).unwrap(), p);
    // an upload of another version is refused by name, whatever follows
    let mut other = bytes.clone();
    other[4..8].copy_from_slice(&(FORMAT_VERSION - 1).to_le_bytes());
    let e = PilotData::decode(&other, 3, 2, 5).unwrap_err();
    assert!(e.contains("format version 2") && e.contains("another Tessera version"), "{e}");
    other[4..8].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    other[8..12].copy_from_slice(&2u32.to_le_bytes());
    assert!(PilotData::decode(&other, 3, 2, 5).unwrap_err().contains("precision 2"));
    // unrounded sums are rounded by the encoding: the decoded data is not the original
    assert_ne!(PilotData::decode(&exact.encode(), 3, 2, 5).unwrap(), exact);
    // a checkpoint keeps sums exactly (they are sums of rounded calls, not rounded)
    let mut w = Writer(Vec::new());
    write_pilot(&mut w, SumPrecision::F32, &exact.moments, &exact.statistics, &exact.guides);
    assert_eq!(PilotData::decode(&w.0, 3, 2, 5).unwrap(), exact);
    assert_eq!(w.0.len(), bytes.len() + 2 * exact.moments.sums.len() - 4);
    // without guides (calls past the guide iterations) an upload leaves them out
    p.guides = GuideBuffer::new(3, 2);
    let bytes = p.encode();
    assert_eq!(bytes.len(), p.encoded_len());
    assert_eq!(bytes.len(), pilot(3, 2, 5).encode().len() - 6 * 7 * 4);
    assert_eq!(PilotData::decode(&bytes, 3, 2, 5).unwrap(), p);
    // a negative zero is not left out (it would come back positive)
    p.guides.normal[1][2] = -0.0;
    let back = PilotData::decode(&p.encode(), 3, 2, 5).unwrap();
    assert_eq!(back.guides.normal[1][2].to_bits(), (-0.0f32).to_bits());
}

#[test]
fn pilot_data_round_trips_and_refuses_bad_sizes_and_values() {
    let p = pilot(3, 2, 5);
    let bytes = p.encode();
    assert_eq!(bytes.len(), p.encoded_len());
    assert_eq!(PilotData::decode(&bytes, 3, 2, 5).unwrap(), p);
    assert!(PilotData::decode(&bytes, 2, 3, 5).unwrap_err().contains("expected 2×3"));
    assert!(PilotData::decode(&bytes[..bytes.len() - 1], 3, 2, 5).unwrap_err().contains("depth guide"));
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(PilotData::decode(&longer, 3, 2, 5).unwrap_err().contains("too many"));
    let mut nan = p.clone();
    nan.moments.sums[7] = f32::NAN;
    assert!(PilotData::decode(&nan.encode(), 3, 2, 5).unwrap_err().contains("moment sum 7 (pixel 1)"));
    let mut guide = p.clone();
    guide.guides.normal[0][1] = f32::INFINITY;
    assert!(PilotData::decode(&guide.encode(), 3, 2, 5).unwrap_err().contains("guide"));
    let mut times = p;
    times.statistics.times.photons_squared = f64::NAN;
    assert!(PilotData::decode(&times.encode(), 3, 2, 5).unwrap_err().contains("work time"));
}

#[test]
fn decisions_read_from_a_checkpoint_head_alone() {
    let config = EmisConfig::own_pilot(EmisMethod::Vcm);
    let mut state = EmisState::new(config, 4, 3);
    state.update(&[[0.5; 3]; 12], 1, crate::emis::RestartTotal::Time(u32::MAX));
    let bytes = state.encode();
    let d = EmisState::read_decisions(&mut &bytes[..]).unwrap();
    assert_eq!(
        (d.nu, Connections::Fixed(d.connections), d.reports.len()),
        (state.strategy.nu, state.strategy.connections, 1)
    );
    assert_eq!(d.reports[0].iteration, 1);
    // the head is enough: the buffers after it are not read
    let meta_len = 12 + u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize;
    assert!(EmisState::read_decisions(&mut &bytes[..meta_len]).is_ok());
    assert!(EmisState::read_decisions(&mut &bytes[..meta_len - 1]).unwrap_err().contains("bytes"));
    assert!(EmisState::read_decisions(&mut &b"TPIL........"[..]).unwrap_err().contains("unknown format"));
    let mut other = bytes.clone();
    other[4..8].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    assert!(EmisState::read_decisions(&mut &other[..]).unwrap_err().contains("another Tessera version"));
    let config = EmisConfig::own_pilot(EmisMethod::Vcm);
    assert!(EmisState::decode(config, 4, 3, &other).err().is_some_and(|e| e.contains("another Tessera version")));
}

#[test]
fn emis_state_checkpoint_round_trips() {
    let config = EmisConfig::own_pilot(EmisMethod::Vcm);
    let mut state = EmisState::new(config.clone(), 3, 2);
    state.absorb(&pilot(3, 2, state.candidates.len())).unwrap();
    state.strategy = Strategy {
        nu: 0.5,
        connections: Connections::Fixed(2),
        merge: Some(MergeMask::PerPixel(Arc::new(vec![0.0, 1.0, 0.5, 0.25, 1.0, 0.0]))),
    };
    state.relative_moment = Some(Image { width: 3, height: 2, data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0] });
    state.updates_done = 2;
    state.stop_collecting();
    let back = EmisState::decode(config.clone(), 3, 2, &state.encode()).unwrap();
    assert_eq!(back.strategy, state.strategy);
    // per-pixel connections travel after the merge mask, and are checked
    let mut per_pixel = EmisState::decode(config.clone(), 3, 2, &state.encode()).unwrap();
    per_pixel.strategy.connections = Connections::PerPixel(Arc::new(vec![0.0, 1.5, 8.0, 0.25, 4.0, 2.0]));
    let back = EmisState::decode(config.clone(), 3, 2, &per_pixel.encode()).unwrap();
    assert_eq!(back.strategy, per_pixel.strategy);
    assert_eq!(back.relative_moment.as_ref().map(|i| &i.data), state.relative_moment.as_ref().map(|i| &i.data));
    per_pixel.strategy.connections = Connections::PerPixel(Arc::new(vec![0.0, 1.5, f32::NAN, 0.25, 4.0, 2.0]));
    let err = EmisState::decode(config.clone(), 3, 2, &per_pixel.encode()).map(|_| ()).unwrap_err();
    assert!(err.contains("connection mask value NaN at pixel 2"), "{err}");
    assert_eq!(back.moments, state.moments);
    assert_eq!(back.statistics, state.statistics);
    assert_eq!(back.guides, state.guides);
    assert_eq!(back.updates_done, 2);
    assert!(!back.collecting());
    assert_eq!(back.relative_moment.as_ref().map(|i| &i.data), state.relative_moment.as_ref().map(|i| &i.data));
    assert!(EmisState::decode(config, 2, 3, &state.encode()).is_err());
}

/// A path-tracing start keeps its reduced candidate set across a checkpoint, and after the
/// restart the full set and the first kept iteration.
#[test]
fn emis_state_checkpoint_keeps_the_candidate_set_and_the_first_kept_iteration() {
    let config = EmisConfig::new(EmisMethod::Vcm);
    let mut state = EmisState::new(config.clone(), 3, 2);
    assert_eq!((state.candidate_set, state.candidates.len()), (CandidateSet::Reduced, 9));
    state.absorb(&pilot(3, 2, 9)).unwrap();
    let back = EmisState::decode(config.clone(), 3, 2, &state.encode()).unwrap();
    assert_eq!((back.candidate_set, back.candidates.len(), back.kept_from), (CandidateSet::Reduced, 9, 0));
    assert_eq!(back.moments, state.moments);
    assert_eq!(back.strategy, state.strategy);
    state.candidate_set = CandidateSet::Full;
    state.candidates = config.candidates_of(CandidateSet::Full);
    state.moments = MomentBuffer::new(3, 2, 51);
    state.kept_from = 4;
    let back = EmisState::decode(config.clone(), 3, 2, &state.encode()).unwrap();
    assert_eq!((back.candidate_set, back.candidates.len(), back.kept_from), (CandidateSet::Full, 51, 4));
    // a reduced set after a restart, or with the bidirectional pilot, is corrupt
    state.candidate_set = CandidateSet::Reduced;
    assert!(EmisState::decode(config, 3, 2, &state.encode()).err().unwrap().contains("reduced"));
    state.kept_from = 0;
    let bidirectional = EmisConfig::own_pilot(EmisMethod::Vcm);
    assert!(EmisState::decode(bidirectional, 3, 2, &state.encode()).err().unwrap().contains("reduced"));
}

/// A kept path-tracing start travels with its image and the exact bits of its weight, and
/// one that does not end where the image begins is refused.
#[test]
fn emis_state_checkpoint_keeps_the_path_tracing_start() {
    let config = EmisConfig::new(EmisMethod::Vcm);
    let mut state = EmisState::new(config.clone(), 3, 2);
    state.candidate_set = CandidateSet::Full;
    state.candidates = config.candidates_of(CandidateSet::Full);
    state.moments = MomentBuffer::new(3, 2, 51);
    state.kept_from = 4;
    let image: Vec<[f32; 3]> = (0..6).map(|p| [p as f32, 0.1 * p as f32, 1.0 / (1 + p) as f32]).collect();
    state.start = Some(KeptStart { image, iterations: 4, weight: None });
    let back = EmisState::decode(config.clone(), 3, 2, &state.encode()).unwrap();
    assert_eq!(back.start, state.start);
    state.start.as_mut().unwrap().weight = Some(0.1 + 0.2);
    let back = EmisState::decode(config.clone(), 3, 2, &state.encode()).unwrap();
    assert_eq!(back.start, state.start);
    state.start.as_mut().unwrap().iterations = 3;
    let err = EmisState::decode(config, 3, 2, &state.encode()).err().unwrap();
    assert!(err.contains("kept start"), "{err}");
}
