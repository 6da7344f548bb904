//! The token that state-changing gRPC calls carry: [`Token`] (read from
//! `transport.auth`), [`Credentials`] (the client side: adds
//! `authorization: Bearer <token>` to every call) and [`TokenLayer`] (the
//! server side: a tower layer in front of a service that refuses a
//! guarded call without the token, before the service sees it).
//!
//! Which calls are guarded is a list of the open ones per service
//! ([`REPLAY_OPEN_CALLS`], [`LEARNER_OPEN_CALLS`]): every other path needs
//! the token, so a call added to a service later is guarded until someone
//! decides otherwise.
//!
//! A refused call is answered UNAUTHENTICATED, naming what is missing; the
//! token is compared in constant time, and a [`Token`]'s `Debug` hides it.

use std::fmt;
use std::path::Path;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use crossroads_config::AuthConfig;
use tonic::Status;
use tonic::codegen::http;
use tonic::metadata::{Ascii, MetadataValue};

use crate::security::SecurityError;

/// Replay calls anyone who can connect may make: they read and change
/// nothing. `Sample` is not among them: it moves the rate limiter.
pub const REPLAY_OPEN_CALLS: &[&str] = &["/crossroads.v1.Replay/Info"];

/// Learner calls anyone who can connect may make: weights, checkpoint
/// listing and download, status. Saving, restoring, deleting checkpoints
/// and reporting evaluations (which pick the best checkpoint) need the
/// token.
pub const LEARNER_OPEN_CALLS: &[&str] = &[
    "/crossroads.v1.Learner/SubscribeWeights",
    "/crossroads.v1.Learner/GetLatestWeights",
    "/crossroads.v1.Learner/ListCheckpoints",
    "/crossroads.v1.Learner/GetCheckpoint",
    "/crossroads.v1.Learner/Status",
];

/// A shared secret. Its `Debug` does not show it.
#[derive(Clone, PartialEq, Eq)]
pub struct Token(Arc<str>);

impl fmt::Debug for Token {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Token(<redacted>)")
    }
}

impl Token {
    /// `text` as a token: surrounding whitespace dropped, then non-empty
    /// printable ASCII without spaces (it travels in an HTTP header).
    /// `source` names where it came from, for the error.
    pub fn new(text: &str, source: &str) -> Result<Self, SecurityError> {
        let text = text.trim();
        let problem = if text.is_empty() {
            "is empty"
        } else if !text.chars().all(|c| c.is_ascii_graphic()) {
            "must be printable ASCII without spaces (it is sent in an HTTP header)"
        } else {
            return Ok(Self(text.into()));
        };
        Err(SecurityError::Token {
            origin: source.to_owned(),
            problem: problem.to_owned(),
        })
    }

    /// The token `auth` names: the contents of `token_file` when set,
    /// else the variable `token_env` when set and not empty, else none.
    pub fn load(auth: &AuthConfig) -> Result<Option<Self>, SecurityError> {
        if let Some(path) = &auth.token_file {
            let text = read_text("transport.auth.token_file", path)?;
            let source = format!("transport.auth.token_file {}", path.display());
            return Self::new(&text, &source).map(Some);
        }
        if auth.token_env.is_empty() {
            return Ok(None);
        }
        match std::env::var(&auth.token_env) {
            Ok(v) if v.trim().is_empty() => Ok(None),
            Ok(v) => {
                let source = format!("environment variable {}", auth.token_env);
                Self::new(&v, &source).map(Some)
            }
            Err(std::env::VarError::NotPresent) => Ok(None),
            Err(std::env::VarError::NotUnicode(_)) => Err(SecurityError::Token {
                origin: format!("environment variable {}", auth.token_env),
                problem: "is not valid UTF-8".to_owned(),
            }),
        }
    }

    fn matches(&self, given: &str) -> bool {
        constant_time_eq(self.0.as_bytes(), given.as_bytes())
    }
}

/// A file's text, or an error naming `key` and the file.
fn read_text(key: &'static str, path: &Path) -> Result<String, SecurityError> {
    std::fs::read_to_string(path).map_err(|source| SecurityError::Read {
        key,
        path: path.to_path_buf(),
        source,
    })
}

/// Equality whose time does not depend on where the bytes differ (only on
/// the lengths), so a caller cannot find the token byte by byte.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The client side: an interceptor that adds `authorization: Bearer
/// <token>` to every call when there is a token.
#[derive(Debug, Clone, Default)]
pub struct Credentials {
    header: Option<MetadataValue<Ascii>>,
}

impl Credentials {
    /// Credentials sending `token`, if any.
    pub fn new(token: Option<&Token>) -> Result<Self, SecurityError> {
        let header = match token {
            None => None,
            Some(t) => {
                let mut value: MetadataValue<Ascii> =
                    format!("Bearer {}", t.0)
                        .parse()
                        .map_err(|_| SecurityError::Token {
                            origin: "the token".to_owned(),
                            problem: "is not valid in an HTTP header".to_owned(),
                        })?;
                value.set_sensitive(true);
                Some(value)
            }
        };
        Ok(Self { header })
    }
}

impl tonic::service::Interceptor for Credentials {
    fn call(&mut self, mut request: tonic::Request<()>) -> Result<tonic::Request<()>, Status> {
        if let Some(value) = &self.header {
            request
                .metadata_mut()
                .insert("authorization", value.clone());
        }
        Ok(request)
    }
}

/// The server side: wraps a gRPC service so that every call whose path is
/// not in `open` needs `authorization: Bearer <token>` when a token is
/// set; without one, or with another, it is answered UNAUTHENTICATED
/// without reaching the service.
#[derive(Debug, Clone)]
pub struct TokenLayer {
    token: Option<Token>,
    open: &'static [&'static str],
}

impl TokenLayer {
    /// Guards every call but `open` with `token` (none: guards nothing).
    pub fn new(token: Option<Token>, open: &'static [&'static str]) -> Self {
        Self { token, open }
    }

    /// Whether a call to `path` with these headers may go through; the
    /// UNAUTHENTICATED status naming what is missing if not.
    fn admit(&self, path: &str, headers: &http::HeaderMap) -> Result<(), Status> {
        let Some(token) = &self.token else {
            return Ok(());
        };
        if self.open.contains(&path) {
            return Ok(());
        }
        let Some(value) = headers.get(http::header::AUTHORIZATION) else {
            return Err(Status::unauthenticated(format!(
                "missing authorization metadata: {path} changes state, and this server \
                 requires `authorization: Bearer <token>` (the client's token comes from \
                 transport.auth.token_file or CROSSROADS_TOKEN)"
            )));
        };
        let given = value
            .to_str()
            .ok()
            .and_then(|v| v.strip_prefix("Bearer "))
            .ok_or_else(|| {
                Status::unauthenticated(
                    "authorization metadata is not of the form `Bearer <token>`",
                )
            })?;
        if token.matches(given.trim()) {
            Ok(())
        } else {
            Err(Status::unauthenticated(format!(
                "bearer token does not match the server's (on {path})"
            )))
        }
    }
}

impl<S> tower::Layer<S> for TokenLayer {
    type Service = TokenCheck<S>;

    fn layer(&self, inner: S) -> TokenCheck<S> {
        TokenCheck {
            inner,
            layer: self.clone(),
        }
    }
}

/// A service behind a [`TokenLayer`].
#[derive(Debug, Clone)]
pub struct TokenCheck<S> {
    inner: S,
    layer: TokenLayer,
}

impl<S, B, R> tower::Service<http::Request<B>> for TokenCheck<S>
where
    S: tower::Service<http::Request<B>, Response = http::Response<R>>,
    S::Future: Send + 'static,
    S::Error: Send + 'static,
    R: Default + Send + 'static,
{
    type Response = S::Response;
    type Error = S::Error;
    type Future =
        Pin<Box<dyn Future<Output = Result<Self::Response, Self::Error>> + Send + 'static>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, request: http::Request<B>) -> Self::Future {
        match self.layer.admit(request.uri().path(), request.headers()) {
            Ok(()) => Box::pin(self.inner.call(request)),
            Err(status) => {
                tracing::debug!(
                    path = request.uri().path(),
                    message = status.message(),
                    "refused"
                );
                Box::pin(std::future::ready(Ok(status.into_http())))
            }
        }
    }
}
