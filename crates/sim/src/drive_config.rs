//! The federated monitor config of the shared car drive (`tests/data/drive/`): its
//! mounting, lever arm and IMU noise, and the 1 Hz single-point GNSS aid the drive
//! experiment derives from its RTK solution. Outside `experiment` because the load
//! generator streams raw-IMU sessions on the same config.

use serde_json::{Value, json};

/// The aid's noise and rate: a single-point receiver's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AidNoise {
    /// Fixes per second.
    pub rate_hz: f64,
    /// Horizontal position σ per axis, m.
    pub pos_sigma_h_m: f64,
    /// Vertical position σ, m.
    pub pos_sigma_v_m: f64,
    /// Velocity σ per axis, m/s.
    pub vel_sigma_mps: f64,
}

impl Default for AidNoise {
    /// 1 Hz; 1.5 m horizontal and 3 m vertical per axis, 0.1 m/s (a single-point
    /// receiver's code and Doppler solution in open sky).
    fn default() -> Self {
        AidNoise {
            rate_hz: 1.0,
            pos_sigma_h_m: 1.5,
            pos_sigma_v_m: 3.0,
            vel_sigma_mps: 0.1,
        }
    }
}

/// The shared drive's mounting: its IMU's axes are (back, right, up) in the car
/// (roll 180°, yaw 180° from forward-right-down), a yaw of 90° in the monitor's
/// convention; the antenna 5 cm left of the IMU.
pub const DRIVE_MOUNTING_DEG: [f64; 3] = [0.0, 0.0, 90.0];
/// The antenna from the IMU, body frame (right, forward, up), m.
pub const DRIVE_LEVER_ARM_M: [f64; 3] = [-0.05, 0.0, 0.0];

/// The monitor config for the drive: the noise densities of the source project's
/// configuration (gyro 0.0038 °/s/√Hz = 0.228 °/√h; accelerometer 70 µg/√Hz =
/// 0.0412 m/s/√h; bias random walks 3.8e-5 °/s²/√Hz = 8.2 °/h/√h and 7 µg/√Hz·s⁻¹ =
/// 420 µg/√h), bias uncertainties after the static calibration (gyro 50 °/h, the
/// accelerometers 15 mg: their scale error shows as ~13 mg at rest), the aid's σ.
pub fn drive_config(noise: &AidNoise) -> Value {
    json!({
        "aids": ["gnss"],
        "input": "imu",
        "gnss": {"pos_sigma_m": noise.pos_sigma_h_m, "vel_sigma_mps": noise.vel_sigma_mps},
        "imu": {
            "gyro_bias_dph": 50.0,
            "accel_bias_ug": 15000.0,
            "arw_deg_rthr": 10.0,
            "vrw_mps_rthr": 1.0,
            "gyro_bias_walk_dph_rthr": 100.0,
            "accel_bias_walk_ug_rthr": 420.0
        },
        "init": {"pos_sigma_m": 3.0, "vel_sigma_mps": 0.3},
        "hal_m": 40.0,
        "strapdown": {
            "mounting_deg": DRIVE_MOUNTING_DEG,
            "gnss_lever_arm_m": DRIVE_LEVER_ARM_M,
            "align": {"static_s": 10.0, "max_accel_dev_mps2": 0.5, "max_rate_dps": 2.0}
        }
    })
}
