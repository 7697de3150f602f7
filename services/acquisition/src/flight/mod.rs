//! Flight data (issue #14): per UAV a video (file or stream, decoded through OpenCV's
//! FFmpeg back end) and MAVLink telemetry (a `.tlog`, or live over UDP), described by a
//! `flight.toml` ([`meta`]); read by [`FlightSource`] (recorded) or
//! [`LiveFlightSource`] (live: [`live_video`], [`live_telemetry`], [`clock_offset`]),
//! and written by the simulator's `--flight-out` ([`writer`]). docs/flight-io.md has
//! the format and the time alignment.

pub mod clock_offset;
pub mod live_source;
pub mod live_telemetry;
pub mod live_video;
pub mod meta;
pub mod nav_track;
pub mod source;
pub mod tlog;
pub mod video;
pub mod writer;
pub mod x264;

pub use live_source::LiveFlightSource;

/// The increments of counters since they were last reported (`reported` is updated):
/// the `(name, increment)` pairs a source's `take_counts` returns, zeros left out.
pub(crate) fn increments<const N: usize>(
    names: [&'static str; N],
    now: [u64; N],
    reported: &mut [u64; N],
) -> Vec<(&'static str, u64)> {
    let out = names
        .iter()
        .zip(now.iter().zip(reported.iter()))
        .filter(|(_, (n, r))| n > r)
        .map(|(name, (n, r))| (*name, n - r))
        .collect();
    *reported = now;
    out
}
pub use meta::FlightMeta;
pub use source::FlightSource;
