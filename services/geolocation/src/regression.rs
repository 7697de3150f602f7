//! Section 2.1: weighted least squares for ξ = (x_P, y_P, δψ_L, δψ_R) (eq. 3–4) from
//! every image's eq.-(1) fix, linearised in its own UAV's yaw bias (eq. 12–13), weighted
//! by the covariance of eq. (15).
//!
//! Each image k contributes two rows:
//! `F_k(γ) = ξ1 + (∂F_k/∂ψ) δψ_uav(k) + W_k`, `W_k ~ N(0, Q_k)` with
//! `Q_k = (∂F_k/∂τ1) Q1 (∂F_k/∂τ1)ᵀ + (∂F_k/∂ψ) σψ² (∂F_k/∂ψ)ᵀ` (the image's block of
//! eq. 15; τ1 is replaced by τ2 and Q1 by Q2 for the right UAV).
//!
//! **Relinearisation (a choice the paper leaves open).** The paper linearises at the
//! raw measurements (eq. 12). Inside the altitude/regression iteration this module is
//! called with the current bias estimate δψ⁽ⁿ⁾: F and its Jacobians are evaluated at the
//! corrected yaw ψ − δψ⁽ⁿ⁾ and the unknowns are the *updates* Δ = δψ − δψ⁽ⁿ⁾, so the
//! linearisation error shrinks as the iteration proceeds. With δψ⁽⁰⁾ = 0 the first
//! round is exactly eq. (12)–(13).
//!
//! The solve whitens each image's two rows by the Cholesky factor of Q_k and solves the
//! 4×4 normal equations by Cholesky: no explicit inverse is formed to solve. The
//! covariance (AᵀQ⁻¹A)⁻¹ is computed from the same factor for reporting.

use crate::ground_model::{prepared_ground_fix, PreparedRay};
use crate::{EstimatorConfig, EstimatorError, Observation};
use nalgebra::{Matrix2, Matrix2x4, Matrix4, Vector2, Vector4};

/// Variance floor added to Q_k's diagonal, m². Keeps the weights finite when a user sets
/// every σ to zero (noise-free replay); 1 mm is far below any real geolocation error.
const Q_FLOOR_M2: f64 = 1e-6;

/// Smallest acceptable reciprocal condition estimate of the normal matrix
/// (ratio of the smallest to largest squared Cholesky pivot).
const MIN_RCOND: f64 = 1e-13;

/// Result of one weighted least-squares solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegressionSolution {
    /// (x_P, y_P), world ENU metres.
    pub xy: Vector2<f64>,
    /// Bias update Δ = (Δψ_L, Δψ_R), radians, relative to the linearisation point.
    pub bias_update: [f64; 2],
    /// Covariance of (x_P, y_P, δψ_L, δψ_R) in m² and rad²: (Aᵀ Q⁻¹ A)⁻¹.
    pub covariance: Matrix4<f64>,
    /// Weighted sum of squared residuals (χ²), for diagnostics.
    pub chi2: f64,
}

/// Eq. (12)–(15): solve the weighted least squares at target altitude `z_target` with the
/// yaws corrected by `yaw_bias` (radians, index by `Uav::index`).
pub fn solve_regression(
    observations: &[Observation],
    rays: &[PreparedRay],
    z_target: f64,
    yaw_bias: [f64; 2],
    config: &EstimatorConfig,
) -> Result<RegressionSolution, EstimatorError> {
    solve_regression_with_prior(observations, rays, z_target, yaw_bias, None, config)
}

/// Prior knowledge of the bias update Δ = δψ − δψ⁽ⁿ⁾: Δ ~ N(`mean`, `information`⁻¹).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BiasPrior {
    /// rad⁻².
    pub information: Matrix2<f64>,
    /// rad.
    pub mean: Vector2<f64>,
}

/// [`solve_regression`] with prior knowledge of the biases (several targets: the
/// biases the target's filter estimated): the prior's rows `Δ = mean`, weighted by its
/// information, join eq. (13)'s, so the bias update stays near the prior and the
/// covariance of (x_P, y_P) carries the biases' uncertainty.
pub fn solve_regression_with_prior(
    observations: &[Observation],
    rays: &[PreparedRay],
    z_target: f64,
    yaw_bias: [f64; 2],
    prior: Option<BiasPrior>,
    config: &EstimatorConfig,
) -> Result<RegressionSolution, EstimatorError> {
    let mut normal = Matrix4::<f64>::zeros();
    let mut rhs = Vector4::<f64>::zeros();
    let mut bb = 0.0;
    if let Some(p) = prior {
        normal
            .fixed_view_mut::<2, 2>(2, 2)
            .copy_from(&p.information);
        let pulled = p.information * p.mean;
        rhs[2] = pulled.x;
        rhs[3] = pulled.y;
        bb = p.mean.dot(&pulled);
    }

    for (k, (obs, ray)) in observations.iter().zip(rays).enumerate() {
        let uav = obs.uav.index();
        let yaw = obs.corrected_yaw(yaw_bias);
        let fix = prepared_ground_fix(k, obs, ray, yaw, z_target)?;
        let noise = config.noise(obs.uav);

        // Eq. (15), this image's 2×2 block. Q1 is diagonal, so
        // (∂F/∂τ1) Q1 (∂F/∂τ1)ᵀ = Σ_j σ_j² c_j c_jᵀ over the columns c_j.
        let mut q = fix.d_yaw * noise.yaw_variance() * fix.d_yaw.transpose()
            + Matrix2::identity() * Q_FLOOR_M2;
        for (j, var) in noise.tau1_variances().iter().enumerate() {
            let c = fix.d_nav.column(j);
            q += c * c.transpose() * *var;
        }
        let chol = q
            .cholesky()
            .ok_or(EstimatorError::SingularNormalMatrix { rcond: 0.0 })?;

        // Eq. (13), this image's rows: [I₂ | ∂F/∂ψ in its own UAV's column].
        let mut a = Matrix2x4::zeros();
        a.fixed_view_mut::<2, 2>(0, 0).fill_with_identity();
        a.set_column(2 + uav, &fix.d_yaw);

        // Whiten: L⁻¹A and L⁻¹b by forward substitution.
        let l = chol.l();
        let aw = l
            .solve_lower_triangular(&a)
            .ok_or(EstimatorError::SingularNormalMatrix { rcond: 0.0 })?;
        let bw = l
            .solve_lower_triangular(&fix.xy)
            .ok_or(EstimatorError::SingularNormalMatrix { rcond: 0.0 })?;
        normal += aw.transpose() * aw;
        rhs += aw.transpose() * bw;
        bb += bw.norm_squared();
    }

    let chol = normal
        .cholesky()
        .ok_or(EstimatorError::SingularNormalMatrix { rcond: 0.0 })?;
    let pivots = chol.l_dirty().diagonal().map(|p| p * p);
    let rcond = pivots.min() / pivots.max();
    if rcond.is_nan() || rcond <= MIN_RCOND {
        return Err(EstimatorError::SingularNormalMatrix { rcond });
    }
    let xi = chol.solve(&rhs);
    let covariance = chol.inverse();
    // χ² = |b̃ − Ãξ|² = b̃ᵀb̃ − ξᵀÃᵀb̃ because (ÃᵀÃ) ξ = Ãᵀb̃.
    let chi2 = (bb - xi.dot(&rhs)).max(0.0);

    if !xi.iter().all(|v| v.is_finite()) || !covariance.iter().all(|v| v.is_finite()) {
        return Err(EstimatorError::NonFiniteResult {
            what: "regression solution",
        });
    }
    Ok(RegressionSolution {
        xy: Vector2::new(xi[0], xi[1]),
        bias_update: [xi[2], xi[3]],
        covariance,
        chi2,
    })
}
