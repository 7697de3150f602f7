//! OpenCV's robust fits as matching runs them: USAC's settings from the configuration,
//! and the seed of OpenCV's thread RNG before a fit. Below the two-view geometry
//! (`epipolar.rs`, `ground_plane.rs`) and frame tracking, which all fit with them.

use crate::config::{MatchingConfig, UsacLocalOptimisation, UsacScore};

/// Seeds OpenCV's thread-local RNG (`cv::theRNG`) from what is being computed, before
/// a robust fit (issue #23: replays repeat exactly). USAC draws its samples from
/// `random_generator_state` (fixed), but its local optimisation and the classic
/// RANSAC paths may draw from the calling thread's RNG, whose state depends on which
/// pool thread ran which job before.
pub fn seed_cv_rng(parts: &[u64]) -> opencv::Result<()> {
    let mut h: u64 = 0x9e37_79b9_7f4a_7c15;
    for p in parts {
        h = (h ^ p).wrapping_mul(0x0100_0000_01b3).rotate_left(29);
    }
    opencv::core::set_rng_seed((h >> 33) as i32)
}

/// OpenCV's USAC settings from the config. The explicit `UsacParams` overloads are
/// used because the `method` overloads ignore `maxIters` on the USAC path (measured,
/// docs/matching.md). The generator is seeded, so a run is repeatable.
pub(crate) fn usac_params(
    config: &MatchingConfig,
    threshold: f64,
) -> opencv::Result<opencv::calib3d::UsacParams> {
    use opencv::calib3d::{LocalOptimMethod, ScoreMethod};
    let mut p = opencv::calib3d::UsacParams::default()?;
    p.confidence = config.ransac_confidence;
    p.threshold = threshold;
    p.max_iterations = config.ransac_max_iterations;
    p.lo_iterations = config.usac_lo_iterations;
    p.is_parallel = false;
    p.random_generator_state = 0;
    p.score = match config.usac_score {
        UsacScore::Magsac => ScoreMethod::SCORE_METHOD_MAGSAC,
        UsacScore::Msac => ScoreMethod::SCORE_METHOD_MSAC,
    };
    p.lo_method = match config.usac_local_optimisation {
        UsacLocalOptimisation::None => LocalOptimMethod::LOCAL_OPTIM_NULL,
        UsacLocalOptimisation::Inner => LocalOptimMethod::LOCAL_OPTIM_INNER_LO,
        UsacLocalOptimisation::InnerAndIterative => LocalOptimMethod::LOCAL_OPTIM_INNER_AND_ITER_LO,
        UsacLocalOptimisation::GraphCut => LocalOptimMethod::LOCAL_OPTIM_GC,
        UsacLocalOptimisation::Sigma => LocalOptimMethod::LOCAL_OPTIM_SIGMA,
    };
    Ok(p)
}
