//! The models [`Ekf`](super::Ekf) and [`EkfSlam`](super::EkfSlam) share: the velocity motion
//! model and its Jacobians G_t and V_t (seed 001 Algorithm 1 lines 3–6), the control and
//! measurement noise M_t and Q_t (lines 5 and 8), the range/bearing observation model and its
//! Jacobian (lines 16–18), the innovation and the maximum-likelihood score of data association
//! (lines 19–21), and the covariance helpers both filters use.

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};

use pheromone_messages::{sinc, sinc_derivative, wrap_angle, NoiseConfig};
use pheromone_messages::{LandmarkObs, PoseMsg};

/// Velocity motion model: the pose change, G_t and V_t (seed 001 Algorithm 1 lines 3, 4, 6).
///
/// Written with sin(θ+ωΔt) − sin θ = 2 cos(θ+a) sin a and cos θ − cos(θ+ωΔt) = 2 sin(θ+a) sin a,
/// a = ωΔt/2, so that −(v/ω) sin θ + (v/ω) sin(θ+ωΔt) = vΔt·sinc(a)·cos(θ+a): the same values
/// for ω ≠ 0, and the straight-line limit (vΔt cos θ, vΔt sin θ) at ω = 0.
pub(super) fn velocity_motion(
    theta: f64,
    v: f64,
    w: f64,
    dt: f64,
) -> (Vector3<f64>, Matrix3<f64>, Matrix3x2<f64>) {
    let a = 0.5 * w * dt;
    let (s, ds) = (sinc(a), sinc_derivative(a));
    let (c_mid, s_mid) = ((theta + a).cos(), (theta + a).sin());
    let dx = v * dt * s * c_mid;
    let dy = v * dt * s * s_mid;
    let delta = Vector3::new(dx, dy, w * dt); // line 6
    #[rustfmt::skip]
    let g = Matrix3::new( // line 3
        1.0, 0.0, -dy,
        0.0, 1.0, dx,
        0.0, 0.0, 1.0,
    );
    let half_vdt2 = 0.5 * v * dt * dt;
    #[rustfmt::skip]
    let vj = Matrix3x2::new( // line 4
        dt * s * c_mid, half_vdt2 * (ds * c_mid - s * s_mid),
        dt * s * s_mid, half_vdt2 * (ds * s_mid + s * c_mid),
        0.0, dt,
    );
    (delta, g, vj)
}

/// Control noise M_t (seed 001 Algorithm 1 line 5), times `inflation`.
pub(super) fn control_noise(noise: &NoiseConfig, v: f64, w: f64, inflation: f64) -> Matrix2<f64> {
    let (var_v, var_w) = noise.control_variances(v, w);
    Matrix2::new(inflation * var_v, 0.0, 0.0, inflation * var_w)
}

/// Measurement noise Q_t (seed 001 Algorithm 1 line 8, without the signature row).
pub(super) fn measurement_noise(noise: &NoiseConfig) -> Matrix2<f64> {
    Matrix2::new(
        noise.range_sigma_m.powi(2),
        0.0,
        0.0,
        noise.bearing_sigma_rad.powi(2),
    )
}

/// Predicted range/bearing of a landmark and the Jacobian w.r.t. the robot pose (seed 001
/// Algorithm 1 lines 16–18, line 18 with corrected signs). The Jacobian w.r.t. the landmark is
/// the negated first two columns. `None` when the landmark sits on the robot.
pub(super) fn predict_measurement(
    robot: &Vector3<f64>,
    lm_x: f64,
    lm_y: f64,
) -> Option<(Vector2<f64>, Matrix2x3<f64>)> {
    let dx = lm_x - robot.x;
    let dy = lm_y - robot.y;
    let q = dx * dx + dy * dy; // line 16
    if q < 1e-12 {
        return None;
    }
    let sq = q.sqrt();
    let z_hat = Vector2::new(sq, wrap_angle(dy.atan2(dx) - robot.z)); // line 17
    #[rustfmt::skip]
    let h = Matrix2x3::new( // line 18
        -dx / sq, -dy / sq, 0.0,
        dy / q, -dx / q, -1.0,
    );
    Some((z_hat, h))
}

pub(super) fn innovation(obs: &LandmarkObs, z_hat: &Vector2<f64>) -> Vector2<f64> {
    Vector2::new(
        f64::from(obs.range_m) - z_hat.x,
        wrap_angle(f64::from(obs.bearing_rad) - z_hat.y),
    )
}

/// Mahalanobis distance² and −2·log-likelihood (line 21) of an innovation.
pub(super) fn score(nu: &Vector2<f64>, s: &Matrix2<f64>) -> Option<(f64, f64)> {
    let det = s.determinant();
    if !(det.is_finite() && det > 0.0) {
        return None;
    }
    let s_inv = s.try_inverse()?;
    let d2 = (nu.transpose() * s_inv * nu)[(0, 0)];
    let neg2_log_l = d2 + (std::f64::consts::TAU.powi(2) * det).ln();
    Some((d2, neg2_log_l))
}

pub(super) fn signatures_match(observed: u32, landmark: u32) -> bool {
    observed == 0 || landmark == 0 || observed == landmark
}

/// Whether a 3×3 covariance is finite, symmetric and positive semi-definite.
pub(super) fn valid_covariance3(cov: &Matrix3<f64>) -> bool {
    if !cov.iter().all(|v| v.is_finite()) {
        return false;
    }
    let scale = cov.abs().max().max(1e-300);
    if (cov - cov.transpose()).abs().max() > 1e-9 * scale {
        return false;
    }
    cov.symmetric_eigenvalues().min() >= -1e-12 * scale
}

pub(super) fn symmetrize3(cov: &Matrix3<f64>) -> Matrix3<f64> {
    (cov + cov.transpose()) * 0.5
}

pub(super) fn pose_msg(
    mean: &Vector3<f64>,
    cov: &Matrix3<f64>,
    robot_id: u32,
    step: u64,
    used: u32,
) -> PoseMsg {
    let mut flat = [0.0; 9];
    for r in 0..3 {
        for c in 0..3 {
            flat[r * 3 + c] = cov[(r, c)];
        }
    }
    PoseMsg {
        stamp_ns: 0,
        step,
        robot_id,
        landmarks_used: used,
        x_m: mean.x,
        y_m: mean.y,
        theta_rad: mean.z,
        cov: flat,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn prediction_matches_algorithm_1() {
        // seed 001 Algorithm 1 lines 3, 4, 6 literally, for ω ≠ 0.
        let (th, v, w, dt): (f64, f64, f64, f64) = (0.4, 0.9, 0.7, 0.1);
        let r = v / w;
        let th2 = th + w * dt;
        let lit_delta = Vector3::new(
            -r * th.sin() + r * th2.sin(),
            r * th.cos() - r * th2.cos(),
            w * dt,
        );
        #[rustfmt::skip]
        let lit_g = Matrix3::new(
            1.0, 0.0, -r * th.cos() + r * th2.cos(),
            0.0, 1.0, -r * th.sin() + r * th2.sin(),
            0.0, 0.0, 1.0,
        );
        #[rustfmt::skip]
        let lit_v = Matrix3x2::new(
            (-th.sin() + th2.sin()) / w,
            v * (th.sin() - th2.sin()) / (w * w) + v * th2.cos() * dt / w,
            (th.cos() - th2.cos()) / w,
            -v * (th.cos() - th2.cos()) / (w * w) + v * th2.sin() * dt / w,
            0.0, dt,
        );
        let (delta, g, vj) = velocity_motion(th, v, w, dt);
        assert_relative_eq!(delta, lit_delta, epsilon = 1e-12);
        assert_relative_eq!(g, lit_g, epsilon = 1e-12);
        assert_relative_eq!(vj, lit_v, epsilon = 1e-10);

        // ω = 0: straight line, and the Jacobians equal finite differences of the motion.
        let (delta, g, vj) = velocity_motion(th, v, 0.0, dt);
        assert_relative_eq!(
            delta,
            Vector3::new(v * dt * th.cos(), v * dt * th.sin(), 0.0),
            epsilon = 1e-15
        );
        let h = 1e-6;
        let d_theta = (velocity_motion(th + h, v, 0.0, dt).0
            - velocity_motion(th - h, v, 0.0, dt).0)
            / (2.0 * h);
        let d_v = (velocity_motion(th, v + h, 0.0, dt).0 - velocity_motion(th, v - h, 0.0, dt).0)
            / (2.0 * h);
        let d_w = (velocity_motion(th, v, h, dt).0 - velocity_motion(th, v, -h, dt).0) / (2.0 * h);
        assert_relative_eq!(
            g.column(2).into_owned(),
            d_theta + Vector3::z(),
            epsilon = 1e-8
        );
        assert_relative_eq!(vj.column(0).into_owned(), d_v, epsilon = 1e-8);
        assert_relative_eq!(vj.column(1).into_owned(), d_w, epsilon = 1e-8);
    }

    #[test]
    fn measurement_jacobian_matches_finite_differences() {
        // Checks the corrected signs of seed 001 Algorithm 1 line 18.
        let robot = Vector3::new(1.0, -2.0, 0.7);
        let (lx, ly) = (4.0, 1.5);
        let (_, h) = predict_measurement(&robot, lx, ly).unwrap();
        let eps = 1e-6;
        for k in 0..3 {
            let mut plus = robot;
            let mut minus = robot;
            plus[k] += eps;
            minus[k] -= eps;
            let zp = predict_measurement(&plus, lx, ly).unwrap().0;
            let zm = predict_measurement(&minus, lx, ly).unwrap().0;
            let numeric = Vector2::new(
                (zp.x - zm.x) / (2.0 * eps),
                wrap_angle(zp.y - zm.y) / (2.0 * eps),
            );
            assert_relative_eq!(h.column(k).into_owned(), numeric, epsilon = 1e-7);
        }
    }
}
