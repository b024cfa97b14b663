//! Fuzzes what a client sends to ask for frames: the range text of `--frames`
//! (`tessera_link::frames::parse`) and a frame-numbered name (`expand`). A parse that succeeds
//! names each frame once and at most `MAX_FRAMES` of them; an expanded name keeps no `#`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tessera_link::frames::{MAX_FRAMES, expand, parse};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(frames) = parse(text) {
        assert!(frames.len() <= MAX_FRAMES, "{} frames", frames.len());
        let unique: std::collections::HashSet<_> = frames.iter().collect();
        assert_eq!(unique.len(), frames.len(), "a frame named twice");
        if let Some(&n) = frames.first() {
            assert!(!expand(text, n).contains('#'), "a run of # left in the name");
        }
    }
});
