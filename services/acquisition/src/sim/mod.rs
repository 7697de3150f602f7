//! The urban-scene simulator: a procedural town rendered with exact perspective and
//! occlusion, a vehicle driving its roads, two nadir UAVs following it, and their
//! measured navigation states with Gaussian noise and yaw biases (eq. 34).
//!
//! [`Simulator`] is a live source: the acquisition service (and `dualgeo simulate`) step
//! it frame by frame and render straight into their own buffers.

pub mod city;
pub mod degrade;
pub mod faults;
pub mod gimbal;
pub mod lens;
pub mod motion;
pub mod record;
pub mod render;
pub mod scenario;
pub mod scenario_args;
pub mod simulator;
pub mod texture;

pub use record::{record, record_flight, RecordSummary};
pub use scenario::{Presets, SimConfig, TrafficCar};
pub use scenario_args::ScenarioArgs;
pub use simulator::{SimFrame, SimStep, Simulator, VehicleTruth};

use crate::recording::RecordingError;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("{0}")]
    Config(String),
    #[error("ground image {path}: {reason}")]
    GroundImage {
        path: std::path::PathBuf,
        reason: String,
    },
    #[error(transparent)]
    Recording(#[from] RecordingError),
    #[error("OpenCV: {0}")]
    OpenCv(String),
}
