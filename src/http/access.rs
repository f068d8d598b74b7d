//! Access control by API key. With no key configured the API is open. With keys, every
//! state-changing request (POST, PUT, PATCH, DELETE) needs `Authorization: Bearer <key>`,
//! and reads too when `protect_reads` is set; the probes, `/metrics` and the dashboard's page
//! and assets (which hold no data) stay public.
//!
//! Only SHA-256 digests of the keys are kept. A presented key is hashed and compared with
//! every configured digest in constant time, without stopping at a match, so the response
//! time tells nothing about how much of a key was right or which key matched.

use std::path::Path;

use anyhow::Context;
use axum::extract::{Request, State};
use axum::http::{Method, header};
use axum::middleware::Next;
use axum::response::Response;
use sha2::{Digest, Sha256};
use subtle::{Choice, ConstantTimeEq};

use super::error::ApiError;
use crate::config::Config;

/// The environment variable of the key list, named in errors.
pub const KEYS_VARIABLE: &str = "AORTAGEN_API_KEYS";

/// Paths answered without a key whatever the configuration (orchestrators and scrapers).
pub const PUBLIC_PATHS: [&str; 3] = ["/healthz", "/readyz", "/metrics"];

/// The configured keys (as digests) and what they protect.
#[derive(Clone, Default)]
pub struct AccessPolicy {
    digests: Vec<[u8; 32]>,
    protect_reads: bool,
}

impl std::fmt::Debug for AccessPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AccessPolicy")
            .field("keys", &self.digests.len())
            .field("protect_reads", &self.protect_reads)
            .finish()
    }
}

/// Whether a request may proceed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// No key needed, or a configured key was presented.
    Allow,
    /// A key is needed and none (or no well-formed bearer credential) was sent.
    Missing,
    /// A bearer credential was sent but it is no configured key.
    Wrong,
}

impl AccessPolicy {
    /// Keys from the flag/environment list and the keys file. A key list that is given but
    /// holds only blanks or commas (`AORTAGEN_API_KEYS=""`, a template left unfilled), or a
    /// keys file that is configured but unreadable or empty, is an error: the service must
    /// not start open when its operator meant it to be closed.
    pub fn from_config(config: &Config) -> anyhow::Result<Self> {
        let mut keys: Vec<String> = config
            .api_keys
            .iter()
            .map(|k| k.expose().trim().to_owned())
            .filter(|k| !k.is_empty())
            .collect();
        anyhow::ensure!(
            config.api_keys.is_empty() || !keys.is_empty(),
            "{KEYS_VARIABLE} (--api-keys) is set but holds no key, only blanks or commas; \
             the service would run without access control. Give at least one key, or unset \
             {KEYS_VARIABLE} to run open on purpose"
        );
        if let Some(path) = &config.api_keys_file {
            let from_file = read_keys_file(path)?;
            anyhow::ensure!(
                !from_file.is_empty(),
                "the API keys file {} holds no key",
                path.display()
            );
            keys.extend(from_file);
        }
        Ok(Self::new(keys, config.protect_reads))
    }

    /// A policy from plain keys.
    pub fn new<S: AsRef<str>>(keys: impl IntoIterator<Item = S>, protect_reads: bool) -> Self {
        let digests = keys
            .into_iter()
            .map(|k| Sha256::digest(k.as_ref().as_bytes()).into())
            .collect();
        Self {
            digests,
            protect_reads,
        }
    }

    /// Whether any key is configured.
    pub fn is_enabled(&self) -> bool {
        !self.digests.is_empty()
    }

    /// Whether reads need a key too.
    pub fn protects_reads(&self) -> bool {
        self.protect_reads
    }

    /// Decides on a request from its method, path and `Authorization` header.
    pub fn decide(&self, method: &Method, path: &str, authorization: Option<&[u8]>) -> Decision {
        let public = PUBLIC_PATHS.contains(&path) || super::dashboard::is_public(path);
        if !self.is_enabled() || public {
            return Decision::Allow;
        }
        let writes = matches!(
            *method,
            Method::POST | Method::PUT | Method::PATCH | Method::DELETE
        );
        if !writes && !self.protect_reads {
            return Decision::Allow;
        }
        let Some(key) = authorization.and_then(bearer_token) else {
            return Decision::Missing;
        };
        if self.matches(key) {
            Decision::Allow
        } else {
            Decision::Wrong
        }
    }

    /// Compares the key's digest with every configured digest, without an early exit.
    fn matches(&self, key: &[u8]) -> bool {
        let presented: [u8; 32] = Sha256::digest(key).into();
        let mut found = Choice::from(0);
        for digest in &self.digests {
            found |= digest[..].ct_eq(&presented[..]);
        }
        found.into()
    }
}

/// The token of an `Authorization: Bearer <token>` header (scheme case-insensitive).
fn bearer_token(value: &[u8]) -> Option<&[u8]> {
    let (scheme, rest) = value.split_at_checked(7)?;
    if !scheme.eq_ignore_ascii_case(b"bearer ") {
        return None;
    }
    let token = rest.trim_ascii();
    (!token.is_empty()).then_some(token)
}

fn read_keys_file(path: &Path) -> anyhow::Result<Vec<String>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the API keys file {}", path.display()))?;
    Ok(text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(str::to_owned)
        .collect())
}

/// The middleware: answers 401 or 403 before the handler (and before any body is read).
pub async fn require_key(
    State(policy): State<std::sync::Arc<AccessPolicy>>,
    req: Request,
    next: Next,
) -> Response {
    let authorization = req
        .headers()
        .get(header::AUTHORIZATION)
        .map(|v| v.as_bytes());
    match policy.decide(req.method(), req.uri().path(), authorization) {
        Decision::Allow => next.run(req).await,
        Decision::Missing => axum::response::IntoResponse::into_response(ApiError::Unauthorized),
        Decision::Wrong => axum::response::IntoResponse::into_response(ApiError::Forbidden),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy(protect_reads: bool) -> AccessPolicy {
        AccessPolicy::new(["first-key", "second-key"], protect_reads)
    }

    #[test]
    fn without_keys_everything_is_allowed() {
        let open = AccessPolicy::new(Vec::<String>::new(), true);
        assert_eq!(
            open.decide(&Method::DELETE, "/v1/cohorts/1", None),
            Decision::Allow
        );
    }

    #[test]
    fn writes_need_a_configured_bearer_key() {
        let p = policy(false);
        let d =
            |auth: Option<&str>| p.decide(&Method::POST, "/v1/cohorts", auth.map(str::as_bytes));
        assert_eq!(d(None), Decision::Missing);
        assert_eq!(d(Some("Basic Zm9vOmJhcg==")), Decision::Missing);
        assert_eq!(d(Some("Bearer ")), Decision::Missing);
        assert_eq!(d(Some("Bearer first-ke")), Decision::Wrong);
        assert_eq!(d(Some("Bearer first-key")), Decision::Allow);
        assert_eq!(d(Some("bearer second-key")), Decision::Allow);
    }

    #[test]
    fn reads_are_public_unless_protected_and_probes_always() {
        assert_eq!(
            policy(false).decide(&Method::GET, "/v1/cohorts", None),
            Decision::Allow
        );
        assert_eq!(
            policy(true).decide(&Method::GET, "/v1/cohorts", None),
            Decision::Missing
        );
        for path in PUBLIC_PATHS {
            assert_eq!(
                policy(true).decide(&Method::GET, path, None),
                Decision::Allow
            );
        }
    }

    #[test]
    fn a_key_list_of_only_blanks_refuses_to_start_and_names_the_variable() {
        let config = |keys: &[&str]| {
            let mut c = Config::with_database("sqlite::memory:", "127.0.0.1:0");
            c.api_keys = keys.iter().map(|k| k.parse().unwrap()).collect();
            c
        };
        for blanks in [&[""][..], &[" "], &["", " ", ""]] {
            let err = AccessPolicy::from_config(&config(blanks)).unwrap_err();
            let message = err.to_string();
            assert!(message.contains(KEYS_VARIABLE), "{message}");
            assert!(message.contains("holds no key"), "{message}");
        }
        let unset = AccessPolicy::from_config(&config(&[])).unwrap();
        assert!(!unset.is_enabled(), "no list at all runs open on purpose");
        let one = AccessPolicy::from_config(&config(&["", " k-1 "])).unwrap();
        assert_eq!(one.digests.len(), 1);
    }

    #[test]
    fn keys_file_skips_comments_and_blank_lines() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("keys");
        std::fs::write(&path, "# operators\nalpha\n\n  beta  \n#gamma\n").unwrap();
        assert_eq!(read_keys_file(&path).unwrap(), ["alpha", "beta"]);
    }

    #[test]
    fn debug_output_shows_no_key() {
        let p = policy(false);
        assert!(!format!("{p:?}").contains("first-key"));
        let key: crate::config::ApiKey = "first-key".parse().unwrap();
        assert!(!format!("{key:?}").contains("first-key"));
    }
}
