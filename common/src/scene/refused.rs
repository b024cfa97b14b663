//! Mitsuba plugins Tessera refuses, as one table: a scene using any of them fails to load with
//! `FILE:LINE:COLUMN: <tag> "<plugin>" is not supported`, wherever the element is, rather than
//! rendering something else. Plugins neither here nor in Tessera's set get the builders' own
//! "unsupported …" errors, which list what is supported.
//!
//! ```
//! use tessera_common::scene::refused::is_refused;
//! assert!(is_refused("shape", "cylinder"));
//! assert!(is_refused("medium", "homogeneous"));
//! assert!(!is_refused("shape", "sphere"));
//! ```

use super::error::SceneError;
use super::xml::Element;

/// Matches every plugin of a tag.
pub const ANY: &str = "*";

/// Refused for good: features outside Tessera's RGB surface renderer. `(tag, plugin)`.
pub const REFUSED: &[(&str, &str)] = &[
    // participating media
    ("medium", ANY),
    ("phase", ANY),
    ("volume", ANY),
    ("texture", "volume"),
    // polarisation
    ("bsdf", "pplastic"),
    ("bsdf", "polarizer"),
    ("bsdf", "retarder"),
    ("bsdf", "circular"),
    ("bsdf", "measured_polarized"),
    ("integrator", "stokes"),
    // shapes
    ("shape", "instance"),
    ("shape", "shapegroup"),
    ("shape", "cylinder"),
    ("shape", "curve"),
    ("shape", "bsplinecurve"),
    ("shape", "linearcurve"),
    ("shape", "sdfgrid"),
    ("shape", "ellipsoids"),
    ("shape", "ellipsoidsmesh"),
    ("shape", "blender"),
    ("shape", "merge"),
    // bsdfs
    ("bsdf", "blendbsdf"),
    ("bsdf", "normalmap"),
    ("bsdf", "bumpmap"),
    ("bsdf", "principled"),
    ("bsdf", "principledthin"),
    ("bsdf", "hair"),
    ("bsdf", "measured"),
    ("bsdf", "null"),
    // emitters
    ("emitter", "directionalarea"),
    ("emitter", "projector"),
    ("emitter", "sunsky"),
    ("emitter", "timed_sunsky"),
    // sensors and films
    ("sensor", "thinlens"),
    ("sensor", "orthographic"),
    ("sensor", "irradiancemeter"),
    ("sensor", "radiancemeter"),
    ("sensor", "distant"),
    ("sensor", "batch"),
    ("film", "specfilm"),
    // integrators of Mitsuba 3 (and of Mitsuba 0.6, found in old scenes) that Tessera's
    // scene-file settings do not model; the algorithm is chosen with --integrator
    ("integrator", "depth"),
    ("integrator", "prb"),
    ("integrator", "prb_basic"),
    ("integrator", "prbvolpath"),
    ("integrator", "prb_projective"),
    ("integrator", "direct_projective"),
    ("integrator", "bdpt"),
    ("integrator", "pssmlt"),
    ("integrator", "mlt"),
    ("integrator", "erpt"),
    ("integrator", "photonmapper"),
    ("integrator", "ppm"),
    ("integrator", "sppm"),
    ("integrator", "vpl"),
    ("integrator", "ao"),
    ("integrator", "irrcache"),
    ("integrator", "adaptive"),
    ("integrator", "field"),
    ("integrator", "multichannel"),
    ("integrator", "volpath_simple"),
];

/// Whether `<tag type="plugin">` is refused.
pub fn is_refused(tag: &str, plugin: &str) -> bool {
    REFUSED.iter().any(|(t, p)| *t == tag && (*p == ANY || *p == plugin))
}

/// Fails on the first refused element in document order, at any depth.
pub fn check_supported(elements: &[Element]) -> Result<(), SceneError> {
    for e in elements {
        if is_refused(&e.tag, &e.plugin) {
            return Err(SceneError::at(&e.location, format!("{} is not supported", e.describe())));
        }
        check_supported(&e.children)?;
    }
    Ok(())
}
