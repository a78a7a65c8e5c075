//! What each route needs (docs/architecture.md §A5): the one table `auth::authorize`
//! consults, beside `app::ROUTES`. A route of `ROUTES` missing here fails a unit test
//! (and, were it served, would need `admin`); `tests/scopes.rs` checks the table
//! against the server and against the scopes the OpenAPI contract declares.

use super::tokens::Scope;

/// What a route needs from its caller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// No token (the dashboard's files, liveness, metrics).
    Public,
    /// Any valid token, whatever its scopes (`whoami`).
    Authenticated,
    /// A valid token holding this scope (or `admin`).
    Scope(Scope),
}

impl Access {
    /// The value of the route's `x-navguard-scope` in the OpenAPI contract.
    pub fn as_str(self) -> &'static str {
        match self {
            Access::Public => "public",
            Access::Authenticated => "authenticated",
            Access::Scope(s) => s.as_str(),
        }
    }
}

/// Where a route names the session a session-limited token must be allowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SessionRef {
    /// Not about one session (models, χ², whoami).
    None,
    /// The `{id}` segment after `/api/v1/sessions/`.
    Path,
    /// The `session` query parameter, which a session-limited token must give.
    Query,
    /// A list of sessions: the handler leaves out the ones the token may not see.
    Listed,
}

use Access::{Authenticated, Public, Scope as S};
use Scope::{Admin, Ingest, Operate, Read};

/// Every (path, method) of `app::ROUTES` with what it needs.
pub const ROUTE_ACCESS: &[(&str, &str, Access, SessionRef)] = &[
    ("/", "GET", Public, SessionRef::None),
    ("/static/{file}", "GET", Public, SessionRef::None),
    ("/healthz", "GET", Public, SessionRef::None),
    ("/metrics", "GET", Public, SessionRef::None),
    ("/api/v1/whoami", "GET", Authenticated, SessionRef::None),
    ("/api/v1/sessions", "GET", S(Read), SessionRef::Listed),
    ("/api/v1/sessions", "POST", S(Admin), SessionRef::None),
    ("/api/v1/sessions/{id}", "GET", S(Read), SessionRef::Path),
    (
        "/api/v1/sessions/{id}",
        "DELETE",
        S(Admin),
        SessionRef::Path,
    ),
    (
        "/api/v1/sessions/{id}/stats",
        "GET",
        S(Read),
        SessionRef::Path,
    ),
    (
        "/api/v1/sessions/{id}/history",
        "GET",
        S(Read),
        SessionRef::Path,
    ),
    (
        "/api/v1/sessions/{id}/recording",
        "GET",
        S(Read),
        SessionRef::Path,
    ),
    (
        "/api/v1/sessions/{id}/calibration",
        "GET",
        S(Read),
        SessionRef::Path,
    ),
    (
        "/api/v1/sessions/{id}/monitors/{name}/threshold",
        "GET",
        S(Read),
        SessionRef::Path,
    ),
    (
        "/api/v1/sessions/{id}/monitors/{name}/threshold",
        "PUT",
        S(Operate),
        SessionRef::Path,
    ),
    (
        "/api/v1/sessions/{id}/ingest",
        "GET",
        S(Ingest),
        SessionRef::Path,
    ),
    (
        "/api/v1/sessions/{id}/events",
        "GET",
        S(Read),
        SessionRef::Path,
    ),
    ("/api/v1/chi2/threshold", "GET", S(Read), SessionRef::None),
    (
        "/api/v1/chi2/missed-detection",
        "GET",
        S(Read),
        SessionRef::None,
    ),
    ("/api/v1/alarms", "GET", S(Read), SessionRef::Query),
    (
        "/api/v1/sessions/{id}/alarms/{alarm_id}/ack",
        "POST",
        S(Operate),
        SessionRef::Path,
    ),
    ("/api/v1/audit", "GET", S(Read), SessionRef::Listed),
    ("/api/v1/models", "GET", S(Read), SessionRef::None),
    ("/api/v1/models", "POST", S(Admin), SessionRef::None),
    ("/api/v1/models/{id}", "GET", S(Read), SessionRef::None),
    ("/api/v1/models/{id}", "DELETE", S(Admin), SessionRef::None),
    (
        "/api/v1/models/{id}/predict",
        "POST",
        S(Read),
        SessionRef::None,
    ),
    ("/api/v1/features", "POST", S(Read), SessionRef::None),
];

/// What `method` on the route `path` (as the router matched it) needs. `HEAD` needs
/// what `GET` needs (the router answers it with the `GET` handler). A method the
/// route does not serve needs only a valid token (the router answers it 405); a
/// served route missing from the table needs `admin`.
pub fn access(path: &str, method: &str) -> (Access, SessionRef) {
    let method = if method == "HEAD" { "GET" } else { method };
    if let Some(&(_, _, a, s)) = ROUTE_ACCESS
        .iter()
        .find(|(p, m, _, _)| *p == path && *m == method)
    {
        return (a, s);
    }
    let served = super::app::ROUTES
        .iter()
        .any(|(p, methods)| *p == path && methods.contains(&method));
    if served {
        (S(Admin), SessionRef::None)
    } else if path.starts_with("/api/") {
        (Authenticated, SessionRef::None)
    } else {
        (Public, SessionRef::None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::app::ROUTES;

    #[test]
    fn every_route_and_method_has_exactly_one_entry() {
        for (path, methods) in ROUTES {
            for method in *methods {
                let n = ROUTE_ACCESS
                    .iter()
                    .filter(|(p, m, _, _)| p == path && m == method)
                    .count();
                assert_eq!(n, 1, "{method} {path} needs one entry in ROUTE_ACCESS");
            }
        }
        for (path, method, _, _) in ROUTE_ACCESS {
            assert!(
                ROUTES
                    .iter()
                    .any(|(p, ms)| p == path && ms.contains(method)),
                "{method} {path} is in ROUTE_ACCESS but not in ROUTES"
            );
        }
    }

    #[test]
    fn only_the_dashboard_liveness_and_metrics_are_public() {
        for (path, method, a, _) in ROUTE_ACCESS {
            assert_eq!(*a == Public, !path.starts_with("/api/"), "{method} {path}");
        }
    }

    #[test]
    fn session_routes_name_their_session_in_the_path() {
        for (path, method, _, s) in ROUTE_ACCESS {
            let by_path = path.starts_with("/api/v1/sessions/{id}");
            assert_eq!(*s == SessionRef::Path, by_path, "{method} {path}");
        }
    }

    #[test]
    fn head_is_get_and_unserved_methods_need_only_a_token() {
        assert_eq!(
            access("/api/v1/sessions", "HEAD"),
            access("/api/v1/sessions", "GET")
        );
        assert_eq!(
            access("/api/v1/sessions", "PATCH"),
            (Authenticated, SessionRef::None)
        );
        assert_eq!(access("/nowhere", "GET"), (Public, SessionRef::None));
    }
}
