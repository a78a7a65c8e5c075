//! The `imu` block of an ingest epoch: one raw IMU sample in the sensor frame, as rates
//! (`f` m/s², `w` °/s, sampled at `t`) or as increments (`dv` m/s, `dtheta` °, over the
//! `dt` seconds that end at `t`), checked here into [`ImuBlock`] (radians inside); and
//! the block written back as a frame (`navguard convert`). docs/methods.md §M30.

use serde::{Deserialize, Serialize};

use navguard_core::epoch::ImuBlock;

use super::ingest::{FrameError, FrameErrorCode};

/// Largest specific force accepted, m/s² (100 g: beyond any vehicle IMU's range).
pub const MAX_SPECIFIC_FORCE: f64 = 100.0 * 9.806_65;
/// Largest angular rate accepted, °/s (a MEMS gyro's range is at most a few thousand).
pub const MAX_RATE_DPS: f64 = 10_000.0;
/// Longest increment interval accepted, s.
pub const MAX_INCREMENT_S: f64 = 1.0;

/// The `imu` block as it arrives: either `f` and `w`, or `dv`, `dtheta` and `dt`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct WireImu {
    #[serde(default)]
    f: Option<[f64; 3]>,
    #[serde(default)]
    w: Option<[f64; 3]>,
    #[serde(default)]
    dv: Option<[f64; 3]>,
    #[serde(default)]
    dtheta: Option<[f64; 3]>,
    #[serde(default)]
    dt: Option<f64>,
}

fn invalid(message: String) -> FrameError {
    FrameError::new(FrameErrorCode::InvalidEpoch, message)
}

fn non_finite(what: &str, v: &[f64]) -> Result<(), FrameError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(FrameError::new(
            FrameErrorCode::NonFinite,
            format!("imu.{what} holds a non-finite number"),
        ))
    }
}

/// `v` finite and every component within `limit` (in the wire's unit).
fn bounded(what: &str, v: &[f64; 3], limit: f64) -> Result<(), FrameError> {
    non_finite(what, v)?;
    match v.iter().find(|x| x.abs() > limit) {
        Some(x) => Err(invalid(format!(
            "imu.{what} component {x} is beyond ±{limit}"
        ))),
        None => Ok(()),
    }
}

impl TryFrom<WireImu> for ImuBlock {
    type Error = FrameError;

    fn try_from(w: WireImu) -> Result<Self, FrameError> {
        match w {
            WireImu {
                f: Some(f),
                w: Some(rate),
                dv: None,
                dtheta: None,
                dt: None,
            } => {
                bounded("f", &f, MAX_SPECIFIC_FORCE)?;
                bounded("w", &rate, MAX_RATE_DPS)?;
                Ok(ImuBlock {
                    accel: f,
                    gyro: rate.map(f64::to_radians),
                    dt: None,
                })
            }
            WireImu {
                f: None,
                w: None,
                dv: Some(dv),
                dtheta: Some(dtheta),
                dt: Some(dt),
            } => {
                non_finite("dt", &[dt])?;
                if !(dt > 0.0 && dt <= MAX_INCREMENT_S) {
                    return Err(invalid(format!(
                        "imu.dt = {dt} s must be in (0, {MAX_INCREMENT_S}]"
                    )));
                }
                bounded("dv", &dv, MAX_SPECIFIC_FORCE * dt)?;
                bounded("dtheta", &dtheta, MAX_RATE_DPS * dt)?;
                Ok(ImuBlock {
                    accel: dv,
                    gyro: dtheta.map(f64::to_radians),
                    dt: Some(dt),
                })
            }
            _ => Err(invalid(
                "imu holds either rates {f, w} or increments {dv, dtheta, dt}, each whole".into(),
            )),
        }
    }
}

/// The `imu` block written back: degrees on the wire.
#[derive(Debug, Serialize)]
pub(super) struct OutImu {
    #[serde(skip_serializing_if = "Option::is_none")]
    f: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    w: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    dv: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    dtheta: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    dt: Option<f64>,
}

impl From<&ImuBlock> for OutImu {
    fn from(b: &ImuBlock) -> Self {
        let gyro = b.gyro.map(f64::to_degrees);
        match b.dt {
            None => OutImu {
                f: Some(b.accel),
                w: Some(gyro),
                dv: None,
                dtheta: None,
                dt: None,
            },
            Some(dt) => OutImu {
                f: None,
                w: None,
                dv: Some(b.accel),
                dtheta: Some(gyro),
                dt: Some(dt),
            },
        }
    }
}

/// The block's numbers, for the finiteness check before writing.
pub(super) fn numbers(b: &ImuBlock, out: &mut Vec<f64>) {
    out.extend(b.accel.iter().chain(&b.gyro).chain(b.dt.iter()));
}

#[cfg(test)]
mod tests {
    use super::super::ingest::{epoch_to_wire, parse_frame};
    use super::*;

    fn code(frame: &str) -> FrameErrorCode {
        parse_frame(frame, 10).map(|_| ()).unwrap_err().code
    }

    #[test]
    fn rates_arrive_in_radians_and_go_back_in_degrees() {
        let e = parse_frame(
            r#"[{"t":1,"imu":{"f":[0.1,-0.2,9.8],"w":[180,0,-90]}}]"#,
            10,
        )
        .unwrap()
        .remove(0);
        let imu = e.imu.unwrap();
        assert_eq!(imu.accel, [0.1, -0.2, 9.8]);
        assert_eq!(
            imu.gyro,
            [std::f64::consts::PI, 0.0, -std::f64::consts::FRAC_PI_2]
        );
        assert_eq!(imu.dt, None);
        let line = epoch_to_wire(&e).unwrap();
        assert_eq!(
            line,
            r#"{"t":1.0,"imu":{"f":[0.1,-0.2,9.8],"w":[180.0,0.0,-90.0]}}"#
        );
    }

    #[test]
    fn increments_keep_their_interval() {
        let e = parse_frame(
            r#"[{"t":1,"imu":{"dv":[0.001,0,0.098],"dtheta":[0.01,0,0],"dt":0.01}}]"#,
            10,
        )
        .unwrap()
        .remove(0);
        let imu = e.imu.unwrap();
        assert_eq!(imu.dt, Some(0.01));
        assert!((imu.gyro[0] - 0.01f64.to_radians()).abs() < 1e-18);
        let back = parse_frame(&format!("[{}]", epoch_to_wire(&e).unwrap()), 10).unwrap();
        assert_eq!(back[0].imu, Some(imu));
    }

    #[test]
    fn mixed_partial_or_absurd_samples_are_refused_with_codes() {
        for frame in [
            r#"[{"t":0,"imu":{"f":[0,0,9.8]}}]"#,
            r#"[{"t":0,"imu":{"f":[0,0,9.8],"w":[0,0,0],"dt":0.01}}]"#,
            r#"[{"t":0,"imu":{"dv":[0,0,0.1],"dtheta":[0,0,0]}}]"#,
            r#"[{"t":0,"imu":{"dv":[0,0,0.1],"dtheta":[0,0,0],"dt":0}}]"#,
            r#"[{"t":0,"imu":{"dv":[0,0,0.1],"dtheta":[0,0,0],"dt":2}}]"#,
            r#"[{"t":0,"imu":{"f":[0,0,2000],"w":[0,0,0]}}]"#,
            r#"[{"t":0,"imu":{"f":[0,0,9.8],"w":[0,20000,0]}}]"#,
        ] {
            assert_eq!(code(frame), FrameErrorCode::InvalidEpoch, "{frame}");
        }
        assert_eq!(
            code(r#"[{"t":0,"imu":{"f":[0,0,9.8],"w":[0,0,0],"g":1}}]"#),
            FrameErrorCode::UnknownInput
        );
        assert_eq!(
            code(r#"[{"t":0,"imu":{"f":[0,0,9.8],"w":[0,0]}}]"#),
            FrameErrorCode::WrongLength
        );
    }
}
