//! Tokens: hashing, the file format and its refusals, lookup, expiry and reloads.
use super::*;

/// FIPS 180-2 appendix B.1: SHA-256("abc").
const ABC: &str = "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad";

fn entry(name: &str, secret: &str, scopes: &[&str]) -> serde_json::Value {
    serde_json::json!({"name": name, "hash": to_hex(&hash_secret(secret)), "scopes": scopes})
}

fn parse(v: serde_json::Value) -> Result<Vec<Known>, TokensError> {
    parse_file("t.json", &v.to_string())
}

#[test]
fn the_hash_is_sha256_as_fips_180_2_gives_it() {
    assert_eq!(to_hex(&hash_secret("abc")), ABC);
    assert_eq!(
        to_hex(&hash_secret("")),
        "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
    );
    assert_eq!(digest_from_hex(ABC), Some(hash_secret("abc")));
    assert_eq!(
        digest_from_hex(&ABC.to_uppercase()),
        Some(hash_secret("abc"))
    );
    assert_eq!(digest_from_hex(&ABC[1..]), None);
    assert_eq!(digest_from_hex(&format!("{}zz", &ABC[2..])), None);
    assert_eq!(digest_from_hex(&"é".repeat(32)), None);
}

#[test]
fn digests_compare_equal_only_when_every_byte_is_equal() {
    let a = hash_secret("s3cret");
    let mut b = a;
    assert!(bool::from(a.ct_eq(&b)));
    b[31] ^= 1;
    assert!(!bool::from(a.ct_eq(&b)));
    b = a;
    b[0] ^= 0x80;
    assert!(!bool::from(a.ct_eq(&b)));
}

#[test]
fn the_default_token_has_every_scope_and_a_wrong_secret_none() {
    let t = Tokens::new(Some("s3cret"), None).unwrap();
    assert!(t.required());
    let Lookup::Valid(p) = t.lookup("s3cret", 0) else {
        panic!("the token is known")
    };
    assert_eq!(p.name, DEFAULT_TOKEN_NAME);
    assert_eq!(p.effective_scopes(), Scope::ALL.to_vec());
    assert_eq!(t.lookup("s3cre", 0), Lookup::Unknown);
    assert!(!Tokens::new(None, None).unwrap().required());
}

#[test]
fn admin_implies_every_scope_and_the_others_only_themselves() {
    let mut p = Principal::anonymous();
    p.scopes = vec![Scope::Read];
    assert!(p.allows(Scope::Read));
    assert!(!p.allows(Scope::Operate) && !p.allows(Scope::Ingest) && !p.allows(Scope::Admin));
    p.scopes = vec![Scope::Admin];
    assert!(Scope::ALL.iter().all(|s| p.allows(*s)));
}

#[test]
fn session_patterns_match_ids_and_prefixes() {
    let f = SessionFilter::parse(&["veh-*".into(), "cart-1".into()]).unwrap();
    assert!(f.allows("veh-1") && f.allows("veh-") && f.allows("cart-1"));
    assert!(!f.allows("cart-10") && !f.allows("ve") && !f.allows("xveh-1"));
    assert_eq!(f.patterns(), vec!["cart-1", "veh-*"]);
    assert!(SessionFilter::parse(&["*".into()]).unwrap().allows("any"));
    assert!(SessionFilter::parse(&["a*b".into()]).is_err());
    assert!(SessionFilter::parse(&["a**".into()]).is_err());
    assert!(SessionFilter::parse(&["".into()]).is_err());
}

#[test]
fn a_file_entry_carries_scopes_sessions_and_expiry() {
    let mut e = entry("veh", "v", &["ingest", "read", "ingest"]);
    e["sessions"] = serde_json::json!(["veh-*"]);
    e["expires"] = serde_json::json!("2030-01-01T00:00:00Z");
    let known = parse(serde_json::json!({"tokens": [e]})).unwrap();
    let p = &known[0].principal;
    assert_eq!(p.scopes, vec![Scope::Ingest, Scope::Read]);
    assert!(p.allows_session("veh-7") && !p.allows_session("car-1"));
    assert_eq!(p.expires_ms, Some(1_893_456_000_000));
}

#[test]
fn bad_files_name_the_entry_and_field() {
    let cases = [
        (serde_json::json!({"tokens": [{"name": "a"}]}), "tokens[0]"),
        (serde_json::json!({"tokens": [], "extra": 1}), "extra"),
        (
            serde_json::json!({"tokens": [entry("a", "x", &["root"])]}),
            "tokens[0].scopes[0]",
        ),
        (
            serde_json::json!({"tokens": [entry("a", "x", &[])]}),
            "tokens[0].scopes",
        ),
        (
            serde_json::json!({"tokens": [{"name": "a", "hash": "abc", "scopes": ["read"]}]}),
            "tokens[0].hash",
        ),
        (
            serde_json::json!({"tokens": [entry("a", "x", &["read"]), entry("a", "y", &["read"])]}),
            "tokens[1].name",
        ),
        (
            serde_json::json!({"tokens": [entry("a", "x", &["read"]), entry("b", "x", &["read"])]}),
            "tokens[1].hash",
        ),
        (
            serde_json::json!({"tokens": [entry(" ", "x", &["read"])]}),
            "tokens[0].name",
        ),
    ];
    for (doc, at) in cases {
        let err = parse(doc.clone()).unwrap_err().to_string();
        assert!(err.contains(at), "{doc}: {err}");
    }
    let mut e = entry("a", "x", &["read"]);
    e["expires"] = serde_json::json!("tomorrow");
    let err = parse(serde_json::json!({"tokens": [e]})).unwrap_err();
    assert!(err.to_string().contains("tokens[0].expires"), "{err}");
    let err = parse_file("t.json", "{not json").unwrap_err();
    assert!(err.to_string().starts_with("t.json:"), "{err}");
}

#[test]
fn an_expired_token_is_told_apart_from_an_unknown_one() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tokens.json");
    let mut e = entry("old", "o", &["read"]);
    e["expires"] = serde_json::json!("2020-01-01T00:00:00+01:00");
    std::fs::write(&path, serde_json::json!({"tokens": [e]}).to_string()).unwrap();
    let t = Tokens::new(None, Some(&path)).unwrap();
    let before = 1_577_833_200_000 - 1;
    assert!(matches!(t.lookup("o", before), Lookup::Valid(_)));
    assert_eq!(t.lookup("o", before + 1), Lookup::Expired("old".into()));
    assert_eq!(t.lookup("x", before), Lookup::Unknown);
}

#[test]
fn a_bad_file_on_reload_keeps_the_tokens_read_before() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tokens.json");
    let write = |v: serde_json::Value| std::fs::write(&path, v.to_string()).unwrap();
    write(serde_json::json!({"tokens": [entry("a", "one", &["read"])]}));
    let t = Tokens::new(Some("d"), Some(&path)).unwrap();
    std::fs::write(&path, "{\"tokens\": [").unwrap();
    t.reload();
    assert!(matches!(t.lookup("one", 0), Lookup::Valid(_)));
    write(serde_json::json!({"tokens": [entry("b", "two", &["read"])]}));
    t.reload();
    assert_eq!(t.lookup("one", 0), Lookup::Unknown);
    assert!(matches!(t.lookup("two", 0), Lookup::Valid(_)));
    assert!(matches!(t.lookup("d", 0), Lookup::Valid(_)));
    std::fs::remove_file(&path).unwrap();
    t.reload();
    assert!(matches!(t.lookup("two", 0), Lookup::Valid(_)));
    assert!(Tokens::new(None, Some(&path)).is_err());
}
