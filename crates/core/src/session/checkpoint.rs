//! A session's checkpoint (docs/deployment.md, Failover): every monitor's evolving state
//! (`Monitor::checkpoint`), its availability, the session's statistics, the stream's
//! position (last epoch time, epoch count) and the runner's recording stream id, as
//! MessagePack (exact for every f64). The 1 Hz statistics history is not carried: a
//! resumed session's history chart starts at the resume.
//!
//! Thresholds and policies are part of the session's spec, which is stored apart: after
//! a restore, each monitor's tests take the configuration of the monitors built from the
//! stored spec, so a threshold changed after the last checkpoint is not undone.

use serde::{Deserialize, Serialize};

use super::SessionCore;
use super::stats::{SessionStats, TestRunning};
use super::thresholds::reapply_configuration;
use crate::monitor::Availability;

/// The checkpoint format this version writes and reads.
const FORMAT: u32 = 1;

#[derive(Serialize, Deserialize)]
struct Envelope {
    format: u32,
    monitors: Vec<MonitorState>,
    stats: SessionStats,
    /// The statistics' running values the wire form leaves out: per monitor and test,
    /// and per monitor the integrity timeline's last epoch time.
    running: Vec<(String, String, TestRunning)>,
    integrity_t: Vec<(String, f64)>,
    last_t: Option<f64>,
    stream_epochs: u64,
    recording_stream: u64,
}

#[derive(Serialize, Deserialize)]
struct MonitorState {
    name: String,
    availability: Option<Availability>,
    state: Vec<u8>,
}

impl SessionCore {
    /// The session's state as checkpoint bytes, with the runner's `recording_stream`.
    pub fn checkpoint(&self, recording_stream: u64) -> Result<Vec<u8>, String> {
        let mut monitors = Vec::with_capacity(self.roster.len());
        for (m, engine) in self.roster.iter().zip(&self.engines) {
            monitors.push(MonitorState {
                name: m.name.clone(),
                availability: m.rule.availability,
                state: engine
                    .checkpoint()
                    .map_err(|e| format!("monitor '{}': {e}", m.name))?,
            });
        }
        let mut running = Vec::new();
        let mut integrity_t = Vec::new();
        for (monitor, m) in &self.stats.monitors {
            for (test, t) in &m.tests {
                running.push((monitor.clone(), test.to_string(), t.running()));
            }
            if let Some(i) = &m.integrity {
                integrity_t.push((monitor.clone(), i.running_t()));
            }
        }
        let envelope = Envelope {
            format: FORMAT,
            monitors,
            stats: self.stats.clone(),
            running,
            integrity_t,
            last_t: self.last_t,
            stream_epochs: self.stream_epochs,
            recording_stream,
        };
        rmp_serde::to_vec_named(&envelope).map_err(|e| e.to_string())
    }

    /// Restores checkpoint bytes into a freshly built session; returns the runner's
    /// recording stream id. On `Err` the session is as built.
    pub fn restore(&mut self, bytes: &[u8]) -> Result<u64, String> {
        let envelope: Envelope = rmp_serde::from_slice(bytes).map_err(|e| e.to_string())?;
        if envelope.format != FORMAT {
            return Err(format!(
                "checkpoint format {} (this server reads {FORMAT})",
                envelope.format
            ));
        }
        let names: Vec<&str> = self.roster.iter().map(|m| m.name.as_str()).collect();
        let saved: Vec<&str> = envelope.monitors.iter().map(|m| m.name.as_str()).collect();
        if names != saved {
            return Err(format!(
                "checkpoint monitors {saved:?}, the session has {names:?}"
            ));
        }
        self.restore_monitors(&envelope.monitors)?;
        self.stats = restored_stats(envelope.stats, &envelope.running, &envelope.integrity_t);
        for index in 0..self.roster.len() {
            self.each_test_of(index, |slot, stats| {
                stats.threshold = slot.threshold;
                stats.state = slot.policy.health();
            });
        }
        self.last_t = envelope.last_t;
        self.stream_epochs = envelope.stream_epochs;
        Ok(envelope.recording_stream)
    }

    /// Restores every monitor's state, then re-applies its configured thresholds and
    /// policies; a monitor that refuses its state leaves every monitor as built.
    fn restore_monitors(&mut self, saved: &[MonitorState]) -> Result<(), String> {
        for (k, saved) in saved.iter().enumerate() {
            let engine = &mut self.engines[k];
            let configured = engine.tests().clone();
            if let Err(e) = engine.restore(&saved.state) {
                for (m, engine) in self.roster[..k].iter_mut().zip(&mut self.engines) {
                    engine.reset();
                    m.rule.availability = None;
                }
                return Err(format!("monitor '{}': {e}", saved.name));
            }
            reapply_configuration(engine.tests_mut(), &configured);
            self.roster[k].rule.availability = saved.availability;
        }
        Ok(())
    }
}

/// The checkpoint's statistics with their running values put back, not connected.
fn restored_stats(
    mut stats: SessionStats,
    running: &[(String, String, TestRunning)],
    integrity_t: &[(String, f64)],
) -> SessionStats {
    for (monitor, test, r) in running {
        if let Some(t) = stats
            .monitors
            .get_mut(monitor)
            .and_then(|m| m.tests.get_mut(test.as_str()))
        {
            t.set_running(*r);
        }
    }
    for (monitor, t) in integrity_t {
        if let Some(i) = stats
            .monitors
            .get_mut(monitor)
            .and_then(|m| m.integrity.as_mut())
        {
            i.set_running_t(*t);
        }
    }
    stats.connected = false;
    stats.epochs_per_s = 0.0;
    stats
}
