//! What Tessera's fuzz targets share: a scratch folder on a tmpfs for the loaders that take a
//! path, the small memory budgets the targets pass, the files a fuzzed scene may name, and the
//! handling of panics that the code under test catches itself.

use std::cell::RefCell;
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, Once, OnceLock};
use tessera_common::texture::TextureLimits;

/// The decoded size one fuzzed image (or a fuzzed scene's images together) may take: enough for
/// any seed, far from the 1 GiB that libFuzzer's `-rss_limit_mb=1024` allows the process.
pub const TEXTURE_BUDGET: u64 = 16 << 20;

/// [`TEXTURE_BUDGET`] as the limits the loaders take.
pub fn texture_limits() -> TextureLimits {
    TextureLimits::total(TEXTURE_BUDGET)
}

/// The folder this process writes its inputs to: a folder per process under
/// `$TESSERA_FUZZ_SCRATCH` when set (scripts/fuzz.sh sets it and removes it afterwards), else
/// under /dev/shm (a tmpfs, so no disk writes), else under the system's temporary folder.
pub fn scratch() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base = std::env::var_os("TESSERA_FUZZ_SCRATCH").map(PathBuf::from).unwrap_or_else(default_base);
        let dir = base.join(format!("tessera-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("invariant: the scratch folder can be created");
        dir
    })
}

fn default_base() -> PathBuf {
    let shm = Path::new("/dev/shm");
    if shm.is_dir() { shm.to_path_buf() } else { std::env::temp_dir() }
}

/// Writes `bytes` to `name` in the scratch folder and returns its path.
pub fn write(name: &str, bytes: &[u8]) -> PathBuf {
    let path = scratch().join(name);
    std::fs::write(&path, bytes).expect("invariant: the scratch folder is writable");
    path
}

/// The files a fuzzed scene may name (beside `scene.xml`, which is the input itself): one
/// small valid file of every kind the builder reads, from the seed corpus.
const SCENE_ASSETS: &[(&str, &[u8])] = &[
    ("mesh.ply", include_bytes!("../corpus/mesh_ply/quad-ascii.ply")),
    ("mesh-binary.ply", include_bytes!("../corpus/mesh_ply/colors-binary.ply")),
    ("mesh.obj", include_bytes!("../corpus/mesh_obj/quad.obj")),
    ("mesh.serialized", include_bytes!("../corpus/mesh_serialized/two-meshes.serialized")),
    ("tex.png", include_bytes!("../corpus/bitmap/rgb8.png")),
    ("tex16.png", include_bytes!("../corpus/bitmap/rgb16.png")),
    ("tex.jpg", include_bytes!("../corpus/bitmap/rgb.jpg")),
    ("tex.exr", include_bytes!("../corpus/bitmap/rgb32.exr")),
    ("tex.hdr", include_bytes!("../corpus/bitmap/rgb.hdr")),
    ("tex.bmp", include_bytes!("../corpus/bitmap/rgb.bmp")),
    ("tex.tga", include_bytes!("../corpus/bitmap/rgb.tga")),
    ("tex.pfm", include_bytes!("../corpus/bitmap/gray.pfm")),
    ("tex.ppm", include_bytes!("../corpus/bitmap/rgb.ppm")),
    ("spec.spd", include_bytes!("../assets/spec.spd")),
    ("part.xml", include_bytes!("../assets/part.xml")),
];

/// The files besides `scene.xml` that a scene target's input holds (a farm job's bundle may hold
/// any number of XML files: several let includes fan out).
pub const SCENE_INCLUDES: [&str; 3] = ["inc1.xml", "inc2.xml", "inc3.xml"];

/// Writes a scene target's input to the scratch folder and returns the path of `scene.xml`:
/// the input up to its first NUL byte (which XML text cannot hold) is `scene.xml`, and the
/// parts after the next NULs are [`SCENE_INCLUDES`] (each written, empty when absent, so that
/// no file is left from an earlier input).
pub fn write_scene(data: &[u8]) -> PathBuf {
    let mut parts = data.splitn(SCENE_INCLUDES.len() + 1, |&b| b == 0);
    let scene = write("scene.xml", parts.next().unwrap_or_default());
    for name in SCENE_INCLUDES {
        write(name, parts.next().unwrap_or_default());
    }
    scene
}

/// Writes [`SCENE_ASSETS`] to the scratch folder (once per process) and returns the folder.
pub fn scene_folder() -> &'static Path {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        for (name, bytes) in SCENE_ASSETS {
            write(name, bytes);
        }
    });
    scratch()
}

thread_local! {
    /// The input being run, for the panic hook of [`tolerate_caught_panics`].
    static INPUT: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
}

/// Runs `f` on `data` where the code under test catches panics itself (the image decoders:
/// a panic on a malformed file becomes an error for that texture, as on a worker). libFuzzer's
/// hook would abort on any panic, caught or not; this one reports each caught panic's location
/// once per process (message and input saved as `caught-panic-<hash>` under
/// `$TESSERA_FUZZ_ARTIFACTS` when set) and lets it unwind. A panic that nothing catches still
/// aborts (libfuzzer-sys aborts when one reaches the harness). `TESSERA_FUZZ_STRICT=1` keeps
/// libFuzzer's hook, so that caught panics are crashes too.
pub fn tolerate_caught_panics(data: &[u8], f: impl FnOnce()) {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        if std::env::var_os("TESSERA_FUZZ_STRICT").is_none_or(|v| v != "1") {
            std::panic::set_hook(Box::new(report_panic_once));
        }
    });
    INPUT.with(|input| data.clone_into(&mut input.borrow_mut()));
    f();
}

fn report_panic_once(info: &std::panic::PanicHookInfo<'_>) {
    static SEEN: Mutex<Option<HashSet<String>>> = Mutex::new(None);
    let location = info.location().map(|l| format!("{}:{}:{}", l.file(), l.line(), l.column())).unwrap_or_default();
    let mut seen = SEEN.lock().unwrap_or_else(|e| e.into_inner());
    if !seen.get_or_insert_with(HashSet::new).insert(location.clone()) {
        return;
    }
    let hash = fnv1a(location.as_bytes());
    eprintln!("tessera-fuzz: caught panic (tolerated) at {location}: {info}");
    if let Some(dir) = std::env::var_os("TESSERA_FUZZ_ARTIFACTS") {
        let path = Path::new(&dir).join(format!("caught-panic-{hash:016x}"));
        INPUT.with(|input| std::fs::write(&path, &*input.borrow()).ok());
        eprintln!("tessera-fuzz: input saved as {}", path.display());
    }
}

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// What the wire targets read from their first bytes: the job the coordinator knows from its
/// own state (a lease, a job's settings), which the uploaded bytes must match. Shared with
/// `examples/wire_seeds.rs`, which writes valid seeds for every choice.
pub mod job {
    use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, PilotStart};
    use tessera_common::film::filter::{Filter, FilterKind};
    use tessera_common::film::{FilmSpec, Rect};

    fn filter(selector: u8) -> Filter {
        match selector % 4 {
            0 => Filter::BOX,
            1 => Filter::new(FilterKind::DEFAULT),
            2 => Filter::new(FilterKind::Tent { radius: 1.0 }),
            _ => Filter::new(FilterKind::Lanczos { lobes: 3 }),
        }
    }

    /// The film (1–8 × 1–8 pixels, one of four filters) and the tile of it (or the full
    /// frame, whose layout keeps splats apart) that `head` names.
    pub fn lease(head: [u8; 3]) -> (FilmSpec, Rect) {
        let (width, height) = (head[0] as u32 % 8 + 1, head[1] as u32 % 8 + 1);
        let spec = FilmSpec::new(width, height, filter(head[2]));
        let mut rects = Rect::tiles(width, height, (head[2] as u32 >> 2) % 4 + 1);
        rects.push(spec.full());
        let rect = rects[(head[2] as usize >> 4) % rects.len()];
        (spec, rect)
    }

    /// Which EMIS decoder a `head` runs.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Decoder {
        /// `PilotData::decode`.
        Pilot,
        /// `EmisState::decode`.
        State,
        /// `EmisState::read_decisions`.
        Decisions,
    }

    /// The EMIS job that `head` describes: the decoder, the configuration (method and pilot),
    /// the candidate set of the pilot data, and the image's width and height (1–4 each).
    pub fn emis(head: [u8; 2]) -> (Decoder, EmisConfig, CandidateSet, u32, u32) {
        let decoder = [Decoder::Pilot, Decoder::State, Decoder::Decisions][head[0] as usize % 3];
        let method = if head[0] & 4 == 0 { EmisMethod::Bdpt } else { EmisMethod::Vcm };
        let mut config = EmisConfig::own_pilot(method);
        config.pilot = if head[0] & 8 == 0 { PilotStart::Bidirectional } else { PilotStart::PathTracing };
        let set = if head[0] & 16 == 0 { CandidateSet::Full } else { CandidateSet::Reduced };
        (decoder, config, set, head[1] as u32 % 4 + 1, (head[1] as u32 >> 2) % 4 + 1)
    }
}
