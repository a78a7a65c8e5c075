//! Validation of a session spec: ids, monitor names, limits, and each monitor's
//! configuration (built once here so a bad model is a 422 naming its field).

use super::SessionError;
use crate::detect::ThresholdSpec;
use crate::monitor::{self, BuildError, ModelSource, Monitor, MonitorConfig, MonitorSpec};
use crate::service::config::Limits;
use crate::service::extract::integral_numbers;
use crate::service::store::StoredSession;
use crate::service::wire::{CreateSession, MonitorSpecWire};

/// Ids and names: 1–64 characters of `A–Z a–z 0–9 _ - .`, so they are safe in
/// URLs and logs; `.` and `..` are refused, as no client can address them (a
/// URL path resolves them away, RFC 3986 §5.2.4).
pub fn valid_name(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s != "."
        && s != ".."
        && s.bytes()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, b'_' | b'-' | b'.'))
}

/// Converts a monitor's wire spec into the domain spec.
pub fn monitor_spec(wire: &MonitorSpecWire) -> Result<MonitorSpec, BuildError> {
    Ok(MonitorSpec {
        kind: wire.kind,
        // The stored config is the client's JSON; its integral floats
        // (`embedding: 4.0`) are integers as the contract counts them.
        config: MonitorConfig::parse(wire.kind, &{
            let mut config = wire.config.clone();
            integral_numbers(&mut config);
            config
        })?,
        policy: wire.policy,
        threshold: ThresholdSpec::from_parts(wire.p_fa, wire.threshold)?,
    })
}

/// A monitor with its name in the session.
pub type NamedMonitors = Vec<(String, Box<dyn Monitor>)>;

/// Builds every monitor of a stored session (used at creation and at restart).
/// Monitors that name a trained model take it from `models` and keep their own
/// `Arc`: deleting the model later does not change a live session (a restart
/// then skips that session with a warning, as its model is gone).
pub fn build_monitors(
    session: &StoredSession,
    models: &dyn ModelSource,
) -> Result<NamedMonitors, SessionError> {
    session
        .monitors
        .iter()
        .enumerate()
        .map(|(i, wire)| {
            let built = monitor_spec(wire).and_then(|spec| monitor::build(&spec, models));
            match built {
                Ok(m) => Ok((wire.name.clone(), m)),
                Err(source) => Err(SessionError::Build { index: i, source }),
            }
        })
        .collect()
}

/// Checks a create request against the naming rules and limits.
pub fn validate_session(req: &CreateSession, limits: &Limits) -> Result<(), SessionError> {
    if let Some(id) = &req.id
        && !valid_name(id)
    {
        return Err(SessionError::invalid(
            "id",
            "must be 1-64 characters of A-Z a-z 0-9 _ - ., and not . or ..",
        ));
    }
    if req.monitors.is_empty() {
        return Err(SessionError::invalid(
            "monitors",
            "a session needs at least one monitor",
        ));
    }
    if req.monitors.len() > limits.max_monitors_per_session {
        return Err(SessionError::TooLarge(format!(
            "{} monitors, the limit per session is {}",
            req.monitors.len(),
            limits.max_monitors_per_session
        )));
    }
    for (i, m) in req.monitors.iter().enumerate() {
        if !valid_name(&m.name) {
            return Err(SessionError::invalid(
                format!("monitors[{i}].name"),
                "must be 1-64 characters of A-Z a-z 0-9 _ - ., and not . or ..",
            ));
        }
        if req.monitors[..i].iter().any(|other| other.name == m.name) {
            return Err(SessionError::invalid(
                format!("monitors[{i}].name"),
                format!("duplicate monitor name '{}'", m.name),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dot_and_dot_dot_are_not_names() {
        for name in ["a", "a.b", "..a", "...", "A_-.9"] {
            assert!(valid_name(name), "{name}");
        }
        for name in [".", "..", "", "a/b", "é", &"x".repeat(65)] {
            assert!(!valid_name(name), "{name}");
        }
    }
}
