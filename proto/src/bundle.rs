//! Scene bundles on the wire and as blobs: a bundle travels as a `SceneBundle` message, and the
//! coordinator stores that message's encoding as a content-addressed blob that workers fetch by
//! its digest ([`crate::blob_digest`]).

use crate::v1 as pb;
use prost::Message;
use tessera_common::bundle::Bundle;

/// Bundle → wire message.
pub fn to_pb(bundle: &Bundle) -> pb::SceneBundle {
    pb::SceneBundle {
        scene_path: bundle.scene_path.clone(),
        files: bundle
            .files
            .iter()
            .map(|(path, data)| pb::BundleFile { path: path.clone(), data: data.clone().into() })
            .collect(),
    }
}

/// Wire message → bundle.
pub fn from_pb(message: pb::SceneBundle) -> Bundle {
    Bundle {
        scene_path: message.scene_path,
        files: message.files.into_iter().map(|f| (f.path, f.data.to_vec())).collect(),
    }
}

/// The blob of a bundle.
pub fn encode(bundle: &Bundle) -> Vec<u8> {
    to_pb(bundle).encode_to_vec()
}

/// A bundle blob's contents.
pub fn decode(bytes: &[u8]) -> Result<Bundle, prost::DecodeError> {
    pb::SceneBundle::decode(bytes).map(from_pb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bundles_round_trip_through_the_blob_encoding() {
        let bundle = Bundle {
            scene_path: "scene.xml".into(),
            files: vec![("scene.xml".into(), b"<scene/>".to_vec()), ("meshes/a.obj".into(), vec![0, 1, 2])],
        };
        assert_eq!(decode(&encode(&bundle)).unwrap(), bundle);
        assert!(decode(&[0xff, 0xff]).is_err());
    }
}
