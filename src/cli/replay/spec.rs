//! The session a replay streams to: used as it is when it exists, otherwise
//! created with the `POST /api/v1/sessions` body the flags and the file call for
//! (`SPEC_HELP` says how the monitor is chosen).

use anyhow::{Context, bail};
use navguard::service::wire::{CreateSession, MonitorSpecWire};
use navguard_core::detect::PolicyConfig;
use navguard_core::epoch::Aid;
use navguard_core::monitor::MonitorKind;
use navguard_core::monitor::federated::FederatedConfigWire;
use serde_json::Value;

use super::input::FileScan;
use super::{PolicyArg, ReplayArgs};
use crate::cli::http::Endpoint;

/// Creates the session unless it exists. Returns true when created.
pub(super) async fn ensure_session(
    endpoint: &Endpoint,
    args: &ReplayArgs,
    scan: &FileScan,
    path: &str,
) -> anyhow::Result<bool> {
    let (status, body) = endpoint.call("GET", path).await?;
    match status {
        200 => {
            if args.session_spec.is_some() || args.monitor_config.is_some() {
                eprintln!(
                    "session '{}' exists: using it as it is (the given spec is ignored)",
                    args.session
                );
            }
            return Ok(false);
        }
        404 => {}
        401 => bail!("{}: unauthorized; pass --token", endpoint.http_base()),
        s => bail!("GET {path}: HTTP {s}: {body}"),
    }
    let spec = session_body(args, scan)?;
    let (status, body) = endpoint
        .request("POST", "/api/v1/sessions", Some(&spec))
        .await?;
    match status {
        201 => Ok(true),
        // Someone created it between our GET and POST: use theirs.
        409 => Ok(false),
        s => bail!("creating session '{}': HTTP {s}: {body}", args.session),
    }
}

/// Reads inline JSON or `@file`.
fn json_arg(text: &str, what: &str) -> anyhow::Result<Value> {
    let (source, body) = match text.strip_prefix('@') {
        Some(path) => (
            path.to_owned(),
            std::fs::read_to_string(path).with_context(|| format!("reading {what} {path}"))?,
        ),
        None => ("the command line".to_owned(), text.to_owned()),
    };
    serde_json::from_str(&body).with_context(|| format!("{what} from {source} is not JSON"))
}

/// The `POST /api/v1/sessions` body for a new session (see `SPEC_HELP`).
pub(super) fn session_body(args: &ReplayArgs, scan: &FileScan) -> anyhow::Result<CreateSession> {
    if let Some(path) = &args.session_spec {
        return spec_file(path, &args.session);
    }
    let (kind, config) = monitor_config(args, scan)?;
    let policy = match args.policy.unwrap_or(PolicyArg::Counters) {
        PolicyArg::Classic => PolicyConfig::Classic,
        PolicyArg::Counters => PolicyConfig::Counters {
            n1: args.n1,
            n2: args.n2,
        },
    };
    let monitor = MonitorSpecWire {
        name: kind.as_str().to_owned(),
        kind,
        config,
        policy,
        p_fa: args.p_fa,
        threshold: args.threshold,
        alarm_level: None,
        tests: Default::default(),
    };
    Ok(CreateSession {
        id: Some(args.session.clone()),
        monitors: vec![monitor],
        echo: false,
        alarm_level: None,
        record: None,
    })
}

/// `--session-spec FILE`: the whole body, its `id` set to `session` (or already it).
fn spec_file(path: &std::path::Path, session: &str) -> anyhow::Result<CreateSession> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading --session-spec {}", path.display()))?;
    let mut body: CreateSession = serde_json::from_str(&text).with_context(|| {
        format!(
            "--session-spec {} is not a POST /api/v1/sessions body",
            path.display()
        )
    })?;
    match &body.id {
        Some(id) if id != session => {
            bail!("--session-spec names session '{id}' but --session is '{session}'")
        }
        _ => body.id = Some(session.to_owned()),
    }
    Ok(body)
}

/// The one monitor's type and config: `federated` for a file with `ins` (over the
/// aids it holds unless `--monitor-config` says otherwise) or with `imu` and no `ins`
/// (`input: imu`, its GNSS aid, the strapdown defaults unless `--monitor-config`),
/// `gnss` for `gnss_raw` (its defaults unless `--monitor-config`), `linear` for `z`.
fn monitor_config(args: &ReplayArgs, scan: &FileScan) -> anyhow::Result<(MonitorKind, Value)> {
    if scan.imu && !scan.ins {
        let config = match &args.monitor_config {
            Some(text) => json_arg(text, "--monitor-config")?,
            None if scan.gnss => serde_json::json!({"aids": ["gnss"], "input": "imu"}),
            None => bail!(
                "the file has `imu` blocks but no `gnss`: the strapdown needs a GNSS fix to align (give --monitor-config for other aids)"
            ),
        };
        return Ok((MonitorKind::Federated, config));
    }
    if scan.gnss_raw && !scan.ins {
        let config = match &args.monitor_config {
            Some(text) => json_arg(text, "--monitor-config")?,
            None => Value::Object(Default::default()),
        };
        return Ok((MonitorKind::Gnss, config));
    }
    if scan.ins {
        let config = match &args.monitor_config {
            Some(text) => json_arg(text, "--monitor-config")?,
            None => {
                let aids: Vec<Aid> = [
                    (Aid::Gnss, scan.gnss),
                    (Aid::Dvl, scan.dvl),
                    (Aid::Cns, scan.cns),
                ]
                .into_iter()
                .filter_map(|(name, present)| present.then_some(name))
                .collect();
                if aids.is_empty() {
                    bail!(
                        "the file has `ins` blocks but no gnss, dvl or cns: nothing to aid the INS with"
                    );
                }
                federated_config(aids)?
            }
        };
        Ok((MonitorKind::Federated, config))
    } else if scan.z {
        let text = args.monitor_config.as_deref().context(
            "the file has `z` blocks: a `linear` monitor needs --monitor-config (its f, h, q, r, x0, p0)",
        )?;
        Ok((MonitorKind::Linear, json_arg(text, "--monitor-config")?))
    } else {
        bail!(
            "cannot tell which monitor the file needs (no `ins`, `gnss_raw` or `z` blocks): give --session-spec"
        );
    }
}

/// The `federated` config with these aids and every other field at its default
/// (written out, so the body says which values the monitor runs with).
fn federated_config(aids: Vec<Aid>) -> anyhow::Result<Value> {
    serde_json::to_value(FederatedConfigWire::new(aids)).context("serialising the federated config")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::replay::tests::args;

    #[test]
    fn a_file_with_pseudoranges_gets_a_gnss_monitor() {
        let scan = FileScan {
            epochs: 3,
            gnss_raw: true,
            ..FileScan::default()
        };
        let body = session_body(&args(&["--policy", "classic"]), &scan).unwrap();
        assert_eq!(body.monitors[0].kind, MonitorKind::Gnss);
        assert_eq!(body.monitors[0].name, "gnss");
        assert_eq!(body.monitors[0].config, serde_json::json!({}));
    }

    #[test]
    fn a_file_with_raw_imu_gets_a_federated_monitor_on_its_imu() {
        let scan = FileScan {
            epochs: 3,
            imu: true,
            gnss: true,
            ..FileScan::default()
        };
        let body = session_body(&args(&[]), &scan).unwrap();
        assert_eq!(body.monitors[0].kind, MonitorKind::Federated);
        assert_eq!(
            body.monitors[0].config,
            serde_json::json!({"aids": ["gnss"], "input": "imu"})
        );
        let no_fix = FileScan {
            gnss: false,
            ..scan
        };
        let err = session_body(&args(&[]), &no_fix).unwrap_err().to_string();
        assert!(err.contains("no `gnss`"), "{err}");
    }

    #[test]
    fn a_file_with_ins_gets_a_federated_monitor_over_its_aids() {
        let scan = FileScan {
            epochs: 3,
            ins: true,
            gnss: true,
            cns: true,
            ..FileScan::default()
        };
        let body = session_body(&args(&["--threshold", "20"]), &scan).unwrap();
        assert_eq!(body.id.as_deref(), Some("s1"));
        let m = &body.monitors[0];
        assert_eq!(
            (m.name.as_str(), m.kind),
            ("federated", MonitorKind::Federated)
        );
        let config: FederatedConfigWire = serde_json::from_value(m.config.clone()).unwrap();
        assert_eq!(config, FederatedConfigWire::new(vec![Aid::Gnss, Aid::Cns]));
        // The monitor runs exactly as it would on the bare aids list.
        let parse = navguard_core::monitor::federated::FederatedConfig::from_json;
        assert_eq!(
            parse(&m.config).unwrap(),
            parse(&serde_json::json!({"aids": ["gnss", "cns"]})).unwrap()
        );
        assert_eq!(m.policy, PolicyConfig::Counters { n1: 10, n2: 5 });
        assert_eq!((m.threshold, m.p_fa), (Some(20.0), None));
        let body = session_body(&args(&["--policy", "classic"]), &scan).unwrap();
        assert_eq!(body.monitors[0].policy, PolicyConfig::Classic);
        assert_eq!(body.monitors[0].threshold, None);
    }

    #[test]
    fn a_linear_file_needs_its_model() {
        let scan = FileScan {
            epochs: 3,
            z: true,
            ..FileScan::default()
        };
        assert!(session_body(&args(&[]), &scan).is_err());
        let body = session_body(
            &args(&[
                "--monitor-config",
                r#"{"f":[[1]],"h":[[1]],"q":[[1]],"r":[[1]],"x0":[0],"p0":[[1]]}"#,
            ]),
            &scan,
        )
        .unwrap();
        assert_eq!(body.monitors[0].kind, MonitorKind::Linear);
        let wire = serde_json::to_value(&body).unwrap();
        assert_eq!(wire["monitors"][0]["config"]["f"], serde_json::json!([[1]]));
        assert_eq!(wire["monitors"][0]["type"], "linear");
        assert!(session_body(&args(&[]), &FileScan::default()).is_err());
    }
}
