//! What Tessera's coordinator, worker and clients share beyond the wire types of
//! `tessera-proto`: the conversions between `tessera.v1` messages and the renderer's settings and
//! rectangles ([`convert`]), so the two ends cannot disagree on a default; the layout of the tile
//! sums a worker uploads ([`payload`]); scene bundles as messages and blobs ([`bundle`]); and how
//! a client reaches a coordinator over `http://` or `https://` ([`connect`], which checks the
//! coordinator's certificate as [`pinned`] says).
//!
//! ```
//! use tessera_common::settings::RenderSettings;
//! let settings = RenderSettings { spp: Some(16), ..RenderSettings::default() };
//! let wire = tessera_link::convert::settings_to_pb(&settings);
//! assert_eq!(tessera_link::convert::settings_from_pb(&wire).unwrap(), settings);
//! ```

#![deny(missing_docs)]

pub mod build;
pub mod bundle;
pub mod connect;
pub mod convert;
pub mod frames;
pub mod mask;
pub mod payload;
pub mod pinned;
