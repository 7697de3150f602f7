//! The estimator on exact synthetic rays (no images): noiseless recovery, the fixed-seed
//! Monte Carlo of the paper's Table 2 protocol, and the consistency filter.

use geolocation::evaluation::{monte_carlo, ErrorStats};
use geolocation::synthetic::{BiasModel, NavNoise, SyntheticScenario};
use geolocation::{geolocate, geolocate_filtered, EstimatorConfig, NoiseModel};
use rand::rngs::StdRng;
use rand::SeedableRng;

fn noiseless(bias: BiasModel) -> SyntheticScenario {
    SyntheticScenario {
        noise: NavNoise::NONE,
        bias,
        ..SyntheticScenario::default()
    }
}

fn tight_config() -> EstimatorConfig {
    EstimatorConfig {
        bias_tolerance_deg: 1e-7,
        max_iterations: 200,
        noise_left: NoiseModel::isotropic(0.5, 0.5, 0.5),
        noise_right: NoiseModel::isotropic(0.5, 0.5, 0.5),
        ..EstimatorConfig::default()
    }
}

#[test]
fn noiseless_rays_recover_target_and_biases_exactly() {
    let scenario = noiseless(BiasModel::Constant {
        left_deg: 12.0,
        right_deg: -7.0,
    });
    let mut rng = StdRng::seed_from_u64(1);
    for n in [2usize, 3, 4] {
        for t in [3.0, 11.5, 27.25] {
            let trial = scenario.trial(t, n, &mut rng).unwrap();
            let est = geolocate(&trial.observations, &tight_config()).unwrap();
            let err = est.position - trial.target;
            assert!(err.norm() < 1e-3, "N={n} t={t}: position error {err}");
            for u in 0..2 {
                let e = (est.yaw_bias[u] - trial.yaw_bias[u]).to_degrees();
                assert!(e.abs() < 0.01, "N={n} t={t}: bias {u} error {e}°");
            }
            assert!(est.converged);
        }
    }
}

#[test]
fn default_tolerance_converges_close_on_noiseless_rays() {
    // With the paper's 0.1° stopping rule the estimate is already near the truth.
    let scenario = noiseless(BiasModel::Eq34 {
        delta0_deg: 20.0,
        rate_deg_s: 0.0,
    });
    let mut rng = StdRng::seed_from_u64(2);
    let trial = scenario.trial(5.0, 4, &mut rng).unwrap();
    let est = geolocate(&trial.observations, &EstimatorConfig::default()).unwrap();
    assert!(est.converged && est.iterations < 20);
    assert!((est.position - trial.target).norm() < 0.5);
}

fn print_stats(label: &str, s: &ErrorStats) {
    println!(
        "{label:>24}: MAE {:7.3}  STD {:7.3}  MAX {:7.3}  (n={})",
        s.mae, s.std, s.max, s.count
    );
}

#[test]
fn monte_carlo_table2_protocol_more_images_help_and_beat_one_shot() {
    let scenario = SyntheticScenario::default(); // σ_att 2°, σ_pos 3 m, δψ0 = 20°, eq. (34)
    let config = EstimatorConfig::default();
    // "4 images" and "8 images" are 2N in all: N = 2 and N = 4 per UAV.
    let r4 = monte_carlo(&scenario, 2, 300, 42, &config);
    let r8 = monte_carlo(&scenario, 4, 300, 42, &config);
    for r in [&r4, &r8] {
        let [x, y, z, h, d] = r.proposed.stats();
        let [ox, oy, oz, oh, od] = r.one_shot.stats();
        println!("N = {} failures {:?}", r.images_per_uav, r.failures);
        print_stats("x", &x);
        print_stats("y", &y);
        print_stats("z", &z);
        print_stats("horizontal", &h);
        print_stats("3d", &d);
        print_stats("bias L (deg)", &ErrorStats::from_errors(&r.bias_deg[0]));
        print_stats("bias R (deg)", &ErrorStats::from_errors(&r.bias_deg[1]));
        print_stats("one-shot x", &ox);
        print_stats("one-shot y", &oy);
        print_stats("one-shot z", &oz);
        print_stats("one-shot horizontal", &oh);
        print_stats("one-shot 3d", &od);
    }
    let mae = |e: &[f64]| ErrorStats::from_errors(e).mae;
    // More images → smaller bias and altitude errors (Tables 2 and 3's trend).
    for u in 0..2 {
        assert!(
            mae(&r8.bias_deg[u]) < 0.7 * mae(&r4.bias_deg[u]),
            "bias {u}"
        );
    }
    assert!(mae(&r8.proposed.z) < 0.8 * mae(&r4.proposed.z));
    assert!(mae(&r8.proposed.horizontal) < mae(&r4.proposed.horizontal));
    // With 8 images the proposed method beats one-shot on horizontal error. (With 4 it
    // is on a par with one-shot here: one past image per UAV is too little evidence to
    // separate ±20° biases from the target's position; see docs/estimator.md.)
    assert!(mae(&r8.proposed.horizontal) < 0.6 * mae(&r8.one_shot.horizontal));
    // Regression guard at 8 images, a margin above what was measured when written
    // (see docs/estimator.md); the paper's Table 2–3 figures are issue #6's target.
    assert!(mae(&r8.proposed.horizontal) < 7.0);
    assert!(mae(&r8.proposed.z) < 7.5);
    assert!(mae(&r8.bias_deg[0]) < 9.0 && mae(&r8.bias_deg[1]) < 9.0);
}

#[test]
fn consistency_filter_rejects_a_planted_wrong_correspondence() {
    let scenario = noiseless(BiasModel::Constant {
        left_deg: 12.0,
        right_deg: -7.0,
    });
    let mut rng = StdRng::seed_from_u64(3);
    let mut trial = scenario.trial(9.0, 4, &mut rng).unwrap();
    // Observations: [L1, R1, L past ×3, R past ×3]; past index 4 is the 2nd right past image.
    let planted = 4;
    trial.observations[2 + planted].pixel.x += 30.0;
    trial.observations[2 + planted].pixel.y -= 12.0;
    let config = tight_config();

    // Without the filter the wrong point drags the estimate off.
    let unfiltered = geolocate(&trial.observations, &config).unwrap();
    let unfiltered_err = (unfiltered.position - trial.target).norm();

    let (current, past) = trial.observations.split_at(2);
    let out = geolocate_filtered(&current[0], &current[1], past, &config).unwrap();
    let rejected: Vec<usize> = (0..past.len())
        .filter(|&n| out.past_rejections[n].is_some())
        .collect();
    assert_eq!(rejected, vec![planted], "{:?}", out.consistency);
    assert_eq!(out.estimate.images_used, 7);
    let err = (out.estimate.position - trial.target).norm();
    assert!(err < 1e-3, "filtered error {err} m");
    assert!(
        unfiltered_err > 100.0 * err.max(1e-4),
        "unfiltered error {unfiltered_err} m"
    );
}
