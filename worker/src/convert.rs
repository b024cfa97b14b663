//! Conversions from the coordinator's messages to renderer types (the shared rules are in
//! `tessera_link::convert`).

use tessera_common::film::Rect;
use tessera_common::settings::RenderSettings;
use tessera_proto::v1 as pb;

/// Wire settings → render settings; the error names the field.
pub fn settings(s: Option<&pb::RenderSettings>) -> Result<RenderSettings, String> {
    tessera_link::convert::settings_from_pb(s.ok_or("lease has no settings")?)
}

/// Wire rect → rect.
pub fn rect(r: Option<&pb::Rect>) -> Result<Rect, String> {
    tessera_link::convert::rect_from_pb(r)
}

pub use tessera_link::convert::rect_to_pb;
