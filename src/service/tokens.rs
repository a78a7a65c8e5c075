//! Who may call what: the bearer tokens the server knows, each with its scopes and,
//! optionally, the sessions it is limited to (docs/architecture.md §A5). Tokens come
//! from `--token` (one token with every scope, named `default`) and from the tokens
//! file (`--tokens-file`), which is read again when it changes. Only SHA-256 digests
//! of the secrets are kept, and they are compared in constant time.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant, SystemTime};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

/// The name `--token` is known by.
pub const DEFAULT_TOKEN_NAME: &str = "default";

/// How often, at most, a request makes the server look at the tokens file's mtime.
const RELOAD_CHECK: Duration = Duration::from_secs(1);

/// What a token may do. `Admin` implies the other three; the others imply nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Scope {
    /// Stream epochs into sessions (the ingest socket).
    Ingest,
    /// Read sessions, statistics, events, alarms, recordings, history, models.
    Read,
    /// Change how sessions decide: thresholds, policies, alarm levels.
    Operate,
    /// Everything: create and delete sessions and models, and all of the above.
    Admin,
}

impl Scope {
    /// Every scope, in the order they are listed.
    pub const ALL: [Scope; 4] = [Scope::Ingest, Scope::Read, Scope::Operate, Scope::Admin];

    /// The scope's name on the wire and in the tokens file.
    pub fn as_str(self) -> &'static str {
        match self {
            Scope::Ingest => "ingest",
            Scope::Read => "read",
            Scope::Operate => "operate",
            Scope::Admin => "admin",
        }
    }

    /// The scope named `name`, if any.
    pub fn parse(name: &str) -> Option<Scope> {
        Scope::ALL.into_iter().find(|s| s.as_str() == name)
    }
}

impl std::fmt::Display for Scope {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The SHA-256 digest of a secret.
pub fn hash_secret(secret: &str) -> [u8; 32] {
    Sha256::digest(secret.as_bytes()).into()
}

/// Lower-case hex of `bytes`.
pub fn to_hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// A 64-digit hex SHA-256 digest (either case).
fn digest_from_hex(hex: &str) -> Option<[u8; 32]> {
    if hex.len() != 64 || !hex.is_ascii() {
        return None;
    }
    let mut out = [0u8; 32];
    for (i, byte) in out.iter_mut().enumerate() {
        *byte = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok()?;
    }
    Some(out)
}

/// The sessions a token may address: exact ids, and prefixes written `"veh-*"`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SessionFilter {
    exact: Vec<String>,
    prefixes: Vec<String>,
}

impl SessionFilter {
    /// Reads `["veh-1", "veh-*"]`; `*` is allowed only at the end.
    fn parse(patterns: &[String]) -> Result<SessionFilter, String> {
        let mut filter = SessionFilter {
            exact: Vec::new(),
            prefixes: Vec::new(),
        };
        for p in patterns {
            match p.strip_suffix('*') {
                _ if p.is_empty() => return Err("an empty session pattern".into()),
                Some(prefix) if !prefix.contains('*') => filter.prefixes.push(prefix.to_owned()),
                None if !p.contains('*') => filter.exact.push(p.clone()),
                _ => return Err(format!("'{p}': '*' may only end a pattern")),
            }
        }
        Ok(filter)
    }

    /// True when the token may address session `id`.
    pub fn allows(&self, id: &str) -> bool {
        self.exact.iter().any(|e| e == id) || self.prefixes.iter().any(|p| id.starts_with(p))
    }

    /// The patterns, as written in the file.
    pub fn patterns(&self) -> Vec<String> {
        let prefixes = self.prefixes.iter().map(|p| format!("{p}*"));
        self.exact.iter().cloned().chain(prefixes).collect()
    }
}

/// The caller a request was authenticated as; handlers read it from the request's
/// extensions.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Principal {
    /// The token's name (`default` for `--token`, `anonymous` when the server has no tokens).
    pub name: String,
    /// The scopes as granted (`admin` implies the others: see [`Principal::allows`]).
    pub scopes: Vec<Scope>,
    /// The sessions it is limited to; `None`: every session.
    pub sessions: Option<SessionFilter>,
    /// When it stops being accepted, Unix milliseconds.
    pub expires_ms: Option<i64>,
}

impl Principal {
    /// Every scope, every session: the caller of a server without tokens.
    pub fn anonymous() -> Principal {
        Principal {
            name: "anonymous".into(),
            scopes: vec![Scope::Admin],
            sessions: None,
            expires_ms: None,
        }
    }

    /// True when the token holds `scope` (or `admin`).
    pub fn allows(&self, scope: Scope) -> bool {
        self.scopes.contains(&scope) || self.scopes.contains(&Scope::Admin)
    }

    /// Every scope the token may use, `admin` expanded.
    pub fn effective_scopes(&self) -> Vec<Scope> {
        Scope::ALL.into_iter().filter(|s| self.allows(*s)).collect()
    }

    /// True when the token may address session `id`.
    pub fn allows_session(&self, id: &str) -> bool {
        self.sessions.as_ref().is_none_or(|f| f.allows(id))
    }
}

/// One entry of the tokens file, as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TokenEntry {
    /// Who holds the token (shown by `whoami` and in logs; never the secret).
    pub name: String,
    /// Hex SHA-256 of the secret.
    pub hash: String,
    /// `ingest`, `read`, `operate`, `admin`.
    pub scopes: Vec<String>,
    /// Session ids and `prefix*` patterns the token is limited to; absent: all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sessions: Option<Vec<String>>,
    /// RFC 3339 time after which the token is refused; absent: never.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expires: Option<String>,
}

impl TokenEntry {
    /// Checks the entry as the server would read it: `Err` names the field and why.
    pub fn check(&self) -> Result<(), String> {
        parse_entry(0, self)
            .map(|_| ())
            .map_err(|(at, reason)| format!("{}: {reason}", at.trim_start_matches("tokens[0].")))
    }
}

/// The tokens file: `{"tokens": [TokenEntry, …]}`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TokensFile {
    /// The entries.
    pub tokens: Vec<TokenEntry>,
}

/// Why a tokens file (or `--token`) was refused.
#[derive(Debug, thiserror::Error)]
pub enum TokensError {
    /// The file could not be read.
    #[error("reading {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a valid tokens file; `at` names the entry or field.
    #[error("{path}: {at}: {reason}")]
    Invalid {
        /// The file.
        path: String,
        /// Where in the file (`tokens[2].scopes[0]`, or the JSON position).
        at: String,
        /// Why.
        reason: String,
    },
}

/// A token the server accepts: its digest and who it is.
#[derive(Debug, Clone)]
struct Known {
    digest: [u8; 32],
    principal: Principal,
}

fn parse_entry(i: usize, e: &TokenEntry) -> Result<Known, (String, String)> {
    let at = |field: &str| format!("tokens[{i}].{field}");
    if e.name.trim().is_empty() || e.name.len() > 64 || e.name.chars().any(char::is_control) {
        return Err((
            at("name"),
            "must be 1-64 printable characters, not blank".into(),
        ));
    }
    let digest = digest_from_hex(&e.hash).ok_or_else(|| {
        (
            at("hash"),
            "must be the 64 hex digits of the secret's SHA-256 (`navguard token hash`)".into(),
        )
    })?;
    if e.scopes.is_empty() {
        return Err((at("scopes"), "must name at least one scope".into()));
    }
    let mut scopes = Vec::new();
    for (j, s) in e.scopes.iter().enumerate() {
        let scope = Scope::parse(s).ok_or_else(|| {
            (
                at(&format!("scopes[{j}]")),
                format!("unknown scope '{s}': one of ingest, read, operate, admin"),
            )
        })?;
        if !scopes.contains(&scope) {
            scopes.push(scope);
        }
    }
    scopes.sort();
    let sessions = match &e.sessions {
        Some(list) if list.is_empty() => {
            return Err((
                at("sessions"),
                "an empty list allows no session; leave it out for all".into(),
            ));
        }
        Some(list) => Some(SessionFilter::parse(list).map_err(|r| (at("sessions"), r))?),
        None => None,
    };
    let expires_ms = match &e.expires {
        Some(t) => Some(
            chrono::DateTime::parse_from_rfc3339(t)
                .map_err(|err| (at("expires"), format!("not an RFC 3339 time: {err}")))?
                .timestamp_millis(),
        ),
        None => None,
    };
    Ok(Known {
        digest,
        principal: Principal {
            name: e.name.clone(),
            scopes,
            sessions,
            expires_ms,
        },
    })
}

/// Parses and checks a tokens file's text (`path` only names it in errors).
fn parse_file(path: &str, text: &str) -> Result<Vec<Known>, TokensError> {
    let invalid = |at: String, reason: String| TokensError::Invalid {
        path: path.to_owned(),
        at,
        reason,
    };
    let mut de = serde_json::Deserializer::from_str(text);
    let file: TokensFile = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let at = e.path().to_string();
        // serde_json's message carries a line and column, never the file's text.
        invalid(at, e.into_inner().to_string())
    })?;
    let mut known: Vec<Known> = Vec::new();
    for (i, entry) in file.tokens.iter().enumerate() {
        let k = parse_entry(i, entry).map_err(|(at, reason)| invalid(at, reason))?;
        if known.iter().any(|o| o.principal.name == k.principal.name) {
            return Err(invalid(
                format!("tokens[{i}].name"),
                format!("'{}' is used twice", k.principal.name),
            ));
        }
        if known.iter().any(|o| bool::from(o.digest.ct_eq(&k.digest))) {
            return Err(invalid(
                format!("tokens[{i}].hash"),
                "the same secret as another entry".into(),
            ));
        }
        known.push(k);
    }
    Ok(known)
}

/// What the tokens file held when last read, and when the server last looked.
#[derive(Debug)]
struct FileState {
    tokens: Vec<Known>,
    /// The modification time and length of the file as last read (`None`: unreadable).
    seen: Option<(SystemTime, u64)>,
    last_check: Instant,
}

/// The tokens the server accepts (`AppState::tokens`).
#[derive(Debug)]
pub struct Tokens {
    /// `--token`, as a digest.
    default: Option<Known>,
    /// `--tokens-file` and what it held.
    file: Option<(PathBuf, Mutex<FileState>)>,
}

/// The outcome of looking a presented secret up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Lookup {
    /// A known token, in date.
    Valid(Principal),
    /// A known token past its `expires`.
    Expired(String),
    /// No token has this secret.
    Unknown,
}

fn stamp(path: &Path) -> Option<(SystemTime, u64)> {
    let meta = std::fs::metadata(path).ok()?;
    Some((meta.modified().ok()?, meta.len()))
}

fn read_file(path: &Path) -> Result<Vec<Known>, TokensError> {
    let text = std::fs::read_to_string(path).map_err(|source| TokensError::Read {
        path: path.display().to_string(),
        source,
    })?;
    parse_file(&path.display().to_string(), &text)
}

impl Tokens {
    /// The tokens of `--token` (all scopes) and `--tokens-file`; a bad file is an error.
    pub fn new(token: Option<&str>, file: Option<&Path>) -> Result<Tokens, TokensError> {
        let default = token.map(|t| Known {
            digest: hash_secret(t),
            principal: Principal {
                name: DEFAULT_TOKEN_NAME.into(),
                scopes: vec![Scope::Admin],
                sessions: None,
                expires_ms: None,
            },
        });
        let file = match file {
            Some(path) => {
                let seen = stamp(path);
                let tokens = read_file(path)?;
                let state = FileState {
                    tokens,
                    seen,
                    last_check: Instant::now(),
                };
                Some((path.to_path_buf(), Mutex::new(state)))
            }
            None => None,
        };
        Ok(Tokens { default, file })
    }

    /// True when requests need a token (`--token` or a tokens file was given).
    pub fn required(&self) -> bool {
        self.default.is_some() || self.file.is_some()
    }

    /// Finds the token whose secret is `secret`, reading the file again first when it
    /// changed (looked at no more than once a second).
    pub fn lookup(&self, secret: &str, now_ms: i64) -> Lookup {
        self.reload_if_changed();
        let digest = hash_secret(secret);
        // Every digest is compared, in constant time, whichever matches.
        let mut found: Option<Principal> = None;
        if let Some(d) = &self.default
            && bool::from(d.digest.ct_eq(&digest))
        {
            found = Some(d.principal.clone());
        }
        if let Some((_, state)) = &self.file {
            let state = state.lock().unwrap_or_else(|p| p.into_inner());
            for k in &state.tokens {
                if bool::from(k.digest.ct_eq(&digest)) && found.is_none() {
                    found = Some(k.principal.clone());
                }
            }
        }
        match found {
            Some(p) if p.expires_ms.is_some_and(|e| now_ms >= e) => Lookup::Expired(p.name),
            Some(p) => Lookup::Valid(p),
            None => Lookup::Unknown,
        }
    }

    /// Reads the file again if its mtime or length changed since the last read, at
    /// most once a second.
    fn reload_if_changed(&self) {
        let Some((path, state)) = &self.file else {
            return;
        };
        let seen = {
            let mut s = state.lock().unwrap_or_else(|p| p.into_inner());
            if s.last_check.elapsed() < RELOAD_CHECK {
                return;
            }
            s.last_check = Instant::now();
            s.seen
        };
        // The stat (and, rarely, the read) happen outside the lock.
        let now = stamp(path);
        if now.is_some() && now != seen {
            self.reload_from(path, state, now);
        }
    }

    /// Reads the file now (SIGHUP). A bad file keeps the tokens read before.
    pub fn reload(&self) {
        if let Some((path, state)) = &self.file {
            self.reload_from(path, state, stamp(path));
        }
    }

    fn reload_from(&self, path: &Path, state: &Mutex<FileState>, seen: Option<(SystemTime, u64)>) {
        let result = read_file(path);
        let mut s = state.lock().unwrap_or_else(|p| p.into_inner());
        // Remembered either way, so a bad file is reported once per change.
        s.seen = seen;
        match result {
            Ok(tokens) => {
                tracing::info!(path = %path.display(), tokens = tokens.len(), "tokens file read");
                s.tokens = tokens;
            }
            Err(e) => {
                tracing::error!(error = %e, "tokens file refused; keeping the tokens read before");
            }
        }
    }
}

#[cfg(test)]
mod tests;
