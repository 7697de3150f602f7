//! # shared-types
//!
//! What every dualgeo process agrees on: the frame conventions (one function builds
//! C_w^c), the shared-memory message layouts and the service names.

pub mod alloc_count;
pub mod assignment;
pub mod checkpoint;
pub mod clock;
pub mod conventions;
pub mod deadline;
pub mod lens;
pub mod messages;
pub mod nav_noise;
pub mod realtime;
pub mod service_names;
pub mod shell;
pub mod stats;
pub mod trace;
pub mod transport;
