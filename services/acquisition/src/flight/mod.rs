//! Flight data (issue #14): per UAV a video (file or stream, decoded through OpenCV's
//! FFmpeg back end) and MAVLink telemetry (a `.tlog`), described by a `flight.toml`
//! ([`meta`]); read by [`FlightSource`] and written by the simulator's `--flight-out`
//! ([`writer`]). docs/flight-io.md has the format and the time alignment.

pub mod meta;
pub mod nav_track;
pub mod source;
pub mod tlog;
pub mod video;
pub mod writer;

pub use meta::FlightMeta;
pub use source::FlightSource;
