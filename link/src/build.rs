//! This build's identity on the wire: what a worker registers with, and what the
//! coordinator requires of it (the same package version and renderer revision).

use tessera_proto::v1 as pb;

/// A registration carrying this build's version and renderer revision (fill in the rest).
pub fn registration() -> pb::RegisterRequest {
    pb::RegisterRequest {
        version: env!("CARGO_PKG_VERSION").into(),
        renderer_revision: tessera_common::RENDERER_REVISION.into(),
        ..Default::default()
    }
}

/// Why a worker of another build is refused, naming both builds; `None` for this build's.
pub fn mismatch(req: &pb::RegisterRequest) -> Option<String> {
    let mine = registration();
    if req.version == mine.version && req.renderer_revision == mine.renderer_revision {
        return None;
    }
    let theirs = format!("{} (renderer {})", or_unknown(&req.version), or_unknown(&req.renderer_revision));
    Some(format!(
        "the worker's build {theirs} is not the coordinator's {}: run the same build on both, \
         or farm renders would not equal local ones",
        tessera_common::build_id()
    ))
}

fn or_unknown(s: &str) -> &str {
    if s.is_empty() { "unknown" } else { s }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_this_build_is_accepted_and_a_refusal_names_both() {
        assert_eq!(mismatch(&registration()), None);
        let old = pb::RegisterRequest { version: "0.0.9".into(), ..Default::default() };
        let why = mismatch(&old).unwrap();
        assert!(why.contains("0.0.9 (renderer unknown)") && why.contains(&tessera_common::build_id()), "{why}");
        let other = pb::RegisterRequest { renderer_revision: "000000000000".into(), ..registration() };
        assert!(mismatch(&other).unwrap().contains("renderer 000000000000"));
    }
}
