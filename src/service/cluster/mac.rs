//! Authenticated bus messages (docs/deployment.md, Securing a cluster). With a cluster key,
//! every message a node publishes on NATS (events, statistics, node calls and their
//! answers) carries an HMAC-SHA256 in `Navguard-Mac`, over the subject, the sender, the
//! send time, the event headers and the payload; a receiving node checks it in constant
//! time and drops a message without a valid one. [`Keyring`] is pure (no I/O; the caller
//! passes the time); [`seal`] reads the clock for it.
//!
//! What is covered, each length-prefixed so that no two messages encode alike:
//! a domain label, the subject, then `Navguard-Sender`, `Navguard-Time`,
//! `Navguard-Epoch`, `Navguard-Seq` and `Navguard-End` (each absent or present with its
//! value), then the payload. The time bounds replay: a message older (or newer) than
//! [`MAX_SKEW_MS`] is refused, so a copied message cannot be sent again later.

use async_nats::HeaderMap;
use hmac::{Hmac, Mac};
use sha2::Sha256;

use super::bus::{END_HEADER, EPOCH_HEADER, SEQ_HEADER};
use crate::service::tokens::to_hex;

/// Header: the MAC, 64 lowercase hex digits.
pub const MAC_HEADER: &str = "Navguard-Mac";
/// Header: the publishing node's id.
pub const SENDER_HEADER: &str = "Navguard-Sender";
/// Header: when the message was sealed, Unix ms.
pub const TIME_HEADER: &str = "Navguard-Time";

/// A sealed message is accepted up to this far from the receiver's clock (the nodes'
/// clocks already agree far closer than this: leases compare them).
pub const MAX_SKEW_MS: i64 = 60_000;

/// Shortest key, bytes (the HMAC-SHA256 block is 64; 32 random bytes are its strength).
pub const MIN_KEY_BYTES: usize = 32;

/// Most keys in a ring (the signing one and those still accepted during a rotation).
pub const MAX_KEYS: usize = 4;

/// Separates this MAC from any other use of the same key.
const DOMAIN: &[u8] = b"navguard-bus-v1";

type HmacSha256 = Hmac<Sha256>;

/// Why a key ring was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    /// No key in the text.
    #[error("the cluster key is empty")]
    Empty,
    /// A key is shorter than [`MIN_KEY_BYTES`] (its position, 1-based).
    #[error("cluster key {0} is shorter than {MIN_KEY_BYTES} bytes")]
    Short(usize),
    /// More than [`MAX_KEYS`] keys.
    #[error("more than {MAX_KEYS} cluster keys")]
    TooMany,
}

/// Why a message was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum MacError {
    /// No `Navguard-Mac` header (an unsigned message).
    #[error("no MAC")]
    Missing,
    /// The MAC header is not 64 hex digits, or matches no key.
    #[error("bad MAC")]
    Bad,
    /// The MAC is right but the send time is missing or further than
    /// [`MAX_SKEW_MS`] from now (a replayed or badly clocked message).
    #[error("stale or undated message")]
    Stale,
}

/// The cluster keys: the first signs, every one verifies (so a new key can be added to
/// every node before any node signs with it). Never printed.
#[derive(Clone)]
pub struct Keyring {
    keys: Vec<Vec<u8>>,
}

impl std::fmt::Debug for Keyring {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Keyring({} keys, REDACTED)", self.keys.len())
    }
}

impl Keyring {
    /// Keys from text: separated by whitespace (a key file's lines), the first signing.
    /// Each key is used as its bytes; at least [`MIN_KEY_BYTES`] each.
    pub fn parse(text: &str) -> Result<Self, KeyError> {
        let keys: Vec<Vec<u8>> = text
            .split_whitespace()
            .map(|k| k.as_bytes().to_vec())
            .collect();
        if keys.is_empty() {
            return Err(KeyError::Empty);
        }
        if keys.len() > MAX_KEYS {
            return Err(KeyError::TooMany);
        }
        if let Some(i) = keys.iter().position(|k| k.len() < MIN_KEY_BYTES) {
            return Err(KeyError::Short(i + 1));
        }
        Ok(Keyring { keys })
    }

    /// Adds `Navguard-Sender`, `Navguard-Time` and `Navguard-Mac` to `headers` for a
    /// message of `payload` on `subject`.
    pub fn seal(
        &self,
        subject: &str,
        headers: &mut HeaderMap,
        payload: &[u8],
        sender: &str,
        now_ms: i64,
    ) {
        headers.insert(SENDER_HEADER, sender);
        headers.insert(TIME_HEADER, now_ms.to_string().as_str());
        let tag = tag(&self.keys[0], subject, headers, payload);
        headers.insert(MAC_HEADER, to_hex(&tag).as_str());
    }

    /// Checks a received message: its MAC under any key of the ring (in constant time),
    /// then its send time against `now_ms`.
    pub fn verify(
        &self,
        subject: &str,
        headers: Option<&HeaderMap>,
        payload: &[u8],
        now_ms: i64,
    ) -> Result<(), MacError> {
        let headers = headers.ok_or(MacError::Missing)?;
        let text = headers.get(MAC_HEADER).ok_or(MacError::Missing)?;
        let given = from_hex(text.as_str()).ok_or(MacError::Bad)?;
        // Every key is tried, so the time taken does not say which one matched.
        let mut matched = false;
        for key in &self.keys {
            matched |= mac(key, subject, headers, payload)
                .verify_slice(&given)
                .is_ok();
        }
        if !matched {
            return Err(MacError::Bad);
        }
        let sent: i64 = headers
            .get(TIME_HEADER)
            .and_then(|t| t.as_str().parse().ok())
            .ok_or(MacError::Stale)?;
        if sent.abs_diff(now_ms) > MAX_SKEW_MS as u64 {
            return Err(MacError::Stale);
        }
        Ok(())
    }
}

/// The headers to publish a message with: with a key ring, `headers` (or new ones) with
/// the sender, the time now and the MAC added; without, `headers` as they are.
pub fn seal(
    keyring: Option<&Keyring>,
    sender: &str,
    subject: &str,
    headers: Option<HeaderMap>,
    payload: &[u8],
) -> Option<HeaderMap> {
    let Some(ring) = keyring else {
        return headers;
    };
    let mut headers = headers.unwrap_or_default();
    ring.seal(
        subject,
        &mut headers,
        payload,
        sender,
        crate::service::now_ms(),
    );
    Some(headers)
}

/// The HMAC state over a message's covered parts (module docs).
fn mac(key: &[u8], subject: &str, headers: &HeaderMap, payload: &[u8]) -> HmacSha256 {
    // HMAC takes a key of any length (RFC 2104 §2): `new_from_slice` cannot fail.
    let mut m = <HmacSha256 as Mac>::new_from_slice(key).unwrap_or_else(|_| unreachable!());
    let mut field = |bytes: &[u8]| {
        m.update(&(bytes.len() as u64).to_be_bytes());
        m.update(bytes);
    };
    field(DOMAIN);
    field(subject.as_bytes());
    for name in [
        SENDER_HEADER,
        TIME_HEADER,
        EPOCH_HEADER,
        SEQ_HEADER,
        END_HEADER,
    ] {
        match headers.get(name) {
            None => field(b"-"),
            Some(v) => field(format!("+{}", v.as_str()).as_bytes()),
        }
    }
    field(payload);
    m
}

/// 64 hex digits (either case) as 32 bytes; `None` for anything else.
fn from_hex(text: &str) -> Option<[u8; 32]> {
    let digits = text.as_bytes();
    if digits.len() != 64 {
        return None;
    }
    let mut out = [0u8; 32];
    for (byte, pair) in out.iter_mut().zip(digits.chunks_exact(2)) {
        let hi = char::from(pair[0]).to_digit(16)?;
        let lo = char::from(pair[1]).to_digit(16)?;
        *byte = (hi * 16 + lo) as u8;
    }
    Some(out)
}

fn tag(key: &[u8], subject: &str, headers: &HeaderMap, payload: &[u8]) -> [u8; 32] {
    mac(key, subject, headers, payload)
        .finalize()
        .into_bytes()
        .into()
}

#[cfg(test)]
mod tests {
    use super::*;

    const KEY: &str = "0123456789abcdef0123456789abcdef";
    const NOW: i64 = 1_800_000_000_000;

    fn sealed() -> (Keyring, HeaderMap) {
        let ring = Keyring::parse(KEY).unwrap();
        let mut h = HeaderMap::new();
        h.insert(EPOCH_HEADER, "3");
        h.insert(SEQ_HEADER, "17");
        ring.seal(
            "navguard.events.s1",
            &mut h,
            b"{\"type\":\"alarm\"}",
            "node1",
            NOW,
        );
        (ring, h)
    }

    #[test]
    fn hmac_sha256_matches_rfc_4231_test_case_2() {
        let mut m = <HmacSha256 as Mac>::new_from_slice(b"Jefe").unwrap();
        m.update(b"what do ya want for nothing?");
        assert_eq!(
            to_hex(&m.finalize().into_bytes()),
            "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"
        );
    }

    #[test]
    fn hmac_sha256_matches_rfc_4231_test_case_6_with_a_key_longer_than_a_block() {
        let mut m = <HmacSha256 as Mac>::new_from_slice(&[0xaa; 131]).unwrap();
        m.update(b"Test Using Larger Than Block-Size Key - Hash Key First");
        assert_eq!(
            to_hex(&m.finalize().into_bytes()),
            "60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54"
        );
    }

    #[test]
    fn a_sealed_message_verifies() {
        let (ring, h) = sealed();
        let payload = b"{\"type\":\"alarm\"}";
        assert_eq!(
            ring.verify("navguard.events.s1", Some(&h), payload, NOW + 1000),
            Ok(())
        );
    }

    #[test]
    fn a_changed_subject_header_or_payload_is_refused() {
        let (ring, h) = sealed();
        let payload: &[u8] = b"{\"type\":\"alarm\"}";
        let verify = |subject: &str, h: &HeaderMap, p: &[u8]| ring.verify(subject, Some(h), p, NOW);
        assert_eq!(
            verify("navguard.events.s2", &h, payload),
            Err(MacError::Bad)
        );
        assert_eq!(
            verify("navguard.events.s1", &h, b"{\"type\":\"alarm\" }"),
            Err(MacError::Bad)
        );
        for (name, value) in [
            (EPOCH_HEADER, "4"),
            (SEQ_HEADER, "18"),
            (SENDER_HEADER, "node2"),
            (TIME_HEADER, &(NOW + 1).to_string()),
            (END_HEADER, "deleted"),
        ] {
            let mut changed = h.clone();
            changed.insert(name, value);
            assert_eq!(
                verify("navguard.events.s1", &changed, payload),
                Err(MacError::Bad),
                "{name} changed"
            );
        }
        let mut flipped = h.clone();
        let mut mac = h.get(MAC_HEADER).unwrap().as_str().to_owned();
        let last = if mac.ends_with('0') { "1" } else { "0" };
        mac.replace_range(63.., last);
        flipped.insert(MAC_HEADER, mac.as_str());
        assert_eq!(
            verify("navguard.events.s1", &flipped, payload),
            Err(MacError::Bad)
        );
    }

    #[test]
    fn an_unsigned_or_garbled_message_is_refused_without_panicking() {
        let (ring, _) = sealed();
        assert_eq!(ring.verify("s", None, b"", NOW), Err(MacError::Missing));
        let mut h = HeaderMap::new();
        h.insert(EPOCH_HEADER, "1");
        h.insert(SEQ_HEADER, "1");
        assert_eq!(ring.verify("s", Some(&h), b"", NOW), Err(MacError::Missing));
        for garbage in [
            "",
            "zz",
            "00",
            &"g".repeat(64),
            &"0".repeat(66),
            &"+f".repeat(32),
            "é",
        ] {
            h.insert(MAC_HEADER, garbage);
            assert_eq!(
                ring.verify("s", Some(&h), b"", NOW),
                Err(MacError::Bad),
                "{garbage:?}"
            );
        }
    }

    #[test]
    fn an_old_message_is_refused_as_stale() {
        let (ring, h) = sealed();
        let payload = b"{\"type\":\"alarm\"}";
        let later = NOW + MAX_SKEW_MS + 1;
        assert_eq!(
            ring.verify("navguard.events.s1", Some(&h), payload, later),
            Err(MacError::Stale)
        );
    }

    #[test]
    fn another_key_is_refused_and_a_ring_accepts_its_older_keys() {
        let (_, h) = sealed();
        let payload = b"{\"type\":\"alarm\"}";
        let other = Keyring::parse("ffffffffffffffffffffffffffffffff").unwrap();
        assert_eq!(
            other.verify("navguard.events.s1", Some(&h), payload, NOW),
            Err(MacError::Bad)
        );
        let rotating = Keyring::parse(&format!("{} {KEY}", "f".repeat(32))).unwrap();
        assert_eq!(
            rotating.verify("navguard.events.s1", Some(&h), payload, NOW),
            Ok(())
        );
    }

    #[test]
    fn short_empty_and_too_many_keys_are_refused_and_never_printed() {
        assert_eq!(Keyring::parse(" \n").unwrap_err(), KeyError::Empty);
        assert_eq!(
            Keyring::parse(&format!("{KEY} short")).unwrap_err(),
            KeyError::Short(2)
        );
        let five = [KEY; 5].join("\n");
        assert_eq!(Keyring::parse(&five).unwrap_err(), KeyError::TooMany);
        let ring = Keyring::parse(KEY).unwrap();
        assert!(!format!("{ring:?}").contains(KEY));
    }
}
