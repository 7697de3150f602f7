//! # acquisition
//!
//! Frame sources for the pipeline, behind one trait ([`source::FrameSource`]): the
//! urban-scene simulator ([`sim`]), recordings in format v1 ([`recording`],
//! `docs/recording-format.md`) and flights: videos with MAVLink telemetry ([`flight`],
//! `docs/flight-io.md`). The service binary (`main.rs`) streams whichever one it opens.

pub mod flight;
pub mod live_gate;
pub mod recording;
pub mod resume;
pub mod sim;
pub mod source;
