//! # acquisition
//!
//! Frame sources for the pipeline: the recording format v1 reader and writer
//! ([`recording`], `docs/recording-format.md`) and the urban-scene simulator. The service
//! binary lands with issue #5.

pub mod live_gate;
pub mod recording;
pub mod resume;
pub mod sim;
