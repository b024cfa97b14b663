//! Fuzzes the EMIS wire decoders of `tessera_common::emis::wire`: the pilot data a worker
//! uploads (`PilotData::decode`), the coordinator's checkpoint (`EmisState::decode`) and the
//! head of one (`EmisState::read_decisions`). The first two bytes choose the decoder, the
//! method, the pilot, the candidate set and the image size (1–4 × 1–4 pixels), as the
//! coordinator knows them from the job (`tessera_fuzz::job`); the rest is the data. What
//! decodes must encode to data that decodes again.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tessera_common::emis::{CandidateSet, EmisConfig, EmisState, PilotData};
use tessera_fuzz::job::{self, Decoder};

fn pilot(config: &EmisConfig, set: CandidateSet, width: u32, height: u32, bytes: &[u8]) {
    let candidates = config.candidates_of(set).len();
    let Ok(pilot) = PilotData::decode(bytes, width, height, candidates) else { return };
    if let Err(e) = PilotData::decode(&pilot.encode(), width, height, candidates) {
        panic!("decoded pilot data encodes to data that does not decode: {e}");
    }
}

fn state(config: EmisConfig, width: u32, height: u32, bytes: &[u8]) {
    let Ok(state) = EmisState::decode(config.clone(), width, height, bytes) else { return };
    if let Err(e) = EmisState::decode(config, width, height, &state.encode()) {
        panic!("a decoded checkpoint encodes to one that does not decode: {e}");
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((head, bytes)) = data.split_first_chunk::<2>() else { return };
    let (decoder, config, set, width, height) = job::emis(*head);
    match decoder {
        Decoder::Pilot => pilot(&config, set, width, height, bytes),
        Decoder::State => state(config, width, height, bytes),
        Decoder::Decisions => {
            let _ = EmisState::read_decisions(&mut &bytes[..]);
        }
    }
});
