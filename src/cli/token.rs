//! `navguard token`: issues tokens for the tokens file (docs/deployment.md, Tokens and
//! scopes). `hash` prints the SHA-256 of a secret read from stdin; `new` makes a random
//! secret and prints it once, with the file entry that holds only its hash.

use std::io::Read;

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use navguard::service::tokens::{TokenEntry, hash_secret, to_hex};
use rand::RngCore;

/// `navguard token …`
#[derive(Debug, Subcommand)]
pub(crate) enum TokenCommand {
    /// Read a secret from stdin (one trailing newline ignored) and print its hex SHA-256.
    Hash,
    /// Make a random secret; print it (once: it is stored nowhere) and then the tokens-file entry.
    New(NewArgs),
}

/// `navguard token new`
#[derive(Debug, Args)]
pub(crate) struct NewArgs {
    /// The token's name (shown by /api/v1/whoami and in logs).
    #[arg(long)]
    name: String,
    /// Comma-separated scopes: ingest, read, operate, admin.
    #[arg(long, value_delimiter = ',', required = true)]
    scopes: Vec<String>,
    /// Comma-separated session ids and `prefix*` patterns the token is limited to.
    #[arg(long, value_delimiter = ',')]
    sessions: Option<Vec<String>>,
    /// RFC 3339 time after which the token is refused, e.g. 2026-01-01T00:00:00Z.
    #[arg(long)]
    expires: Option<String>,
}

/// A secret read from stdin: one trailing `\n` or `\r\n` removed, and refused if blank
/// or padded with whitespace, as the server refuses such a `--token`.
fn secret_from(mut text: String) -> anyhow::Result<String> {
    if text.ends_with('\n') {
        text.pop();
        if text.ends_with('\r') {
            text.pop();
        }
    }
    if text.trim().is_empty() {
        bail!("the secret on stdin is blank");
    }
    if text.trim() != text {
        bail!("the secret on stdin is padded with whitespace (a header could never carry it)");
    }
    Ok(text)
}

/// A new secret: 32 bytes from the thread's CSPRNG (ChaCha, seeded by the OS), in hex.
fn new_secret() -> String {
    let mut bytes = [0u8; 32];
    rand::rng().fill_bytes(&mut bytes);
    format!("ngt_{}", to_hex(&bytes))
}

/// Runs `navguard token …`.
pub(crate) fn run(command: TokenCommand) -> anyhow::Result<()> {
    match command {
        TokenCommand::Hash => {
            let mut text = String::new();
            std::io::stdin()
                .read_to_string(&mut text)
                .context("reading the secret from stdin")?;
            println!("{}", to_hex(&hash_secret(&secret_from(text)?)));
        }
        TokenCommand::New(args) => {
            let secret = new_secret();
            let entry = TokenEntry {
                name: args.name,
                hash: to_hex(&hash_secret(&secret)),
                scopes: args.scopes,
                sessions: args.sessions,
                expires: args.expires,
            };
            if let Err(e) = entry.check() {
                bail!("{e}");
            }
            println!("{secret}");
            println!("{}", serde_json::to_string(&entry)?);
            eprintln!(
                "The first line is the secret: give it to the token's holder; it is shown only this once. \
                 Add the second line to the \"tokens\" list of the tokens file."
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_trailing_newline_is_dropped_and_padding_refused() {
        assert_eq!(secret_from("abc\n".into()).unwrap(), "abc");
        assert_eq!(secret_from("abc\r\n".into()).unwrap(), "abc");
        assert_eq!(secret_from("abc".into()).unwrap(), "abc");
        assert!(secret_from("abc\n\n".into()).is_err());
        assert!(secret_from(" abc".into()).is_err());
        assert!(secret_from("\n".into()).is_err());
    }

    #[test]
    fn new_secrets_differ_and_are_url_safe() {
        let (a, b) = (new_secret(), new_secret());
        assert_ne!(a, b);
        assert_eq!(a.len(), 4 + 64);
        assert!(a.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_'));
    }
}
