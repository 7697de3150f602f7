//! # geolocation — the paper's estimator
//!
//! Pure functions over plain data (no IPC, no OpenCV) implementing Pan et al. 2023,
//! "Vision-Based Moving-Target Geolocation Using Dual UAVs":
//!
//! | paper | here |
//! | --- | --- |
//! | eq. (1), F of eq. (7) and ∂F/∂τ of eq. (12) | [`ground_model`] |
//! | Section 2.1, eq. (12)–(15): weighted least squares for ξ | [`regression`] |
//! | Section 2.2, eq. (16)–(23): target altitude | [`altitude`] |
//! | the altitude/regression iteration | [`iteration`] ([`geolocate`]) |
//! | Section 2.3, eq. (29)–(32): consistency filter | [`consistency`] |
//! | Section 3.1: the one-shot baseline | [`one_shot`] |
//! | several targets with the shared yaw biases (beyond the paper) | [`shared_bias`], [`tracks`] |
//! | Q1–Q3's σ's (eq. 8–10) raised to what the pose samples show (beyond the paper) | [`telemetry_noise`] |
//! | Section 3.1's scenario and eq. (33)–(34) | [`synthetic`], [`evaluation`] |
//!
//! Units: metres, pixels, radians inside; degrees only in [`EstimatorConfig`] and in
//! reports. Frames: see `shared_types::conventions`.

pub mod altitude;
pub mod config;
pub mod configured;
pub mod consistency;
pub mod error;
pub mod evaluation;
pub mod geolocator;
pub mod ground_model;
pub mod hypotheses;
pub mod iteration;
pub mod joint;
pub mod observation;
pub mod one_shot;
pub mod others_message;
pub mod regression;
pub mod set_message;
pub mod shared_bias;
pub mod start_agreement;
pub mod start_prior;
pub mod synthetic;
pub mod target_identity;
pub mod telemetry_noise;
pub mod temporal;
pub mod temporal_snapshot;
pub mod tracks;

pub use config::{EstimatorConfig, EstimatorMethod, NoiseModel};
pub use configured::{coast_set, estimate_set, SetEstimate};
pub use consistency::{
    consistency_filter, geolocate_configured, geolocate_filtered, geolocate_filtered_paper,
    ConsistencyOutcome, FilteredEstimate,
};
pub use error::EstimatorError;
pub use iteration::{geolocate, geolocate_paper, Estimate};
pub use observation::{ImageId, Observation, PastImage};
pub use one_shot::one_shot;
pub use temporal::{Quality, TemporalEstimate, TemporalEstimator};
pub use temporal_snapshot::TemporalSnapshot;
