//! Conversions between the wire messages and the renderer's types that both ends use (settings
//! and rectangles), so the coordinator and the worker cannot disagree on defaults. Errors name
//! the field at fault.

use tessera_common::emis::PilotStart;
use tessera_common::emis::cost::CostModel;
use tessera_common::emis::denoise::ImageEstimate;
use tessera_common::emis::optimize::{ConnectionScope, OutlierStage};
use tessera_common::film::Rect;
use tessera_common::settings::RenderSettings;
use tessera_proto::v1 as pb;

fn parse_json_name<T: serde::de::DeserializeOwned>(field: &str, value: &str) -> Result<T, String> {
    serde_json::from_value(serde_json::Value::String(value.to_string()))
        .map_err(|_| format!("settings field \"{field}\": unknown value \"{value}\""))
}

fn json_name<T: serde::Serialize>(value: &T) -> String {
    match serde_json::to_value(value) {
        Ok(serde_json::Value::String(s)) => s,
        _ => unreachable!("invariant: unit enum variants serialise as strings"),
    }
}

/// Wire settings → render settings: unset fields take the renderer's defaults; the error
/// names the field.
pub fn settings_from_pb(s: &pb::RenderSettings) -> Result<RenderSettings, String> {
    let d = RenderSettings::default();
    // the fields with retired settings or values, checked as the JSON settings are
    let mut retired = serde_json::Map::new();
    let fields = [
        ("merge_ratio", &s.merge_ratio),
        ("merge_kernel", &s.merge_kernel),
        ("cost_model", &s.cost_model),
        ("moment_filter", &s.moment_filter),
    ];
    for (field, value) in fields {
        if let Some(v) = value {
            retired.insert(field.into(), v.clone().into());
        }
    }
    tessera_common::settings::strip_retired(&mut retired).map_err(|e| e.to_string())?;
    let integrator = if s.integrator.is_empty() {
        d.integrator
    } else {
        s.integrator.parse().map_err(|e: tessera_common::settings::SettingsError| e.to_string())?
    };
    Ok(RenderSettings {
        integrator,
        spp: s.spp,
        time_s: s.time_s,
        seed: s.seed,
        max_depth: s.max_depth,
        light_paths_per_pixel: s.light_paths_per_pixel.unwrap_or(d.light_paths_per_pixel),
        connections: s.connections.unwrap_or(d.connections),
        merge: s.merge.unwrap_or(d.merge),
        correlation_aware: s.correlation_aware.unwrap_or(d.correlation_aware),
        defines: s.defines.clone().into_iter().collect(),
        emis_updates: s.emis_updates.as_ref().map_or(d.emis_updates, |u| u.iterations.clone()),
        cost_model: match &s.cost_model {
            Some(v) => parse_json_name::<CostModel>("cost_model", v)?,
            None => d.cost_model,
        },
        moment_outliers: match &s.moment_outliers {
            Some(v) => parse_json_name::<OutlierStage>("moment_outliers", v)?,
            None => d.moment_outliers,
        },
        emis_pilot: match &s.emis_pilot {
            Some(v) => parse_json_name::<PilotStart>("emis_pilot", v)?,
            None => d.emis_pilot,
        },
        emis_connections: match &s.emis_connections {
            Some(v) => parse_json_name::<ConnectionScope>("emis_connections", v)?,
            None => d.emis_connections,
        },
        emis_image: match &s.emis_image {
            Some(v) => parse_json_name::<ImageEstimate>("emis_image", v)?,
            None => d.emis_image,
        },
    })
}

/// Render settings → wire settings (every field set).
pub fn settings_to_pb(s: &RenderSettings) -> pb::RenderSettings {
    pb::RenderSettings {
        integrator: s.integrator.to_string(),
        spp: s.spp,
        time_s: s.time_s,
        seed: s.seed,
        max_depth: s.max_depth,
        light_paths_per_pixel: Some(s.light_paths_per_pixel),
        connections: Some(s.connections),
        merge: Some(s.merge),
        correlation_aware: Some(s.correlation_aware),
        defines: s.defines.clone().into_iter().collect(),
        emis_updates: Some(pb::EmisUpdates { iterations: s.emis_updates.clone() }),
        merge_ratio: None,
        merge_kernel: None,
        cost_model: Some(json_name(&s.cost_model)),
        moment_filter: None,
        moment_outliers: Some(json_name(&s.moment_outliers)),
        emis_pilot: Some(json_name(&s.emis_pilot)),
        emis_connections: Some(json_name(&s.emis_connections)),
        emis_image: Some(json_name(&s.emis_image)),
    }
}

/// Wire rect → rect; refuses an empty one.
pub fn rect_from_pb(r: Option<&pb::Rect>) -> Result<Rect, String> {
    let r = r.ok_or("field \"rect\" is missing")?;
    if r.x0 >= r.x1 || r.y0 >= r.y1 {
        return Err(format!("field \"rect\" is empty: {r:?}"));
    }
    Ok(Rect { x0: r.x0, y0: r.y0, x1: r.x1, y1: r.y1 })
}

/// Rect → wire rect.
pub fn rect_to_pb(r: Rect) -> pb::Rect {
    pb::Rect { x0: r.x0, y0: r.y0, x1: r.x1, y1: r.y1 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tessera_common::settings::IntegratorName;

    #[test]
    fn settings_round_trip_and_name_bad_fields() {
        let s = RenderSettings {
            integrator: IntegratorName::EmisVcm,
            spp: Some(9),
            emis_updates: vec![2, 5],
            cost_model: CostModel::Measured,
            emis_pilot: PilotStart::Bidirectional,
            emis_connections: ConnectionScope::PerPixel,
            emis_image: ImageEstimate::Guided,
            ..RenderSettings::default()
        };
        assert_eq!(settings_from_pb(&settings_to_pb(&s)).unwrap(), s);
        assert_eq!(settings_from_pb(&pb::RenderSettings::default()).unwrap(), RenderSettings::default());
        let bad = pb::RenderSettings { moment_outliers: Some("cubic".into()), ..Default::default() };
        assert!(settings_from_pb(&bad).unwrap_err().contains("moment_outliers"));
        // retired settings: what older clients send is accepted, a retired variant refused
        let old = pb::RenderSettings { merge_kernel: Some("squared".into()), ..Default::default() };
        assert_eq!(settings_from_pb(&old).unwrap(), RenderSettings::default());
        let retired = pb::RenderSettings { merge_ratio: Some("reference".into()), ..Default::default() };
        assert!(settings_from_pb(&retired).unwrap_err().contains("merge_ratio"));
        let retired = pb::RenderSettings { cost_model: Some("reference".into()), ..Default::default() };
        assert!(settings_from_pb(&retired).unwrap_err().contains("cost_model"));
        let retired = pb::RenderSettings { moment_filter: Some("absolute".into()), ..Default::default() };
        assert!(settings_from_pb(&retired).unwrap_err().contains("moment_filter"));
        let retired = pb::RenderSettings { moment_outliers: Some("filtered".into()), ..Default::default() };
        assert!(settings_from_pb(&retired).unwrap_err().contains("moment_outliers"));
    }
}
