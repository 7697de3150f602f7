//! The scene suite's section of docs/evaluation.md: one table per protocol, a cell
//! that misses issue #12's target marked **miss**, and what the chain had to adapt.

use super::report::ordinal;
use super::suite::{median, SceneResult, PROTOCOLS, SUITE_WARM_UP_S};
use std::fmt::Write;

/// Issue #12's targets.
const LOCATED_MIN_PCT: f64 = 90.0;
const T1_XY_MAX_M: f64 = 0.15;
const T1_Z_MAX_M: f64 = 0.5;
const T2_H_MAX_M: f64 = 1.0;
const T2_Z_MAX_M: f64 = 1.5;
const T2_BIAS_MAX_DEG: f64 = 2.0;
const CALIBRATION_PCT: (f64, f64) = (60.0, 75.0);
const CPU_MAX_MS: f64 = 25.0;

fn mark(miss: bool) -> &'static str {
    if miss {
        " **miss**"
    } else {
        ""
    }
}

fn pct(k: usize, n: usize) -> f64 {
    if n == 0 {
        f64::NAN
    } else {
        100.0 * k as f64 / n as f64
    }
}

/// Markdown of the suite: `every` is the pair step, `seconds` the wall time.
pub fn section(results: &[SceneResult], every: u64, seconds: f64) -> String {
    let mut w = String::new();
    let _ = writeln!(
        w,
        "## Scene suite: accuracy on scenes unlike the tuning town (issue #12)\n"
    );
    let _ = writeln!(
        w,
        "Each suite preset (`dualgeo simulate --list`: the `suite_*` scenes, and `tilted` and `gimbal`, the town seen by cameras 30° forward and by tracking gimbals 45° off nadir) is rendered once and streamed through the whole chain (colour detector, spread ORB, guided matching, ground-plane F, transfer) with the default configuration, every {every}{} pair, under both protocols: Table 1 gives the chain the true poses; Table 2 the measured ones (σ_att 2°, σ_pos 3 m, eq. 34 biases with δψ0 = 20°), keyframes chosen by them as in flight. Errors count after a {SUITE_WARM_UP_S:.0} s warm-up. {:.0} s on this 2-core machine. Regenerate with `cargo run --release -p dualgeo -- evaluate` (or `-- evaluate --suite-only`).\n",
        ordinal(every),
        seconds
    );
    let _ = writeln!(w, "- **located**: pairs after the warm-up with the target in both images that the default estimator located (target ≥ {LOCATED_MIN_PCT:.0} %).");
    let _ = writeln!(w, "- **default** is the temporal filter, the default estimator; **paper** is `method = \"paper\"` on the same matched sets. MAE x / y / z in metres.");
    let _ = writeln!(w, "- Targets: Table 1 MAE x, y ≤ {T1_XY_MAX_M} m and z ≤ {T1_Z_MAX_M} m; Table 2 horizontal MAE ≤ {T2_H_MAX_M} m, z ≤ {T2_Z_MAX_M} m, each yaw-bias MAE ≤ {T2_BIAS_MAX_DEG}°; the default's 1σ holds ({}–{} % of errors within h_acc and v_acc); median CPU per geolocation ≤ {CPU_MAX_MS} ms. A **miss** marks a cell outside its target.", CALIBRATION_PCT.0, CALIBRATION_PCT.1);
    let _ = writeln!(w, "- **within h_acc / v_acc** in Table 2 is one run, and more than half of one run's vertical error after the warm-up is an offset it keeps for seconds (partly its yaw biases' errors): its share is set mostly by that offset, and every scene here flies the same seed, so the column is one draw, not a calibration. The calibration over seeds, by the estimate's age, is in [monte-carlo.md](monte-carlo.md) (docs/temporal.md, \"The one-run suite's vertical\").\n");
    for (p, title) in PROTOCOLS.iter().enumerate() {
        let _ = writeln!(w, "### {title}\n");
        let _ = writeln!(w, "| scene | located | default MAE x / y / z | paper MAE x / y / z | yaw-bias MAE L / R (°), default | within h_acc / v_acc | CPU ms p50 |");
        let _ = writeln!(w, "| --- | --- | --- | --- | --- | --- | --- |");
        for scene in results {
            let r = &scene.protocols[p];
            let located = pct(r.located, r.visible);
            let d = r.default.stats_xyz();
            let pa = r.paper.stats_xyz();
            let b = r.default.stats_bias();
            let horizontal = (d[0].mae.powi(2) + d[1].mae.powi(2)).sqrt();
            let accuracy_miss = if p == 0 {
                d[0].mae > T1_XY_MAX_M || d[1].mae > T1_XY_MAX_M || d[2].mae > T1_Z_MAX_M
            } else {
                horizontal > T2_H_MAX_M || d[2].mae > T2_Z_MAX_M
            };
            let bias_miss = p == 1 && (b[0].mae > T2_BIAS_MAX_DEG || b[1].mae > T2_BIAS_MAX_DEG);
            let [h1, _, v1, _] = r.calibration.shares();
            let within = |s: f64| s.is_nan() || s < CALIBRATION_PCT.0 || s > CALIBRATION_PCT.1;
            let cpu = median(&r.cpu_us) / 1000.0;
            let _ = writeln!(
                w,
                "| `{}` | {:.1} % ({}/{}){} | {:.3} / {:.3} / {:.3}{} | {:.3} / {:.3} / {:.3} | {:.2} / {:.2}{} | {:.0} / {:.0} %{} | {:.1}{} |",
                scene.name,
                located,
                r.located,
                r.visible,
                mark(located.is_nan() || located < LOCATED_MIN_PCT),
                d[0].mae,
                d[1].mae,
                d[2].mae,
                mark(d[0].count == 0 || accuracy_miss),
                pa[0].mae,
                pa[1].mae,
                pa[2].mae,
                b[0].mae,
                b[1].mae,
                mark(bias_miss),
                h1,
                v1,
                mark(within(h1) || within(v1)),
                cpu,
                mark(cpu.is_nan() || cpu > CPU_MAX_MS),
            );
        }
        let _ = writeln!(w);
    }
    let _ = writeln!(w, "What the chain adapted after the warm-up: past-image matchings retried with the looser ratio (and rescued), frames whose FAST threshold was lowered, keypoints outside the lens model, past images rejected by reason, and default estimates made while the target was outside an image:\n");
    let _ = writeln!(w, "| scene | protocol | retried (rescued) | FAST lowered | outside lens | rejected past images | estimates while not visible |");
    let _ = writeln!(w, "| --- | --- | --- | --- | --- | --- | --- |");
    for scene in results {
        for (p, r) in scene.protocols.iter().enumerate() {
            let c = r.counts;
            let rejected = if r.rejected.is_empty() {
                "none".to_string()
            } else {
                r.rejected
                    .iter()
                    .map(|(k, n)| format!("{k} {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let _ = writeln!(
                w,
                "| `{}` | Table {} | {} ({}) | {} | {} | {} | {} of {} |",
                scene.name,
                p + 1,
                c.retried_looser_ratio,
                c.retry_rescued,
                c.fast_threshold_lowered,
                c.keypoints_outside_lens,
                rejected,
                r.located_not_visible,
                r.not_visible
            );
        }
    }
    let _ = writeln!(w, "\nThe scenes:\n");
    for scene in results {
        let _ = writeln!(
            w,
            "- `{}`: {}",
            scene.name,
            scene.description.trim_start_matches("Suite: ")
        );
    }
    w
}
