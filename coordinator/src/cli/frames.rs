//! The `--frames` flags that `tessera render` and `tessera submit` share: which frames, the
//! scene parameter that carries the number, the seed per frame and EMIS's warm start, and
//! where each frame's files go.

use crate::options::InvalidInput;
use std::path::{Path, PathBuf};
use tessera_link::frames::FrameRule;

/// Frames of a camera move or a sequence of scene files.
#[derive(clap::Args, Debug, Clone)]
pub struct FrameArgs {
    /// Render these frames (`1-240`, `1-240:2`, `1,5,10-20`): frame N sets the scene parameter
    /// `--frame-param` to N, as `-D frame=N` would. A scene name with runs of `#`
    /// (`shot.####.xml`) is one file per frame. `-o` names the frames' files with `#` runs
    /// too [default: SCENE.####.exr].
    #[arg(long, value_name = "FRAMES")]
    pub frames: Option<String>,
    /// The scene parameter that carries the frame number.
    #[arg(long, default_value = "frame", value_name = "NAME")]
    pub frame_param: String,
    /// Frame N renders with the seed plus N (as `tessera render --seed S+N`), not all with S.
    #[arg(long)]
    pub seed_per_frame: bool,
    /// emis-*: start each frame from the previous frame's decision (its strategy once its
    /// updates ended) instead of the pilot; a frame then waits for that decision. Frame N
    /// equals `tessera render --frames` of the frames up to N with this flag.
    #[arg(long, requires = "frames")]
    pub warm_start: bool,
}

impl FrameArgs {
    /// The frame numbers, if `--frames` was given.
    pub fn numbers(&self) -> Result<Option<Vec<u32>>, InvalidInput> {
        self.frames.as_deref().map(tessera_link::frames::parse).transpose().map_err(InvalidInput)
    }

    /// How frame N is made of `scene` (a path with runs of `#` or one file).
    pub fn rule<'a>(&'a self, scene: &'a str) -> FrameRule<'a> {
        FrameRule { scene, param: &self.frame_param, seed_per_frame: self.seed_per_frame }
    }
}

/// The name of `scene` a job and its outputs take: its file or folder name, its own `#` runs
/// left out.
pub fn job_name(scene: &Path) -> String {
    crate::options::scene_name(scene).replace('#', "").trim_matches('.').to_string()
}

/// The output a command writes by default for `scene`: `NAME.exr`, or `NAME.####.exr` for
/// frames.
pub fn default_output(scene: &Path, frames: bool) -> PathBuf {
    let name = job_name(scene);
    PathBuf::from(if frames { format!("{name}.####.exr") } else { format!("{name}.exr") })
}

/// Where frame `number` goes: `output` with its runs of `#` the frame number (`.####` before
/// the extension when it has none).
pub fn frame_path(output: &Path, number: u32) -> PathBuf {
    let text = output.to_string_lossy();
    if tessera_link::frames::is_pattern(&text) {
        return PathBuf::from(tessera_link::frames::expand(&text, number));
    }
    let stem = output.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let ext = output.extension().map_or_else(|| "exr".into(), |e| e.to_string_lossy().into_owned());
    output.with_file_name(format!("{stem}.{number:04}.{ext}"))
}
