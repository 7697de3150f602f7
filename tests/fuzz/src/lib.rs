//! Fuzz targets over every input dualgeo parses (issue #13): the recording reader, the
//! image headers, the configuration, the checkpoints, and every shared-memory message a
//! service reads. Each target is a plain function of bytes, so the same code runs under
//! `cargo afl fuzz` (`src/bin/<target>.rs`) and over the committed corpus in
//! `replay` (scripts/fuzz.sh). A target must never panic, hang or allocate without
//! bound, whatever the bytes; what it may do is return an error.
//!
//! Messages are read the way a service sees them: arbitrary bytes in the `#[repr(C)]`
//! layout of the message ([`message`]), so NaN, infinities, huge counts and unknown
//! enumeration codes all arrive.

pub mod bytes;
pub mod targets;

pub use bytes::{message, message_bytes, segments, Cursor, SEPARATOR};

/// The targets by name, for `replay` and the seed writer.
pub const TARGETS: [(&str, fn(&[u8])); 7] = [
    ("recording", targets::recording),
    ("image", targets::image),
    ("config", targets::config),
    ("checkpoint", targets::checkpoint),
    ("frames", targets::frames),
    ("observations", targets::observations),
    ("flight", targets::flight),
];
