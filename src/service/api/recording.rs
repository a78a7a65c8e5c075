//! `GET /api/v1/sessions/{id}/recording` (the flight recorder, docs/architecture.md
//! §A12) and `GET /api/v1/sessions/{id}/history` (the dashboard's past).
//!
//! The recording is streamed as JSON lines in the `simulate`/`replay` format: one
//! epoch per line, each exactly the text the client sent for it (a batch frame is split
//! into its epochs; line breaks inside a frame, which JSON allows only as whitespace,
//! become spaces), so `navguard replay` of it into a fresh session with the same spec
//! reproduces every result and alarm bit for bit. `format=events` streams instead the
//! messages each frame caused, with their epoch index; `format=index` lists the recorded
//! streams. A recording outlives its session until retention drops it.

use axum::Json;
use axum::body::{Body, Bytes};
use axum::extract::{Path, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::value::RawValue;

use std::collections::BTreeMap;

use crate::service::app::AppState;
use crate::service::error::ApiError;
use crate::service::extract::{ApiQuery, query_integer_opt};
use crate::service::session::SessionError;
use crate::service::session::spec::build_monitors;
use crate::service::store::{RecordedFrame, Store};
use crate::service::wire::{TestThresholdSpec, calibrated_tests, parse_frame};
use navguard_core::epoch::Epoch;
use navguard_core::monitor::calibrate::CalibrationLine;
use navguard_core::monitor::calibrate::live::{LiveOptions, calibrate_live};
use navguard_core::session::history::HistoryView;

/// Frames read from the store per chunk of the response.
const PAGE: i64 = 500;

/// What the recording route answers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordingFormat {
    /// One epoch per line, as sent (the `replay` format).
    #[default]
    Epochs,
    /// One message (`state`, `alarm`, `availability`) per line with its epoch index.
    Events,
    /// The recorded streams, as JSON.
    Index,
}

/// Query of the recording route.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordingQuery {
    /// Which stream (its attach time, Unix ms, as the index lists it); default the latest.
    #[serde(default, deserialize_with = "query_integer_opt")]
    stream: Option<u64>,
    /// `epochs` (default), `events` or `index`.
    #[serde(default)]
    format: RecordingFormat,
}

/// The lines of one recorded frame in the asked format.
fn lines(frame: &RecordedFrame, format: RecordingFormat, out: &mut String) {
    match format {
        RecordingFormat::Epochs => {
            let text = frame.frame.trim_start();
            let epochs: Vec<&str> = if text.starts_with('[') {
                serde_json::from_str::<Vec<&RawValue>>(text)
                    .map(|v| v.into_iter().map(RawValue::get).collect())
                    .unwrap_or_default()
            } else {
                vec![text]
            };
            for epoch in epochs.into_iter().take(frame.epochs as usize) {
                out.extend(
                    epoch
                        .trim()
                        .chars()
                        .map(|c| if c == '\n' || c == '\r' { ' ' } else { c }),
                );
                out.push('\n');
            }
        }
        RecordingFormat::Events => {
            if let Ok(events) = serde_json::from_str::<Vec<&RawValue>>(&frame.events) {
                for e in events {
                    out.push_str(e.get());
                    out.push('\n');
                }
            }
        }
        RecordingFormat::Index => {}
    }
}

/// `GET /api/v1/sessions/{id}/recording?stream=&format=`
pub async fn recording(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ApiQuery(q): ApiQuery<RecordingQuery>,
) -> Result<Response, ApiError> {
    let store = state.store.clone();
    // Frames queued for the writer are part of the recording already.
    store.flush_recordings().await;
    let streams = store.recording_streams(&id).await?;
    if q.format == RecordingFormat::Index {
        return Ok(Json(serde_json::json!({"session": id, "streams": streams})).into_response());
    }
    let Some(last) = streams.last() else {
        return Err(ApiError::NotFound(format!(
            "no recording for session '{id}'"
        )));
    };
    let stream = q.stream.unwrap_or(last.stream);
    if !streams.iter().any(|s| s.stream == stream) {
        let known: Vec<String> = streams.iter().map(|s| s.stream.to_string()).collect();
        return Err(ApiError::NotFound(format!(
            "session '{id}' has no recorded stream {stream}; recorded: {}",
            known.join(", ")
        )));
    }
    let format = q.format;
    let name = format!("recording-{id}-{stream}.jsonl");
    let body = futures_util::stream::unfold(Some(0i64), move |cursor| {
        let (store, id) = (store.clone(), id.clone());
        async move { chunk(&store, &id, stream, cursor?, format).await }
    });
    Ok((
        StatusCode::OK,
        [
            (header::CONTENT_TYPE, "application/x-ndjson".to_owned()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{name}\""),
            ),
        ],
        Body::from_stream(body),
    )
        .into_response())
}

/// The next chunk of the response from the frame with an id above `after`, and the
/// cursor after it (`None` once the stream is done).
async fn chunk(
    store: &Store,
    id: &str,
    stream: u64,
    after: i64,
    format: RecordingFormat,
) -> Option<(Result<Bytes, std::io::Error>, Option<i64>)> {
    let page = match store.recording_page(id, stream, after, PAGE).await {
        Ok(page) => page,
        Err(e) => return Some((Err(std::io::Error::other(e.to_string())), None)),
    };
    let (last_id, _) = page.last()?;
    let next = (page.len() as i64 == PAGE).then_some(*last_id);
    let mut out = String::new();
    for (_, frame) in &page {
        lines(frame, format, &mut out);
    }
    Some((Ok(Bytes::from(out)), next))
}

/// Query of the calibration route.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationQuery {
    /// False-alarm rate per epoch and test to calibrate for.
    far: f64,
    /// Confidence that the true rate at the proposal is at most `far` (default 0.95).
    confidence: Option<f64>,
    /// The recorded stream to replay (default the latest).
    #[serde(default, deserialize_with = "query_integer_opt")]
    stream: Option<u64>,
    /// Tests to calibrate, comma-separated (default each monitor's main tests).
    tests: Option<String>,
    /// Share of the epochs, at the end, held out to check the proposal (default 0.5).
    holdout: Option<f64>,
    /// Largest held-out rate accepted, a multiple of `far` (default 2).
    max_transfer: Option<f64>,
}

impl CalibrationQuery {
    /// The live options, checked, and the test names asked for.
    fn options(&self) -> Result<(LiveOptions, Vec<String>), ApiError> {
        let confidence = self.confidence.unwrap_or(0.95);
        if !(self.far > 0.0 && self.far < 1.0) {
            return Err(ApiError::invalid("far", "must lie in (0, 1)"));
        }
        if !(confidence > 0.0 && confidence < 1.0) {
            return Err(ApiError::invalid("confidence", "must lie in (0, 1)"));
        }
        let mut options = LiveOptions::new(self.far, confidence);
        if let Some(h) = self.holdout {
            if !(0.0..=0.9).contains(&h) {
                return Err(ApiError::invalid("holdout", "must lie in [0, 0.9]"));
            }
            options.holdout = h;
        }
        if let Some(t) = self.max_transfer {
            if !(t >= 1.0 && t.is_finite()) {
                return Err(ApiError::invalid("max_transfer", "must be a number ≥ 1"));
            }
            options.max_transfer = t;
        }
        let names: Vec<String> = self
            .tests
            .iter()
            .flat_map(|t| t.split(','))
            .map(str::trim)
            .filter(|t| !t.is_empty())
            .map(str::to_owned)
            .collect();
        Ok((options, names))
    }
}

/// One monitor's calibration and the `PUT …/threshold` body that applies it.
#[derive(Debug, serde::Serialize)]
pub struct MonitorCalibrationView {
    tests: Vec<CalibrationLine>,
    put: BTreeMap<&'static str, BTreeMap<String, TestThresholdSpec>>,
}

/// What `GET …/calibration` answers.
#[derive(Debug, serde::Serialize)]
pub struct CalibrationView {
    session: String,
    stream: u64,
    far: f64,
    confidence: f64,
    epochs: usize,
    monitors: BTreeMap<String, MonitorCalibrationView>,
}

/// Every epoch of a recorded stream, as the monitors saw them.
async fn recorded_epochs(store: &Store, id: &str, stream: u64) -> Result<Vec<Epoch>, ApiError> {
    let mut epochs = Vec::new();
    let mut after = 0;
    loop {
        let page = store.recording_page(id, stream, after, PAGE).await?;
        let Some((last, _)) = page.last() else { break };
        after = *last;
        for (_, frame) in &page {
            let parsed = parse_frame(&frame.frame, usize::MAX).map_err(|e| {
                ApiError::Internal(format!("recorded frame unreadable: {}", e.message))
            })?;
            epochs.extend(parsed.into_iter().take(frame.epochs as usize));
        }
        if (page.len() as i64) < PAGE {
            break;
        }
    }
    Ok(epochs)
}

/// `GET /api/v1/sessions/{id}/calibration?far=&confidence=&stream=&tests=&holdout=&max_transfer=`:
/// `navguard calibrate` over the session's own recording (docs/methods.md §M25): its
/// recorded stream replayed through its monitors as they are configured now, with the
/// candidate threshold live, and per test the threshold that gives `far` on that data
/// and how it does on the held-out end of it (with the `PUT` body). The recording should
/// be fault-free; the replays run on the blocking pool.
pub async fn calibration(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ApiQuery(q): ApiQuery<CalibrationQuery>,
) -> Result<Json<CalibrationView>, ApiError> {
    let (options, names) = q.options()?;
    let handle = state
        .registry
        .get(&id)
        .ok_or_else(|| ApiError::NotFound(format!("no session '{id}'")))?;
    let stored = handle.stored();
    state.store.flush_recordings().await;
    let streams = state.store.recording_streams(&id).await?;
    let stream = match q.stream {
        Some(s) if streams.iter().any(|x| x.stream == s) => s,
        Some(s) => {
            return Err(ApiError::NotFound(format!(
                "session '{id}' has no recorded stream {s}"
            )));
        }
        None => streams
            .last()
            .map(|s| s.stream)
            .ok_or_else(|| ApiError::NotFound(format!("no recording for session '{id}'")))?,
    };
    let epochs = recorded_epochs(&state.store, &id, stream).await?;
    let models = state.models.clone();
    let (far, confidence) = (options.far, options.confidence);
    let answer = tokio::task::spawn_blocking(move || {
        let monitors = build_monitors(&stored, &*models)?;
        let mut out = BTreeMap::new();
        for (name, mut m) in monitors {
            let mut options = options.clone();
            if !names.is_empty() {
                let bank = m.tests_mut();
                let mine: Vec<String> = names
                    .iter()
                    .filter(|t| bank.index_of(t).is_some())
                    .cloned()
                    .collect();
                if mine.is_empty() {
                    continue;
                }
                options.tests = Some(mine);
            }
            let tests = calibrate_live(&mut *m, &epochs, &options)
                .map_err(|e| SessionError::invalid(name.clone(), e.to_string()))?;
            let put = BTreeMap::from([("tests", calibrated_tests(&tests))]);
            out.insert(name, MonitorCalibrationView { tests, put });
        }
        if let Some(missing) = names.iter().find(|n| {
            !out.values()
                .any(|m: &MonitorCalibrationView| m.tests.iter().any(|t| &t.test == *n))
        }) {
            return Err(SessionError::invalid(
                "tests",
                format!("no monitor of the session has a calibratable test '{missing}'"),
            ));
        }
        Ok::<_, SessionError>((out, epochs.len()))
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    Ok(Json(CalibrationView {
        session: id,
        stream,
        far,
        confidence,
        epochs: answer.1,
        monitors: answer.0,
    }))
}

/// Query of the history route.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HistoryQuery {
    /// Only samples at or after this epoch time, s.
    since: Option<f64>,
}

/// `GET /api/v1/sessions/{id}/history?since=`: 1 Hz samples of the statistics of the
/// current stream (docs/architecture.md §A12).
pub async fn history(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ApiQuery(q): ApiQuery<HistoryQuery>,
) -> Result<Json<HistoryView>, ApiError> {
    if q.since.is_some_and(|s| !s.is_finite()) {
        return Err(ApiError::invalid("since", "must be a finite number"));
    }
    let handle = state
        .registry
        .get(&id)
        .ok_or_else(|| ApiError::NotFound(format!("no session '{id}'")))?;
    Ok(Json(handle.history(q.since).await?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    fn frame(text: &str, epochs: u64) -> RecordedFrame {
        RecordedFrame {
            session: "s".into(),
            stream: 1,
            first_epoch: 0,
            epochs,
            recorded_at_ms: 0,
            frame: Arc::from(text),
            events: r#"[{"epoch_index":0,"message":{"type":"state"}}]"#.into(),
        }
    }

    #[test]
    fn batches_split_into_their_epochs_exactly_as_sent() {
        let mut out = String::new();
        lines(
            &frame(
                "[{\"t\": 1.10000000000000009, \"z\": [1e-3]},\n {\"t\":2}, {\"t\":3}]",
                2,
            ),
            RecordingFormat::Epochs,
            &mut out,
        );
        // Two of three epochs were processed; the digits are the client's own.
        assert_eq!(
            out,
            "{\"t\": 1.10000000000000009, \"z\": [1e-3]}\n{\"t\":2}\n"
        );
        let mut out = String::new();
        lines(&frame("{\"t\":\n5}", 1), RecordingFormat::Epochs, &mut out);
        assert_eq!(out, "{\"t\": 5}\n");
        let mut out = String::new();
        lines(&frame("{\"t\":5}", 1), RecordingFormat::Events, &mut out);
        assert_eq!(
            out,
            "{\"epoch_index\":0,\"message\":{\"type\":\"state\"}}\n"
        );
    }
}
