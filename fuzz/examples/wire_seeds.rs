//! Writes the seed corpus of the wire targets, `corpus/tile_payload/` and `corpus/emis_wire/`,
//! with the project's own encoders, so that every seed is valid data for the job its first
//! bytes name (`tessera_fuzz::job`). Run in fuzz/: `cargo run --example wire_seeds`.

use glam::{Vec2, Vec3};
use std::path::Path;
use tessera_common::emis::cost::StatisticsSums;
use tessera_common::emis::guides::GuideBuffer;
use tessera_common::emis::moments::MomentBuffer;
use tessera_common::emis::{CandidateSet, EmisState, PilotData};
use tessera_common::film::TileAccum;
use tessera_fuzz::job::{self, Decoder};
use tessera_link::payload::encode_tile;

fn main() {
    let corpus = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus");
    tile_seeds(&corpus.join("tile_payload"));
    emis_seeds(&corpus.join("emis_wire"));
}

fn put(dir: &Path, name: &str, head: &[u8], body: &[u8]) {
    std::fs::create_dir_all(dir).expect("the corpus folder can be created");
    std::fs::write(dir.join(name), [head, body].concat()).expect("the corpus folder is writable");
}

/// For every filter and a few film sizes: a seed for a tile and one for the full frame.
fn tile_seeds(dir: &Path) {
    for (w, h) in [(2u8, 1u8), (4, 3), (8, 8)] {
        for filter in 0..4u8 {
            let heads = (0..=255u8).filter(|c| c % 4 == filter && (c >> 2) % 4 == 1).map(|c| [w - 1, h - 1, c]);
            let mut seen = (false, false);
            for head in heads {
                let (spec, rect) = job::lease(head);
                let full = rect == spec.full();
                if (full && seen.1) || (!full && seen.0) {
                    continue;
                }
                seen = (seen.0 || !full, seen.1 || full);
                let mut tile = TileAccum::new(rect, &spec);
                let raster = Vec2::new(rect.x0 as f32 + 0.25, rect.y0 as f32 + 0.75);
                tile.add_sample(rect.x0, rect.y0, raster, Vec3::new(0.25, 0.5, 1.0));
                if full {
                    tile.add_splat(Vec2::new(0.5, 0.5), Vec3::ONE);
                }
                put(
                    dir,
                    &format!("tile-{w}x{h}-f{filter}-{}", if full { "full" } else { "tile" }),
                    &head,
                    &encode_tile(&tile),
                );
            }
        }
    }
}

/// The first header byte that runs `decoder` with the configuration bits `flags`.
fn emis_head(decoder: Decoder, flags: u8, width: u32, height: u32) -> [u8; 2] {
    let size = (width - 1 + 4 * (height - 1)) as u8;
    let first = (0..=255u8)
        .find(|&b| b & 28 == flags && job::emis([b, size]).0 == decoder)
        .expect("invariant: every decoder has a byte for every flag set");
    [first, size]
}

fn pilot_data(width: u32, height: u32, candidates: usize, guides: bool) -> PilotData {
    let mut moments = MomentBuffer::new(width, height, candidates);
    for (i, s) in moments.sums.iter_mut().enumerate() {
        *s = if i % 5 == 2 { f32::INFINITY } else { i as f32 * 0.5 };
    }
    moments.iterations = 1;
    let mut buffer = GuideBuffer::new(width, height);
    buffer.samples = 1;
    if guides {
        buffer.albedo.iter_mut().for_each(|a| *a = [0.5, 0.25, 0.125]);
        buffer.depth.iter_mut().enumerate().for_each(|(i, d)| *d = i as f32);
    }
    let statistics = StatisticsSums { iterations: 1, camera_vertices: 4, light_paths: 2, ..Default::default() };
    PilotData { moments, statistics, guides: buffer }
}

/// Pilot data, checkpoints and their heads for both methods, pilots and candidate sets.
fn emis_seeds(dir: &Path) {
    for flags in [0u8, 4, 8, 12, 16, 20] {
        for (width, height, guides) in [(1, 1, false), (3, 2, true)] {
            let head = emis_head(Decoder::Pilot, flags, width, height);
            let (_, config, set, ..) = job::emis(head);
            let data = pilot_data(width, height, config.candidates_of(set).len(), guides);
            put(dir, &format!("pilot-{flags}-{width}x{height}"), &head, &data.encode());
            if set == CandidateSet::Full {
                let state = EmisState::new(config.clone(), width, height).encode();
                let head = emis_head(Decoder::State, flags, width, height);
                put(dir, &format!("state-{flags}-{width}x{height}"), &head, &state);
                let head = emis_head(Decoder::Decisions, flags, width, height);
                put(dir, &format!("decisions-{flags}-{width}x{height}"), &head, &state);
            }
        }
    }
}
