//! Conversions from the coordinator's messages to renderer types.

use tessera_common::film::Rect;
use tessera_common::settings::RenderSettings;
use tessera_proto::v1 as pb;

/// Wire settings → render settings; the error names the field.
pub fn settings(s: Option<&pb::RenderSettings>) -> Result<RenderSettings, String> {
    let s = s.ok_or("lease has no settings")?;
    let d = RenderSettings::default();
    Ok(RenderSettings {
        integrator: s.integrator.parse().map_err(|e: tessera_common::settings::SettingsError| e.to_string())?,
        spp: s.spp,
        time_s: s.time_s,
        seed: s.seed,
        max_depth: s.max_depth,
        light_paths_per_pixel: s.light_paths_per_pixel.unwrap_or(d.light_paths_per_pixel),
        connections: s.connections.unwrap_or(d.connections),
        merge: s.merge.unwrap_or(d.merge),
        correlation_aware: s.correlation_aware.unwrap_or(d.correlation_aware),
        defines: s.defines.clone().into_iter().collect(),
    })
}

/// Wire rect → rect.
pub fn rect(r: Option<&pb::Rect>) -> Result<Rect, String> {
    let r = r.ok_or("lease has no rect")?;
    Ok(Rect { x0: r.x0, y0: r.y0, x1: r.x1, y1: r.y1 })
}

/// Rect → wire rect.
pub fn rect_to_pb(r: Rect) -> pb::Rect {
    pb::Rect { x0: r.x0, y0: r.y0, x1: r.x1, y1: r.y1 }
}
