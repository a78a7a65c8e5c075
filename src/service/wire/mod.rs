//! Wire types: the JSON the service reads and writes, parsed and validated once
//! here and converted into domain types (`Epoch`, `MonitorSpec`) that cannot hold
//! a bad value. Units on the wire are degrees; inside they are radians.
//!
//! - [`rest`]: REST request and response bodies (sessions, thresholds).
//! - [`ingest`]: ingest frames (epochs in, their error codes) and epochs back to frames.
//! - [`gnss`]: the `gnss_raw` block (pseudoranges) of an ingest epoch.
//! - [`imu`]: the `imu` block (one raw IMU sample) of an ingest epoch.
//! - [`events`]: what the server sends out (results, alarms, state changes, errors).
//!
//! Every item is re-exported here by name, so `wire::X` names it wherever it lives. The
//! session core's records (alarm-log entries, state and availability changes) and its
//! threshold bodies are part of the wire contract too, and are named here beside them.

pub mod events;
pub mod gnss;
pub mod imu;
pub mod ingest;
pub mod rest;

pub use events::{
    ErrorEvent, RESULT_FRAME_BYTES, Tagged, result_frame, tagged, write_result_frame,
};
pub use ingest::{FrameError, FrameErrorCode, epoch_to_wire, parse_frame, through_the_wire};
pub use navguard_core::session::{
    AlarmLevel, AlarmRecord, AvailabilityChange, Severity, StateChange, TestThreshold,
    TestThresholdSpec, ThresholdUpdate, ThresholdView,
};
pub use rest::{CreateSession, MonitorSpecWire, calibrated_tests};

#[cfg(test)]
mod tests {
    use super::*;
    use navguard_core::detect::Health;

    #[test]
    fn one_epoch_and_batches_parse() {
        let e = parse_frame(r#"{"t": 1.5, "z": [1, 2]}"#, 10).unwrap();
        assert_eq!(e.len(), 1);
        assert_eq!(e[0].z, Some(vec![1.0, 2.0]));
        let e = parse_frame(r#"[{"t": 1}, {"t": 1}, {"t": 2}]"#, 10).unwrap();
        assert_eq!(e.len(), 3);
    }

    #[test]
    fn degrees_become_radians() {
        let e = parse_frame(
            r#"{"t":0,"ins":{"lat":30,"lon":114,"h":10,"vel":[1,2,3],"att":[0,0,90]},"gnss":{"lat":-45,"lon":0,"h":0}}"#,
            1,
        )
        .unwrap();
        let ins = e[0].ins.as_ref().unwrap();
        assert!((ins.lat - 30f64.to_radians()).abs() < 1e-15);
        assert!((ins.att[2] - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert!((e[0].gnss.as_ref().unwrap().lat + std::f64::consts::FRAC_PI_4).abs() < 1e-15);
    }

    #[test]
    fn bad_frames_get_their_codes() {
        let code = |s: &str| parse_frame(s, 3).unwrap_err().code.as_str();
        assert_eq!(code(r#"{"t": 1, "z": [1,"#), "malformed_json");
        assert_eq!(code(r#"{"t": NaN}"#), "non_finite");
        assert_eq!(code(r#"{"t": 1, "z": [Infinity]}"#), "non_finite");
        assert_eq!(code(r#"{"t": 1e999}"#), "non_finite");
        assert_eq!(code(r#"{"t": 1, "lidar": {}}"#), "unknown_input");
        assert_eq!(
            code(r#"{"t": 1, "ins": {"lat":0,"lon":0,"h":0,"vel":[1,2],"att":[0,0,0]}}"#),
            "wrong_length"
        );
        assert_eq!(
            code(r#"{"t": 1, "gnss": {"lat":91,"lon":0,"h":0}}"#),
            "invalid_epoch"
        );
        assert_eq!(code(r#"{"z": [1]}"#), "invalid_epoch");
        assert_eq!(code(r#"[{"t": 2}, {"t": 1}]"#), "time_backwards");
        assert_eq!(code(r#"[]"#), "empty_batch");
        assert_eq!(
            code(r#"[{"t":1},{"t":2},{"t":3},{"t":4}]"#),
            "batch_too_large"
        );
        // A NaN inside a string is not a non-finite number.
        assert_eq!(code(r#"{"t": 1, "note": "NaN"}"#), "unknown_input");
    }

    #[test]
    fn batch_errors_name_the_epoch() {
        let e = parse_frame(
            r#"[{"t": 0}, {"t": 1, "gnss": {"lat":95,"lon":0,"h":0}}]"#,
            5,
        )
        .unwrap_err();
        assert_eq!(e.index, Some(1));
    }

    #[test]
    fn tagged_messages_carry_their_type() {
        let change = StateChange {
            session: "s".into(),
            monitor: "m".into(),
            test: "residual".into(),
            t: 1.0,
            from: Health::Healthy,
            to: Health::Suspect,
            severity: Some(Severity::Warning),
            log_id: Some(3),
        };
        let v: serde_json::Value = serde_json::from_str(&tagged("state", &change)).unwrap();
        assert_eq!(v["type"], "state");
        assert_eq!(v["to"], "suspect");
    }
}
