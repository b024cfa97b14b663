//! Interprets `<integrator>` and `<sampler>` elements into the settings a render starts from.
//!
//! Tessera picks its rendering algorithm on the command line; from the scene file it takes what
//! decides the converged image (path length, hidden emitters) and the sample budget. So every
//! Mitsuba integrator and sampler whose *expectation* Tessera reproduces is accepted, with one
//! warning per element saying what is approximated:
//!
//! * integrators `path`; `volpath`/`volpathmis` (no media, which are refused anyway); `direct`
//!   (= `path` with `max_depth` 2); `ptracer` (its `max_depth` means what `path`'s does); `aov`
//!   and `moment` (their first nested integrator);
//! * samplers `independent`, `stratified`, `multijitter`, `orthogonal`, `ldsampler`, with the
//!   sample count rounded up as each does. Tessera draws independent samples, so only the noise
//!   differs; `jitter=false` is refused because stratum centres change the expectation.

use super::IntegratorSettings;
use super::error::SceneError;
use super::xml::Element;

#[derive(Clone, Copy)]
enum Kind {
    Float,
    Integer,
    Boolean,
}

/// Parameters every sampling integrator reads that do not change the converged image.
const SAMPLING_INTEGRATOR_EXTRAS: &[(&str, Kind)] =
    &[("timeout", Kind::Float), ("block_size", Kind::Integer), ("samples_per_pass", Kind::Integer)];

/// The settings of an `<integrator>` element.
pub(super) fn build_integrator(e: &Element) -> Result<IntegratorSettings, SceneError> {
    match e.plugin.as_str() {
        "aov" | "moment" => build_wrapper(e),
        "path" | "volpath" | "volpathmis" | "ptracer" => build_path_like(e),
        "direct" => build_direct(e),
        other => Err(SceneError::at(
            &e.location,
            format!(
                "unsupported integrator \"{other}\" in the scene file (use path, volpath, direct, ptracer, aov or moment; choose Tessera's integrator with --integrator)"
            ),
        )),
    }
}

/// Reads (type-checked) the parameters in `names` that are present, returning which were.
fn read_ignored(e: &Element, names: &[(&'static str, Kind)]) -> Result<Vec<&'static str>, SceneError> {
    let mut present = vec![];
    for &(name, kind) in names {
        let found = match kind {
            Kind::Float => e.float(name)?.is_some(),
            Kind::Integer => e.integer(name)?.is_some(),
            Kind::Boolean => {
                let found = e.properties.iter().any(|p| p.name == name);
                e.boolean_or(name, false)?;
                found
            }
        };
        if found {
            present.push(name);
        }
    }
    Ok(present)
}

fn max_depth(e: &Element) -> Result<Option<u32>, SceneError> {
    match e.integer("max_depth")?.unwrap_or(-1) {
        -1 => Ok(None),
        d if d >= 0 => Ok(Some(d.min(u32::MAX as i64) as u32)),
        d => Err(SceneError::at(
            e.location_of("max_depth"),
            format!("\"max_depth\" must be -1 (unlimited) or non-negative, found {d}"),
        )),
    }
}

fn rr_depth(e: &Element) -> Result<u32, SceneError> {
    match e.integer("rr_depth")?.unwrap_or(5) {
        d if d > 0 => Ok(d.min(u32::MAX as i64) as u32),
        d => Err(SceneError::at(e.location_of("rr_depth"), format!("\"rr_depth\" must be positive, found {d}"))),
    }
}

fn build_path_like(e: &Element) -> Result<IntegratorSettings, SceneError> {
    let settings = IntegratorSettings {
        kind: e.plugin.clone(),
        max_depth: max_depth(e)?,
        rr_depth: rr_depth(e)?,
        hide_emitters: e.boolean_or("hide_emitters", false)?,
        delta_light_factor: 1,
    };
    let mut ignored = read_ignored(e, SAMPLING_INTEGRATOR_EXTRAS)?;
    if e.plugin == "volpathmis" {
        ignored.extend(read_ignored(e, &[("use_spectral_mis", Kind::Boolean)])?);
    }
    e.check_all_used()?;
    let why = match e.plugin.as_str() {
        "path" if ignored.is_empty() => return Ok(settings),
        "path" => "integrator parameters that do not change the image are ignored",
        "ptracer" => "ptracer converges to path's image with the same max_depth: rendered with Tessera's integrator",
        _ => "volpath without media converges to path's image: rendered with Tessera's integrator",
    };
    tracing::warn!(file = %e.location, integrator = %e.plugin, ignored = ?ignored, "{why}");
    Ok(settings)
}

/// `direct` = emitter hits plus next-event and BSDF samples at the first surface: `path`'s
/// expectation with `max_depth` 2, but that each emitter sample of a point, spot or directional
/// light counts whole ([`IntegratorSettings::delta_light_factor`]).
fn build_direct(e: &Element) -> Result<IntegratorSettings, SceneError> {
    let shading = e.integer("shading_samples")?;
    let (emitter, bsdf) = (e.integer("emitter_samples")?, e.integer("bsdf_samples")?);
    if shading.is_some() && (emitter.is_some() || bsdf.is_some()) {
        return Err(SceneError::at(
            e.location_of("shading_samples"),
            "give either \"shading_samples\" or \"emitter_samples\"/\"bsdf_samples\", not both",
        ));
    }
    let shading = shading.unwrap_or(1);
    let counts = [emitter.unwrap_or(shading), bsdf.unwrap_or(shading)];
    if counts.iter().any(|c| *c < 0) || counts.iter().all(|c| *c == 0) {
        return Err(SceneError::at(
            &e.location,
            "direct needs at least one emitter or bsdf sample (and none negative)",
        ));
    }
    let hide_emitters = e.boolean_or("hide_emitters", false)?;
    let ignored = read_ignored(e, SAMPLING_INTEGRATOR_EXTRAS)?;
    e.check_all_used()?;
    if counts[1] == 0 {
        // BSDF sampling is the only way `direct` lights a smooth mirror or glass (or a lobe
        // of one): without it Mitsuba shows no light there, path tracing does
        tracing::warn!(
            file = %e.location,
            "direct with bsdf_samples 0 renders what mirrors, glass and smooth coatings reflect of area and environment lights; Mitsuba leaves it black"
        );
    }
    tracing::warn!(
        file = %e.location,
        integrator = %e.plugin,
        ignored = ?ignored,
        "direct converges to path's image with max_depth 2, point, spot and directional lights times emitter_samples: rendered that way"
    );
    Ok(IntegratorSettings {
        kind: e.plugin.clone(),
        max_depth: Some(2),
        rr_depth: 5,
        hide_emitters,
        delta_light_factor: counts[0] as u32,
    })
}

/// `aov` and `moment` render their first nested integrator; the extra outputs are not produced.
fn build_wrapper(e: &Element) -> Result<IntegratorSettings, SceneError> {
    if e.plugin == "aov" && e.string("aovs")?.is_none() {
        return Err(SceneError::at(&e.location, "aov needs \"aovs\""));
    }
    e.boolean_or("hide_emitters", false)?;
    read_ignored(e, SAMPLING_INTEGRATOR_EXTRAS)?;
    if let Some(c) = e.children.iter().find(|c| c.tag != "integrator") {
        return Err(SceneError::at(
            &c.location,
            format!("{} can only contain integrators, found <{}>", e.describe(), c.tag),
        ));
    }
    let first = e
        .children
        .first()
        .ok_or_else(|| SceneError::at(&e.location, format!("{} needs a nested integrator", e.describe())))?;
    let settings = build_integrator(first)?;
    for other in &e.children[1..] {
        build_integrator(other)?;
    }
    e.check_all_used()?;
    tracing::warn!(
        file = %e.location,
        integrator = %e.plugin,
        "only the first nested integrator's image is rendered; the extra channels are not produced"
    );
    Ok(settings)
}

/// Samples per pixel and seed of a `<sampler>`.
pub(super) fn build_sampler(c: &Element) -> Result<(u32, u64), SceneError> {
    const SAMPLERS: &[&str] = &["independent", "stratified", "multijitter", "orthogonal", "ldsampler"];
    if !SAMPLERS.contains(&c.plugin.as_str()) {
        return Err(SceneError::at(
            &c.location,
            format!("unsupported sampler \"{}\" (supported: {})", c.plugin, SAMPLERS.join(", ")),
        ));
    }
    let requested = match c.integer("sample_count")?.unwrap_or(4) {
        n if n > 0 && n <= u32::MAX as i64 => n as u32,
        n => {
            return Err(SceneError::at(
                c.location_of("sample_count"),
                format!("\"sample_count\" must be positive, found {n}"),
            ));
        }
    };
    let seed = match c.integer("seed")?.unwrap_or(0) {
        s if (0..=u32::MAX as i64).contains(&s) => s as u64,
        s => {
            return Err(SceneError::at(
                c.location_of("seed"),
                format!("\"seed\" must lie in 0..=4294967295, found {s}"),
            ));
        }
    };
    if matches!(c.plugin.as_str(), "stratified" | "multijitter" | "orthogonal") && !c.boolean_or("jitter", true)? {
        return Err(SceneError::at(
            c.location_of("jitter"),
            format!(
                "{} with jitter=false puts samples at stratum centres, which changes the image; Tessera renders jittered samples only",
                c.describe()
            ),
        ));
    }
    if c.plugin == "orthogonal" {
        c.integer("strength")?;
    }
    c.check_all_used()?;
    let spp = rounded_sample_count(&c.plugin, requested).ok_or_else(|| {
        SceneError::at(c.location_of("sample_count"), format!("\"sample_count\" {requested} is too large"))
    })?;
    if c.plugin != "independent" {
        tracing::warn!(
            file = %c.location,
            sampler = %c.plugin,
            requested,
            spp,
            "sampler drawn as independent samples (same image, different noise), count rounded up as Mitsuba does"
        );
    }
    Ok((spp, seed))
}

/// The sample count each Mitsuba sampler actually takes for `n` (`set_sample_count`).
fn rounded_sample_count(plugin: &str, n: u32) -> Option<u32> {
    let n = n as u64;
    let square_of = |mut r: u64, step: &dyn Fn(u64) -> u64, ok: &dyn Fn(u64) -> bool| {
        while r * r < n || !ok(r) {
            r = step(r);
        }
        r * r
    };
    let is_prime = |x: u64| (2..=x / 2).all(|i| !x.is_multiple_of(i));
    let count = match plugin {
        "stratified" => square_of(1, &|r| r + 1, &|_| true),
        "ldsampler" => square_of(2, &|r| (r + 1).next_power_of_two(), &|_| true),
        "orthogonal" => square_of(2, &|r| r + 1, &is_prime),
        "multijitter" => {
            let rows = ((n as f32).sqrt() as u64).max(1);
            n.div_ceil(rows) * rows
        }
        _ => n,
    };
    u32::try_from(count).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounded_sample_count_matches_mitsuba() {
        let cases: &[(&str, &[(u32, u32)])] = &[
            ("independent", &[(1, 1), (5, 5)]),
            ("stratified", &[(1, 1), (4, 4), (5, 9), (17, 25)]),
            ("ldsampler", &[(1, 4), (4, 4), (5, 16), (17, 64), (64, 64)]),
            ("orthogonal", &[(1, 4), (4, 4), (5, 9), (10, 25), (26, 49)]),
            ("multijitter", &[(1, 1), (5, 6), (10, 12), (16, 16)]),
        ];
        for (plugin, pairs) in cases {
            for &(n, expected) in *pairs {
                assert_eq!(rounded_sample_count(plugin, n), Some(expected), "{plugin} {n}");
            }
        }
    }
}
