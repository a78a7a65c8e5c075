//! The dashboard in a real browser: headless Chromium driven over WebDriver
//! (chromedriver) against a server started in this process on port 0. A
//! shortened ship scenario with a GNSS position step is streamed into the
//! ingest socket at 20× real time while the page is open; the test checks that
//! the session appears, the alarm row appears, the charts (the federated
//! monitor's track plot included) have been drawn with data, that the session's
//! URL opened directly in a new tab draws the run's history, and that a threshold change made through the page's controls is what
//! the REST API then reports. It also feeds 10 monitors at 20 stats messages a
//! second and prints the page's own frame-time figures (never asserted: no
//! test asserts wall-clock time), and saves screenshots under `target/`. A
//! second test streams real phone pseudoranges into a `gnss` monitor and checks
//! that its sky plot, protection-level chart and Stanford diagram are drawn. A
//! third streams a still vehicle's raw IMU into two `federated` monitors with
//! `input: imu` and checks their alignment badges, the single mechanized track and
//! an unknown protection level shown as a dash.
//!
//! Needs `/usr/bin/chromium` and `/usr/bin/chromedriver` (Debian's `chromium`
//! and `chromium-driver`; `CHROMIUM` / `CHROMEDRIVER` override the paths). With
//! `NAVGUARD_BROWSER_TEST=1` (set by `.ci/run`) their absence fails the test;
//! otherwise the test prints why it is skipped and passes. With
//! `NAVGUARD_DASHBOARD_PNG=path` the session-view screenshot is also written
//! there (how `static/dashboard.png` for the README is made).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use fantoccini::wd::Capabilities;
use fantoccini::{Client, ClientBuilder, Locator};
use futures_util::SinkExt;
use navguard::service::Limits;
use navguard::service::wire::epoch_to_wire;
use navguard_core::epoch::Aid;
use navguard_sim::scenario::ship_with;
use navguard_sim::{Channel, Fault, FaultKind};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

/// Seconds of the shortened ship run (10 Hz INS: 2,400 epochs).
const SHIP_SECONDS: f64 = 240.0;
/// Epochs per frame: one simulated second of the 10 Hz INS.
const EPOCHS_PER_FRAME: usize = 10;
/// Pause between frames: 20 frames a wall-clock second, i.e. 20× real time,
/// which is also the events socket's top rate of `stats` messages.
const FRAME_PERIOD: Duration = Duration::from_millis(50);
/// Monitors in the load session.
const LOAD_MONITORS: usize = 10;
/// GSDC 2023's Pixel 7 Pro (tests/data/gnss/README.md): five 1 Hz epochs of 21
/// satellites with a truth position, as ingest frames written by `navguard convert`.
const GNSS_FRAMES: &str = "tests/data/gnss/gsdc2023_pixel7pro.jsonl";
/// Pause between GNSS frames: well over the 50 ms between stats messages, so each
/// epoch reaches the page in a stats message of its own.
const GNSS_FRAME_PERIOD: Duration = Duration::from_millis(200);

fn tool(env: &str, default: &str) -> PathBuf {
    std::env::var_os(env).map_or_else(|| PathBuf::from(default), PathBuf::from)
}

/// The browser and its driver, or the reason the test cannot run.
fn browser_tools() -> Result<(PathBuf, PathBuf), String> {
    let chromium = tool("CHROMIUM", "/usr/bin/chromium");
    let driver = tool("CHROMEDRIVER", "/usr/bin/chromedriver");
    for path in [&chromium, &driver] {
        if !path.exists() {
            return Err(format!(
                "{} not found (install Debian's chromium and chromium-driver)",
                path.display()
            ));
        }
    }
    Ok((chromium, driver))
}

/// The browser and its driver, or `None` (after saying why) when the test is to be
/// skipped; without them, `NAVGUARD_BROWSER_TEST=1` fails the test instead.
fn browser_tools_or_skip() -> Option<(PathBuf, PathBuf)> {
    match browser_tools() {
        Ok(tools) => Some(tools),
        Err(reason) if std::env::var("NAVGUARD_BROWSER_TEST").as_deref() == Ok("1") => {
            panic!("NAVGUARD_BROWSER_TEST=1 but {reason}")
        }
        Err(reason) => {
            eprintln!(
                "skipping the browser test: {reason}; set NAVGUARD_BROWSER_TEST=1 to require it"
            );
            None
        }
    }
}

/// chromedriver on a free port; killed on drop.
struct Driver {
    child: Child,
    url: String,
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

async fn start_driver(path: &Path) -> Driver {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let child = Command::new(path)
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromedriver starts");
    // Owned by the guard from here on, so a panic below still kills it.
    let driver = Driver {
        child,
        url: format!("http://127.0.0.1:{port}"),
    };
    for _ in 0..100 {
        if tokio::net::TcpStream::connect(("127.0.0.1", port))
            .await
            .is_ok()
        {
            return driver;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("chromedriver did not listen on port {port}");
}

async fn open_browser(driver: &Driver, chromium: &Path, profile: &Path) -> Client {
    let mut caps = Capabilities::new();
    caps.insert(
        "goog:chromeOptions".into(),
        json!({
            "binary": chromium,
            // The flags a sandboxed CI machine with a closed network needs.
            "args": [
                "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                "--no-first-run", "--disable-background-networking",
                "--disable-component-update", "--disable-sync",
                "--disable-dev-shm-usage", "--hide-scrollbars",
                format!("--user-data-dir={}", profile.display()),
                "--window-size=1400,1000",
            ],
        }),
    );
    let connector = hyper_util::client::legacy::connect::HttpConnector::new();
    ClientBuilder::new(connector)
        .capabilities(caps)
        .connect(&driver.url)
        .await
        .expect("a WebDriver session with chromium")
}

/// Polls `script` (a JS expression) until it is truthy; panics with `what` after 30 s.
async fn wait_js(client: &Client, script: &str, what: &str) -> Value {
    for _ in 0..300 {
        let v = client
            .execute(&format!("return ({script});"), vec![])
            .await
            .expect("script runs");
        let truthy = match &v {
            Value::Null => false,
            Value::Bool(b) => *b,
            Value::Number(n) => n.as_f64() != Some(0.0),
            Value::String(s) => !s.is_empty(),
            _ => true,
        };
        if truthy {
            return v;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let html = client.source().await.unwrap_or_default();
    panic!(
        "timed out waiting for {what} ({script}); page:\n{}",
        &html[html.find("<main").unwrap_or(0)..][..html
            .len()
            .min(6000)
            .min(html.len() - html.find("<main").unwrap_or(0))]
    );
}

async fn js(client: &Client, script: &str) -> Value {
    client.execute(script, vec![]).await.expect("script runs")
}

/// The ship run with a GNSS position step of 40 m north on [90, 150) s: a
/// fault the GNSS test isolates within a few epochs and releases after.
fn ship_frames() -> Vec<String> {
    let fault = Fault {
        aid: Aid::Gnss,
        channel: Channel::Position,
        component: 1,
        kind: FaultKind::Step { value: 40.0 },
        start_s: 90.0,
        end_s: Some(150.0),
    };
    let scenario = ship_with(7, vec![fault], SHIP_SECONDS).expect("ship scenario");
    scenario
        .epochs
        .chunks(EPOCHS_PER_FRAME)
        .map(|chunk| {
            let epochs: Vec<String> = chunk
                .iter()
                .map(|e| epoch_to_wire(&e.epoch).expect("finite epoch"))
                .collect();
            format!("[{}]", epochs.join(","))
        })
        .collect()
}

fn ship_session() -> Value {
    let scenario = ship_with(7, vec![], 1.0).expect("ship scenario");
    json!({
        "id": "ship",
        "monitors": [{
            "name": "federated",
            "type": "federated",
            "config": scenario.default_monitor_config(),
            "policy": {"kind": "counters", "n1": 10, "n2": 5},
        }],
        "record": true,
    })
}

/// A constant-velocity track (docs/methods.md §M2's linear monitor) observed in noise.
fn load_session() -> Value {
    let monitors: Vec<Value> = (0..LOAD_MONITORS)
        .map(|i| {
            json!({
                "name": format!("cv{i}"),
                "type": "linear",
                "config": {
                    "f": [[1.0, 1.0], [0.0, 1.0]], "h": [[1.0, 0.0]],
                    "q": [[0.25, 0.5], [0.5, 1.0]], "r": [[1.0]],
                    "x0": [0.0, 0.0], "p0": [[10.0, 0.0], [0.0, 10.0]],
                },
            })
        })
        .collect();
    json!({"id": "load", "monitors": monitors})
}

/// Frames of `z` = a deterministic pseudo-noise around 0 (no RNG needed: the
/// statistic only has to move for the charts to redraw).
fn load_frames(n: usize) -> Vec<String> {
    (0..n)
        .map(|k| {
            let z = ((k as f64) * 1.7).sin() * 0.8;
            json!({"t": k as f64, "z": [z]}).to_string()
        })
        .collect()
}

async fn stream(url: String, frames: Vec<String>) {
    stream_every(url, frames, FRAME_PERIOD).await;
}

/// Sends `frames` into the ingest socket at `url`, one every `period`.
async fn stream_every(url: String, frames: Vec<String>, period: Duration) {
    let mut socket = common::connect(&url).await;
    for frame in frames {
        socket
            .send(Message::Text(frame.into()))
            .await
            .expect("send");
        tokio::time::sleep(period).await;
    }
    let _ = socket.close(None).await;
}

async fn save_screenshot(client: &Client, name: &str) -> PathBuf {
    let png = client.screenshot().await.expect("screenshot");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, &png).unwrap();
    path
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_shows_a_faulty_replay_and_applies_a_threshold_change() {
    let Some((chromium, driver_path)) = browser_tools_or_skip() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let server = common::start(&dir.path().join("t.db"), None, Limits::default()).await;
    let http = common::http(&server);
    let ws = common::ws(&server);
    let rest = reqwest::Client::new();
    let created = rest
        .post(format!("{http}/api/v1/sessions"))
        .json(&ship_session())
        .send()
        .await
        .unwrap();
    assert_eq!(created.status(), 201, "{}", created.text().await.unwrap());

    let driver = start_driver(&driver_path).await;
    let profile = tempfile::tempdir().unwrap();
    let client = open_browser(&driver, &chromium, profile.path()).await;
    client.goto(&format!("{http}/")).await.unwrap();

    // 1. The session appears in the overview, with its monitor's test badges.
    client
        .wait()
        .for_element(Locator::Css(r#"#sessions [data-session="ship"]"#))
        .await
        .expect("the session card appears");
    wait_js(
        &client,
        r#"document.querySelectorAll('#sessions [data-session="ship"] .badge[data-test]').length >= 4"#,
        "badges for gnss, dvl, cns and hpl",
    )
    .await;

    // 2. Open the session and replay the faulty run while the page watches.
    client
        .goto(&format!("{http}/#/session/ship"))
        .await
        .unwrap();
    let feeder = tokio::spawn(stream(
        format!("{ws}/api/v1/sessions/ship/ingest"),
        ship_frames(),
    ));
    let alarm = wait_js(
        &client,
        r#"(() => { const r = document.querySelector('#session-alarms tr[data-alarm-id]'); return r && r.textContent; })()"#,
        "an alarm row in the session view",
    )
    .await;
    println!("first alarm row: {alarm}");
    feeder.await.unwrap();

    // 3. The GNSS chart has drawn the whole run, and its canvas holds real pixels.
    let points = wait_js(
        &client,
        r#"(() => { const c = document.querySelector('canvas[data-monitor="federated"][data-test="gnss"]'); return c && Number(c.dataset.points) >= 100 && Number(c.dataset.points); })()"#,
        "the gnss chart to draw at least 100 points",
    )
    .await;
    let inked = js(
        &client,
        r#"const c = document.querySelector('canvas[data-test="gnss"]');
           const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
           let blue = 0, shaded = 0;
           for (let i = 0; i < d.length; i += 4) {
             if (d[i + 2] > 150 && d[i] < 60 && d[i + 3] > 200) blue++;       // the statistic line
             if (d[i] > 200 && d[i + 2] < 200 && d[i + 3] > 20 && d[i + 3] < 120) shaded++; // a state band
           }
           return {blue, shaded};"#,
    )
    .await;
    println!("gnss chart: {points} points drawn, pixels {inked}");
    assert!(inked["blue"].as_u64().unwrap() > 100, "{inked}");
    let hpl = js(
        &client,
        r#"return Number(document.querySelector('canvas[data-test="hpl"]').dataset.points);"#,
    )
    .await;
    assert!(hpl.as_f64().unwrap() >= 100.0, "HPL chart points: {hpl}");

    // The track plot holds the sampled corrected and INS tracks and has inked both.
    let track_points = wait_js(
        &client,
        r#"(() => { const c = document.querySelector('canvas.track-chart[data-monitor="federated"]'); return c && Number(c.dataset.points) >= 100 && Number(c.dataset.points); })()"#,
        "the track plot to hold at least 100 points",
    )
    .await;
    let track_ink = js(
        &client,
        r#"const c = document.querySelector('canvas.track-chart[data-monitor="federated"]');
           const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
           const near = (i, r, g, b) => Math.abs(d[i] - r) < 40 && Math.abs(d[i + 1] - g) < 40 && Math.abs(d[i + 2] - b) < 40 && d[i + 3] > 200;
           let corrected = 0, ins = 0;
           for (let i = 0; i < d.length; i += 4) {
             if (near(i, 0x0a, 0x7d, 0x4f)) corrected++;   // the corrected track
             if (near(i, 0xd9, 0x73, 0x0d)) ins++;         // the raw INS track
           }
           return {corrected, ins, drawn: Number(c.dataset.drawn), lastE: Number(c.dataset.lastE), lastN: Number(c.dataset.lastN),
                   lines: c.dataset.lines, legend: c.dataset.legend,
                   badge: !!document.querySelector('[data-kind="alignment"][data-monitor="federated"]')};"#,
    )
    .await;
    println!("track plot: {track_points} points, {track_ink}");
    // Well beyond the legend's swatches (about 40 pixels each at DPR 1).
    assert!(
        track_ink["corrected"].as_u64().unwrap() > 200,
        "{track_ink}"
    );
    assert!(track_ink["ins"].as_u64().unwrap() > 200, "{track_ink}");
    // A monitor fed a client's INS: two tracks, two legend entries, no alignment badge.
    assert_eq!(track_ink["lines"], "2", "{track_ink}");
    assert_eq!(track_ink["legend"], "corrected, raw INS", "{track_ink}");
    assert_eq!(track_ink["badge"], false, "{track_ink}");
    // The ship moves: the last corrected point is well away from the origin.
    let (e, n) = (
        track_ink["lastE"].as_f64().unwrap(),
        track_ink["lastN"].as_f64().unwrap(),
    );
    assert!(e.hypot(n) > 100.0, "{track_ink}");

    // The page's alarm matches the log.
    let log: Value = rest
        .get(format!(
            "{http}/api/v1/alarms?session=ship&monitor=federated"
        ))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let gnss_alarms: Vec<&Value> = log["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|a| a["test"] == "gnss")
        .collect();
    assert!(!gnss_alarms.is_empty(), "{log}");
    let t = gnss_alarms.last().unwrap()["t"].as_f64().unwrap();
    assert!((90.0..100.0).contains(&t), "GNSS alarm at t = {t}");
    // Severities are told apart in the session's table; an alarm row jumps the charts
    // to its moment; the recording can be downloaded.
    let severities = wait_js(
        &client,
        r#"(() => { const r = [...document.querySelectorAll('#session-alarms tr[data-severity]')].map(r => r.dataset.severity); return r.includes('alarm') && r.includes('warning') && r.join(','); })()"#,
        "an alarm and a warning in the session's table",
    )
    .await;
    println!("session rows by severity: {severities}");
    js(
        &client,
        r#"document.querySelector('#session-alarms [data-control="show-alarm"]').click(); return true;"#,
    )
    .await;
    wait_js(
        &client,
        r#"document.querySelector('#range-text').textContent.startsWith('showing t')"#,
        "the charts to zoom to the alarm's moment",
    )
    .await;
    let download = js(
        &client,
        r#"return !document.querySelector('#download-recording').hidden;"#,
    )
    .await;
    assert_eq!(
        download,
        json!(true),
        "a recording session offers its recording"
    );
    js(
        &client,
        r#"document.querySelector('#reset-zoom').click(); return true;"#,
    )
    .await;
    let shot = save_screenshot(&client, "dashboard-session.png").await;
    if let Some(path) = std::env::var_os("NAVGUARD_DASHBOARD_PNG") {
        std::fs::copy(&shot, path).unwrap();
    }

    // A view opened after the run draws the past from the 1 Hz history (the stream has
    // ended, so nothing live can fill the charts).
    client.goto(&format!("{http}/#/")).await.unwrap();
    client.refresh().await.unwrap();
    client
        .goto(&format!("{http}/#/session/ship"))
        .await
        .unwrap();
    let past = wait_js(
        &client,
        r#"(() => { const c = document.querySelector('canvas[data-monitor="federated"][data-test="gnss"]'); return c && Number(c.dataset.points) >= 100 && Number(c.dataset.points); })()"#,
        "the gnss chart to draw the history of the run",
    )
    .await;
    println!("gnss chart from the history: {past} points");

    // The link an operator bookmarks: a new tab opened straight on the session's URL. Its
    // view opens before the session list has arrived, and still draws the history: the
    // strip charts and the track plot hold the run's 1 Hz samples, not only the last
    // snapshot the events socket sends.
    let first_tab = client.window().await.unwrap();
    let tab = client.new_window(true).await.unwrap();
    client.switch_to_window(tab.handle).await.unwrap();
    client
        .goto(&format!("{http}/#/session/ship"))
        .await
        .unwrap();
    let bookmarked = wait_js(
        &client,
        r#"(() => { const c = document.querySelector('canvas[data-monitor="federated"][data-test="gnss"]'); return c && Number(c.dataset.points) >= 100 && Number(c.dataset.points); })()"#,
        "the gnss chart of a session URL opened directly to draw the history",
    )
    .await;
    let bookmarked_track = wait_js(
        &client,
        r#"(() => { const c = document.querySelector('canvas.track-chart[data-monitor="federated"]'); return c && Number(c.dataset.points) >= 100 && Number(c.dataset.points); })()"#,
        "the track plot of a session URL opened directly to draw the history",
    )
    .await;
    println!(
        "session URL opened directly: gnss chart {bookmarked} points, track {bookmarked_track} points"
    );
    client.close_window().await.unwrap();
    client.switch_to_window(first_tab).await.unwrap();

    // 4. Change the threshold through the controls; REST reports it.
    client
        .find(Locator::Css(
            r#"button[data-control="toggle"][data-monitor="federated"]"#,
        ))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    wait_js(
        &client,
        r#"document.querySelector('[data-control="applied"]')?.dataset.state === 'loaded'"#,
        "the controls to load the threshold in force",
    )
    .await;
    client
        .find(Locator::Css(r#"select[data-control="mode"]"#))
        .await
        .unwrap()
        .select_by_value("p_fa")
        .await
        .unwrap();
    let value = client
        .find(Locator::Css(r#"input[data-control="value"]"#))
        .await
        .unwrap();
    value.clear().await.unwrap();
    value.send_keys("0.0001").await.unwrap();
    // The live preview asks /api/v1/chi2/threshold: χ²(6) at p_fa 1e-4 is 27.86.
    let preview = wait_js(
        &client,
        r#"[...document.querySelectorAll('[data-preview]')].map(e => e.textContent).find(t => t.startsWith('gnss (dof 6)') && t.includes('27.86'))"#,
        "the preview of the GNSS threshold",
    )
    .await;
    println!("preview: {preview}");
    // The reason goes to the audit log (a browser sends `é` as ISO-8859-1).
    client
        .find(Locator::Css(r#"input[data-control="reason"]"#))
        .await
        .unwrap()
        .send_keys("quay multipath, café test")
        .await
        .unwrap();
    client
        .find(Locator::Css(r#"button[data-control="apply"]"#))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    let applied = wait_js(
        &client,
        r#"(() => { const p = document.querySelector('[data-control="applied"]'); return p.dataset.state === 'applied' && p.textContent; })()"#,
        "the controls to show the change applied",
    )
    .await;
    println!("{applied}");
    let view: Value = rest
        .get(format!(
            "{http}/api/v1/sessions/ship/monitors/federated/threshold"
        ))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(view["p_fa"], 0.0001, "{view}");
    assert_eq!(view["policy"]["kind"], "counters", "{view}");
    let gnss = view["tests"]["gnss"]["threshold"].as_f64().unwrap();
    // χ²(6) quantile at 1 − 1e-4 (scipy.stats.chi2.ppf(1 - 1e-4, 6) = 27.8563...).
    assert!((gnss - 27.856_3).abs() < 1e-3, "{view}");

    // 5. The alarm log page lists the persisted alarms.
    client.goto(&format!("{http}/#/alarms")).await.unwrap();
    wait_js(
        &client,
        r#"document.querySelectorAll('#alarms tr[data-session="ship"]').length > 0"#,
        "alarm rows on the alarms page",
    )
    .await;
    save_screenshot(&client, "dashboard-alarms.png").await;
    // An unacknowledged alarm is highlighted with its button; acknowledging it (the
    // prompt answered) shows who and why in its row, and the audit view lists it.
    let acked = wait_js(
        &client,
        r#"(() => {
             const r = document.querySelector('#alarms tr.unacked[data-session="ship"][data-severity="alarm"]');
             const b = r && r.querySelector('button[data-control="ack"]');
             if (!b) return null;
             window.prompt = () => 'checked by the browser test';
             b.click();
             return r.dataset.alarmId;
           })()"#,
        "an unacknowledged alarm with its Acknowledge button",
    )
    .await;
    let acked = acked.as_str().unwrap().to_owned();
    wait_js(
        &client,
        &format!(
            r#"(() => {{
                 const r = document.querySelector('#alarms tr[data-alarm-id="{acked}"]');
                 return r !== null && !r.classList.contains('unacked')
                   && r.textContent.includes('by anonymous') && r.textContent.includes('checked by the browser test');
               }})()"#
        ),
        "the acknowledgement in the alarm's row",
    )
    .await;
    client.goto(&format!("{http}/#/audit")).await.unwrap();
    wait_js(
        &client,
        r#"[...document.querySelectorAll('#audit tr[data-audit-id]')].some(r => r.textContent.includes('/alarms/{alarm_id}/ack') && r.textContent.includes('ship'))"#,
        "the acknowledgement in the audit view",
    )
    .await;
    wait_js(
        &client,
        r#"[...document.querySelectorAll('#audit tr[data-audit-id]')].some(r => r.textContent.includes('/threshold') && r.textContent.includes('quay multipath, café test'))"#,
        "the threshold change with its reason in the audit view",
    )
    .await;
    save_screenshot(&client, "dashboard-audit.png").await;

    // 6. Models page: a trained model is listed with its kind and can be
    // deleted, after which the page says "No models". Training must be accepted:
    // a server without the model API fails here rather than passing on "No models".
    let x: Vec<Vec<f64>> = (0..40).map(|i| vec![f64::from(i) / 10.0]).collect();
    let y: Vec<f64> = x.iter().map(|v| v[0].sin()).collect();
    let trained = rest
        .post(format!("{http}/api/v1/models"))
        .json(
            &json!({"kind": "lssvm", "name": "sine", "params": {"gamma": 10, "sigma2": 1},
                      "data": {"x": x, "y": y}}),
        )
        .send()
        .await
        .unwrap();
    let status = trained.status();
    let record: Value = trained.json().await.unwrap_or(Value::Null);
    assert_eq!(status, 202, "training a model: {record}");
    client.goto(&format!("{http}/#/models")).await.unwrap();
    let id = record["id"].as_str().unwrap().to_owned();
    let row = format!(r#"#models tr[data-model="{id}"]"#);
    let text = wait_js(
        &client,
        &format!(
            r#"(() => {{ const r = document.querySelector('{row}'); return r && r.dataset.status === 'ready' && r.textContent; }})()"#
        ),
        "the trained model's row",
    )
    .await;
    assert!(text.as_str().unwrap().contains("lssvm"), "{text}");
    assert!(text.as_str().unwrap().contains("sine"), "{text}");
    println!("models page lists {id}: {text}");
    save_screenshot(&client, "dashboard-models.png").await;
    client
        .find(Locator::Css(&format!(r#"button[data-model="{id}"]"#)))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    wait_js(
        &client,
        &format!(r#"!document.querySelector('{row}')"#),
        "the deleted model's row to go",
    )
    .await;
    let gone = rest
        .get(format!("{http}/api/v1/models/{id}"))
        .send()
        .await
        .unwrap();
    assert_eq!(gone.status(), 404);
    wait_js(
        &client,
        "!document.getElementById('no-models').hidden && document.getElementById('no-models').textContent.startsWith('No models')",
        "the emptied models page to say there are no models",
    )
    .await;

    // 7. Load: 10 monitors, 20 stats messages a second, 10 charts on screen.
    let created = rest
        .post(format!("{http}/api/v1/sessions"))
        .json(&load_session())
        .send()
        .await
        .unwrap();
    assert_eq!(created.status(), 201);
    client
        .goto(&format!("{http}/#/session/load"))
        .await
        .unwrap();
    wait_js(
        &client,
        "document.querySelectorAll('#session-monitors canvas').length === 10",
        "ten charts",
    )
    .await;
    js(&client, "window.navguardPerf(true); return null;").await;
    stream(
        format!("{ws}/api/v1/sessions/load/ingest"),
        load_frames(120),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let perf = js(&client, "return window.navguardPerf(false);").await;
    println!(
        "frame time with {LOAD_MONITORS} monitors at 20 stats/s (ms): render {} ; frame interval {} ; message handling {}",
        perf["frame"], perf["interval"], perf["message"]
    );
    assert!(perf["message"]["n"].as_u64().unwrap() > 10, "{perf}");
    assert!(perf["frame"]["n"].as_u64().unwrap() > 10, "{perf}");
    let drawn = js(
        &client,
        "return [...document.querySelectorAll('#session-monitors canvas')].every(c => Number(c.dataset.points) > 50);",
    )
    .await;
    assert_eq!(drawn, Value::Bool(true));
    save_screenshot(&client, "dashboard-load.png").await;

    // 8. The server restarts: the page reports it unreachable, then its
    // sockets reconnect (with backoff) and live updates flow again.
    client.goto(&format!("{http}/#/")).await.unwrap();
    wait_js(
        &client,
        r#"document.querySelectorAll('#sessions [data-session]').length === 2"#,
        "both sessions in the overview",
    )
    .await;
    save_screenshot(&client, "dashboard-overview.png").await;
    let addr = server.addr;
    let db = dir.path().join("t.db");
    server.shutdown().await;
    wait_js(
        &client,
        "document.getElementById('status').dataset.state === 'unreachable'",
        "the page to notice the server is gone",
    )
    .await;
    let server = restart(addr, &db, None).await;
    wait_js(
        &client,
        r#"document.querySelector('[data-session="load"]')?.dataset.live === 'live'"#,
        "the events socket to reconnect",
    )
    .await;
    // Frames every 100 ms until the page shows the new stream's epochs. (The
    // session publishes stats at most every 50 ms and has no trailing publish,
    // so the stats of a lone last frame can wait for the next frame.)
    let mut socket = common::connect(&format!("{ws}/api/v1/sessions/load/ingest")).await;
    let epochs = r#"Number(document.querySelector('[data-session="load"] dd[data-field="epochs"]')?.textContent)"#;
    let mut seen = 0.0;
    for k in 0..100 {
        common::send(&mut socket, &json!({"t": f64::from(k), "z": [0.5]})).await;
        tokio::time::sleep(Duration::from_millis(100)).await;
        seen = js(&client, &format!("return {epochs};"))
            .await
            .as_f64()
            .unwrap_or(0.0);
        if seen >= 1.0 {
            break;
        }
    }
    assert!(
        seen >= 1.0,
        "no stats from the restarted server reached the page"
    );
    socket.close(None).await.unwrap();
    server.shutdown().await;

    // 9. Back with a token: the page asks for it once, keeps it for the tab
    // (sessionStorage), and uses it on REST and sockets.
    let server = restart(addr, &db, Some("s3cret")).await;
    wait_js(
        &client,
        "!document.getElementById('auth').hidden",
        "the token prompt",
    )
    .await;
    client
        .find(Locator::Id("token"))
        .await
        .unwrap()
        .send_keys("s3cret")
        .await
        .unwrap();
    client
        .find(Locator::Css("#auth button"))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    wait_js(
        &client,
        r#"document.querySelector('[data-session="ship"]')?.dataset.live === 'live' && document.getElementById('status').dataset.state === 'ok'"#,
        "REST and sockets with the token",
    )
    .await;
    client.refresh().await.unwrap();
    wait_js(
        &client,
        r#"document.getElementById('status').dataset.state === 'ok' && document.getElementById('auth').hidden"#,
        "a reload to reuse the stored token without asking",
    )
    .await;
    assert_eq!(
        js(&client, "return sessionStorage.getItem('navguard.token');").await,
        "s3cret"
    );
    server.shutdown().await;

    // 10. A read-only token from a tokens file: the page names it and hides the
    // threshold controls, which it may not use.
    let tokens = dir.path().join("tokens.json");
    let hash = navguard::service::tokens::to_hex(&navguard::service::tokens::hash_secret("r3ad"));
    let entry = json!({"name": "wall-screen", "hash": hash, "scopes": ["read"]});
    std::fs::write(&tokens, json!({ "tokens": [entry] }).to_string()).unwrap();
    let mut config = navguard::service::ServiceConfig::new(addr, &db);
    config.token = Some("s3cret".into());
    config.tokens_file = Some(tokens);
    let server = navguard::service::start(config).await.expect("restarts");
    js(
        &client,
        "sessionStorage.setItem('navguard.token', 'r3ad'); return true;",
    )
    .await;
    client
        .goto(&format!("{http}/#/session/ship"))
        .await
        .unwrap();
    client.refresh().await.unwrap();
    wait_js(
        &client,
        r#"(() => {
             const b = document.querySelector('button[data-control="toggle"]');
             return b !== null && getComputedStyle(b).display === 'none'
               && document.getElementById('whoami').textContent.includes('wall-screen');
           })()"#,
        "the threshold controls hidden from a read-only token",
    )
    .await;
    client.goto(&format!("{http}/#/alarms")).await.unwrap();
    wait_js(
        &client,
        r#"(() => {
             const b = document.querySelector('#alarms button[data-control="ack"]');
             return b !== null && getComputedStyle(b).display === 'none';
           })()"#,
        "the Acknowledge buttons hidden from a read-only token",
    )
    .await;

    client.close().await.unwrap();
    server.shutdown().await;
}

/// The ingest frames of [`GNSS_FRAMES`], one JSON line each.
fn gnss_frames() -> Vec<String> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(GNSS_FRAMES);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (written by `navguard convert` from tests/data/gnss/gsdc)",
            path.display()
        )
    });
    text.lines()
        .filter(|line| !line.trim().is_empty())
        .map(str::to_owned)
        .collect()
}

/// A JS expression: the number a gnss canvas published as `dataset[field]`, null before it exists.
fn gnss_canvas(plot: &str, field: &str) -> String {
    format!(
        r#"(() => {{ const c = document.querySelector('canvas[data-monitor="gnss"][data-plot="{plot}"]'); return c ? Number(c.dataset.{field}) : null; }})()"#
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_draws_a_gnss_monitors_sky_plot_levels_and_stanford_diagram() {
    let Some((chromium, driver_path)) = browser_tools_or_skip() else {
        return;
    };
    let frames = gnss_frames();
    let dir = tempfile::tempdir().unwrap();
    let server = common::start(&dir.path().join("t.db"), None, Limits::default()).await;
    let http = common::http(&server);
    let ws = common::ws(&server);
    let created = reqwest::Client::new()
        .post(format!("{http}/api/v1/sessions"))
        .json(&json!({
            "id": "gnss",
            "monitors": [{"name": "gnss", "type": "gnss", "config": {}}],
        }))
        .send()
        .await
        .unwrap();
    assert_eq!(created.status(), 201, "{}", created.text().await.unwrap());

    let driver = start_driver(&driver_path).await;
    let profile = tempfile::tempdir().unwrap();
    let client = open_browser(&driver, &chromium, profile.path()).await;
    // As a user would: the overview lists the session, then its view opens.
    client.goto(&format!("{http}/")).await.unwrap();
    client
        .wait()
        .for_element(Locator::Css(r#"#sessions [data-session="gnss"]"#))
        .await
        .expect("the overview lists the gnss session");
    client
        .goto(&format!("{http}/#/session/gnss"))
        .await
        .unwrap();
    client
        .wait()
        .for_element(Locator::Css(
            r#"canvas[data-monitor="gnss"][data-plot="stanford"]"#,
        ))
        .await
        .expect("the gnss monitor's figures appear");
    stream_every(
        format!("{ws}/api/v1/sessions/gnss/ingest"),
        frames,
        GNSS_FRAME_PERIOD,
    )
    .await;

    // The last epoch's satellites on the sky plot (21 tracked in every epoch).
    let sky = wait_js(
        &client,
        &format!("{} >= 15 && {0}", gnss_canvas("sky", "points")),
        "the sky plot to draw at least 15 satellites",
    )
    .await;
    // One point per epoch with a solution; the Stanford diagram one per epoch with a truth too.
    let pl = wait_js(
        &client,
        &format!("{} >= 3 && {0}", gnss_canvas("pl", "points")),
        "the protection-level chart to draw at least 3 epochs",
    )
    .await;
    let stanford = wait_js(
        &client,
        &format!("{} >= 3 && {0}", gnss_canvas("stanford", "points")),
        "the Stanford diagram to hold at least 3 epochs",
    )
    .await;
    let regions = js(
        &client,
        r#"const d = document.querySelector('canvas[data-monitor="gnss"][data-plot="stanford"]').dataset;
           return {nominal: d.nominal, mi: d.mi, hmi: d.hmi, unavailable: d.unavailable};"#,
    )
    .await;
    // The HPL the caption shows is the latest epoch's, a finite number of metres.
    let hpl = js(
        &client,
        r#"const v = document.querySelector('[data-field="hpl"][data-monitor="gnss"]');
           return {value: v && v.dataset.value, text: v && v.textContent};"#,
    )
    .await;
    println!(
        "gnss: sky {sky} satellites, PL {pl} epochs, Stanford {stanford} epochs {regions}, {hpl}"
    );
    let value: f64 = hpl["value"]
        .as_str()
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN);
    assert!(value.is_finite() && value > 0.0, "{hpl}");
    save_screenshot(&client, "dashboard-gnss.png").await;

    // Opened afresh after the run, the view draws the same figures from the history
    // (levels, Stanford points) and the current stats (the latest satellites).
    client.goto("about:blank").await.unwrap();
    client
        .goto(&format!("{http}/#/session/gnss"))
        .await
        .unwrap();
    let sky_again = wait_js(
        &client,
        &format!("{} >= 15 && {0}", gnss_canvas("sky", "points")),
        "the reopened view's sky plot to draw the latest satellites",
    )
    .await;
    let stanford_again = wait_js(
        &client,
        &format!("{} >= 3 && {0}", gnss_canvas("stanford", "points")),
        "the reopened view's Stanford diagram to hold the history's epochs",
    )
    .await;
    assert_eq!(sky_again, sky, "the same latest epoch");
    println!("reopened: sky {sky_again} satellites, Stanford {stanford_again} epochs");

    client.close().await.unwrap();
    server.shutdown().await;
}

/// A still vehicle's raw IMU at 100 Hz from `t0` for `seconds`: gravity up, no
/// rotation; with `fixes`, a still GNSS fix every 100th epoch (1 Hz, the first
/// at `t0`). Frames of 10 epochs.
fn still_imu_frames(t0: f64, seconds: usize, fixes: bool) -> Vec<String> {
    (0..seconds * 100)
        .map(|k| {
            let t = t0 + k as f64 / 100.0;
            let mut epoch = json!({"t": t, "imu": {"f": [0.0, 0.0, 9.80], "w": [0.0, 0.0, 0.0]}});
            if fixes && k % 100 == 0 {
                epoch["gnss"] =
                    json!({"lat": 40.0, "lon": -105.0, "h": 1600.0, "vel": [0.0, 0.0, 0.0]});
            }
            epoch
        })
        .collect::<Vec<Value>>()
        .chunks(10)
        .map(|chunk| Value::from(chunk.to_vec()).to_string())
        .collect()
}

/// A JS expression: the alignment badge of `monitor` as `{state, text}`, null before it exists.
fn alignment_badge(monitor: &str) -> String {
    format!(
        r#"(() => {{ const b = document.querySelector('[data-kind="alignment"][data-monitor="{monitor}"]'); return b && {{state: b.dataset.state, text: b.textContent}}; }})()"#
    )
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_shows_the_alignment_of_a_federated_monitor_on_raw_imu() {
    let Some((chromium, driver_path)) = browser_tools_or_skip() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let server = common::start(&dir.path().join("t.db"), None, Limits::default()).await;
    let http = common::http(&server);
    let ws = common::ws(&server);
    // "level" finds its heading from the GNSS speed, so a still vehicle keeps it
    // levelling; "heading" is given one, so it aligns once levelled at a fix.
    let monitor = |name: &str, align: Value| {
        json!({"name": name, "type": "federated",
               "config": {"aids": ["gnss"], "input": "imu", "strapdown": {"align": align}}})
    };
    let created = reqwest::Client::new()
        .post(format!("{http}/api/v1/sessions"))
        .json(&json!({
            "id": "imu",
            "monitors": [
                monitor("level", json!({"static_s": 2})),
                monitor("heading", json!({"static_s": 2, "heading_deg": 30})),
            ],
        }))
        .send()
        .await
        .unwrap();
    assert_eq!(created.status(), 201, "{}", created.text().await.unwrap());

    let driver = start_driver(&driver_path).await;
    let profile = tempfile::tempdir().unwrap();
    let client = open_browser(&driver, &chromium, profile.path()).await;
    client.goto(&format!("{http}/#/session/imu")).await.unwrap();

    // 1. Three still seconds without a fix: no solution, nothing aligns, and both
    // monitors' stats say levelling (a fix is needed to place the mechanization).
    stream_every(
        format!("{ws}/api/v1/sessions/imu/ingest"),
        still_imu_frames(0.0, 3, false),
        Duration::from_millis(20),
    )
    .await;
    let heading = wait_js(
        &client,
        &format!(
            "{} && {0}.state === 'levelling' && {0}",
            alignment_badge("heading")
        ),
        "the heading monitor's badge to say levelling",
    )
    .await;
    let level = wait_js(
        &client,
        &format!(
            "{} && {0}.state === 'levelling' && {0}",
            alignment_badge("level")
        ),
        "the level monitor's badge to say levelling",
    )
    .await;
    println!("no fix yet: heading {heading}, level {level}");
    assert_eq!(
        heading["text"],
        "levelling \u{2014} waiting for a still vehicle and a GNSS fix"
    );
    assert_eq!(
        level["text"],
        "levelling \u{2014} waiting for a still vehicle and a GNSS fix"
    );
    // While aligning the protection level is not known: a dash, never "null" or "NaN".
    let hpl = wait_js(
        &client,
        r#"(() => { const f = document.querySelector('section[data-monitor="level"] figure.hpl figcaption'); return f && f.textContent.includes('converging') && f.textContent; })()"#,
        "the level monitor's HPL caption",
    )
    .await;
    println!("aligning HPL caption: {hpl}");
    let hpl = hpl.as_str().unwrap();
    assert!(hpl.contains("HPL \u{2014} / HAL"), "{hpl}");
    assert!(!hpl.contains("null") && !hpl.contains("NaN"), "{hpl}");

    // 2. Three more still seconds with a fix each second: the given heading aligns at
    // the first fix, and its one track is the mechanized solution; the other, levelled
    // but never moving, stays levelling (it starts when the vehicle moves off).
    stream_every(
        format!("{ws}/api/v1/sessions/imu/ingest"),
        still_imu_frames(3.0, 3, true),
        Duration::from_millis(20),
    )
    .await;
    let aligned = wait_js(
        &client,
        &format!(
            "{} && {0}.state === 'aligned' && {0}",
            alignment_badge("heading")
        ),
        "the heading monitor's badge to say aligned",
    )
    .await;
    assert_eq!(aligned["text"], "aligned", "{aligned}");
    let track = wait_js(
        &client,
        r#"(() => { const c = document.querySelector('canvas.track-chart[data-monitor="heading"]'); return c && Number(c.dataset.points) >= 2 && {points: Number(c.dataset.points), lines: c.dataset.lines, legend: c.dataset.legend}; })()"#,
        "the heading monitor's track",
    )
    .await;
    println!("aligned: {aligned}, track {track}");
    assert_eq!(track["lines"], "1", "{track}");
    assert_eq!(track["legend"], "mechanized solution", "{track}");
    let level = js(&client, &format!("return {};", alignment_badge("level"))).await;
    assert_eq!(level["state"], "levelling", "{level}");
    let level_track = js(
        &client,
        r#"return Number(document.querySelector('canvas.track-chart[data-monitor="level"]').dataset.points);"#,
    )
    .await;
    assert_eq!(
        level_track, 0,
        "a still vehicle without a heading has no solution"
    );
    // The aligned monitor's badge and mechanized track on screen.
    js(
        &client,
        r#"document.querySelector('section[data-monitor="heading"] figure.track').scrollIntoView({block: 'center'}); return null;"#,
    )
    .await;
    save_screenshot(&client, "dashboard-imu.png").await;

    client.close().await.unwrap();
    server.shutdown().await;
}

/// A server on the same address and store as before (sessions persist).
async fn restart(
    addr: std::net::SocketAddr,
    db: &Path,
    token: Option<&str>,
) -> navguard::service::Server {
    let mut config = navguard::service::ServiceConfig::new(addr, db);
    config.token = token.map(str::to_owned);
    navguard::service::start(config)
        .await
        .expect("the server restarts on its old address")
}
