//! Scene bundles on the wire and as blobs: a bundle travels as a `SceneBundle` message, and the
//! coordinator stores that message's encoding as a content-addressed blob that workers fetch by
//! its digest ([`tessera_proto::blob_digest`]).

use prost::Message;
use tessera_common::bundle::Bundle;
use tessera_proto::v1 as pb;

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

/// Writes the blob of a bundle whose files are not in memory: the same bytes as [`encode`] of
/// the bundle holding `files` (path and length, in order) with `scene_path`, the data of file
/// `i` read from `open(i)`, which must yield exactly the length given.
pub fn encode_to<R: std::io::Read>(
    scene_path: &str,
    files: &[(String, u64)],
    mut open: impl FnMut(usize) -> std::io::Result<R>,
    out: &mut impl std::io::Write,
) -> std::io::Result<()> {
    use prost::encoding::{WireType, encode_key, encode_varint, encoded_len_varint, key_len};
    // proto3 leaves empty strings and bytes out, as prost does
    let field_len = |len: u64| if len == 0 { 0 } else { key_len(1) as u64 + encoded_len_varint(len) as u64 + len };
    let mut head = Vec::with_capacity(64);
    if !scene_path.is_empty() {
        encode_key(1, WireType::LengthDelimited, &mut head);
        encode_varint(scene_path.len() as u64, &mut head);
        head.extend_from_slice(scene_path.as_bytes());
    }
    out.write_all(&head)?;
    for (i, (path, len)) in files.iter().enumerate() {
        head.clear();
        encode_key(2, WireType::LengthDelimited, &mut head);
        encode_varint(field_len(path.len() as u64) + field_len(*len), &mut head);
        if !path.is_empty() {
            encode_key(1, WireType::LengthDelimited, &mut head);
            encode_varint(path.len() as u64, &mut head);
            head.extend_from_slice(path.as_bytes());
        }
        if *len > 0 {
            encode_key(2, WireType::LengthDelimited, &mut head);
            encode_varint(*len, &mut head);
        }
        out.write_all(&head)?;
        let copied = std::io::copy(&mut open(i)?.take(*len), out)?;
        if copied != *len {
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!("bundle file {path} has {copied} bytes, not the {len} announced"),
            ));
        }
    }
    Ok(())
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

    #[test]
    fn streamed_encoding_equals_the_message_encoding() {
        let big = (0..300u32).map(|i| i as u8).collect::<Vec<_>>();
        for bundle in [
            Bundle {
                scene_path: "scene.xml".into(),
                files: vec![
                    ("meshes/a.obj".into(), big.clone()),
                    ("scene.xml".into(), b"<scene/>".to_vec()),
                    ("empty.txt".into(), vec![]),
                ],
            },
            Bundle { scene_path: String::new(), files: vec![] },
            Bundle { scene_path: "s".into(), files: vec![(String::new(), vec![7; 200_000])] },
        ] {
            let lens: Vec<_> = bundle.files.iter().map(|(p, d)| (p.clone(), d.len() as u64)).collect();
            let mut out = Vec::new();
            encode_to(&bundle.scene_path, &lens, |i| Ok(&bundle.files[i].1[..]), &mut out).unwrap();
            assert_eq!(out, encode(&bundle));
        }
        let short = [("a".to_string(), 5)];
        let err = encode_to("a", &short, |_| Ok(&b"abc"[..]), &mut Vec::new()).unwrap_err();
        assert!(err.to_string().contains("3 bytes, not the 5"), "{err}");
    }
}
