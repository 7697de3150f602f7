//! # matching
//!
//! Paper Section 2.3: using *past* images to locate the target's *current* position.
//! Each UAV keeps a ring of keyframes admitted by the baseline constraint T_re, with ORB
//! features cached at admission ([`ring`]). For each past image, F_Ln and F_Rn are
//! estimated from ORB matches, and the current target pixel's epipolar lines meet at
//! its corresponding point ([`epipolar`], eq. 24–28). Each camera's ground points are
//! tracked frame to frame ([`frame_tracking`]), and every pair is answered from them;
//! ORB, matching with past images and admissions run as *refreshes* on a thread of
//! their own and land at a frame boundary (`chain/refresh.rs`, issue #24). [`chain`]
//! runs everything, through the consistency filter and the estimator.

pub mod chain;
pub mod config;
pub mod epipolar;
pub mod features;
pub mod frame;
pub mod frame_tracking;
pub mod grid;
pub mod ground_plane;
pub mod hamming;
pub mod intake;
pub mod rectify;
pub mod ring;
pub mod ring_snapshot;
pub mod ring_store;
pub mod robust_fit;
pub mod set_message;

pub use chain::{
    estimate_matched, extract_undistorted, ChainCounts, ChainOutcome, ChainResult, ChainTiming,
    FrameInput, FrameMeta, Located, MatchOutcome, MatchedSet, PastMatch, UnseenSet, VisionChain,
};
pub use config::{FundamentalMethod, MatchingConfig, OrbScore, UsacLocalOptimisation, UsacScore};
pub use frame_tracking::{FrameTracker, Motion, Observed, TrackReport};
