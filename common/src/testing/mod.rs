//! Test utilities: a chi² goodness-of-fit test for direction samplers against their own pdfs,
//! and the statistics it needs. Compiled for tests and behind the `test-util` feature.

pub mod chi2;
