//! TLS and tokens on the gRPC endpoints, as `[transport.tls]` and
//! `[transport.auth]` describe them: the files are read here, once, when a
//! role starts, so a missing or unreadable one stops it at once with an
//! error naming the key and the file.
//!
//! [`ServerSecurity`] is the servers' half: [`ServerSecurity::builder`] is
//! the one place the replay's and the learner's tonic servers are built,
//! with TLS (and client certificates, for mutual TLS) when configured and a
//! [`TokenLayer`] in front of their services. [`ClientSecurity`] is the
//! clients' half, which [`crate::channel`] applies to every channel.
//!
//! With mutual TLS, a verified client certificate admits a connection; a
//! token, when configured, is still required on the guarded calls (the
//! two are independent locks: one on the connection, one on the calls).

use std::path::{Path, PathBuf};

use crossroads_config::{TlsConfig, TransportConfig};
use tonic::transport::{Certificate, ClientTlsConfig, Identity, Server, ServerTlsConfig};
use tower::layer::util::{Identity as NoLayer, Stack};

use crate::auth::{Token, TokenLayer};

/// Why TLS or token material could not be used.
#[derive(Debug, thiserror::Error)]
pub enum SecurityError {
    /// A file named in the config cannot be read.
    #[error("{key}: cannot read {}: {source}", path.display())]
    Read {
        /// The dotted key naming the file, e.g. `transport.tls.cert_file`.
        key: &'static str,
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A file was read but does not hold what the key says it should.
    #[error("{key}: {}: {problem}", path.display())]
    Invalid {
        /// The dotted key.
        key: &'static str,
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        problem: String,
    },
    /// The token cannot be used.
    #[error("{origin}: the token {problem}")]
    Token {
        /// Where the token came from (a file, an environment variable).
        origin: String,
        /// What is wrong with it.
        problem: String,
    },
    /// An endpoint URL cannot be used as given.
    #[error("endpoint {endpoint:?}: {problem}")]
    Endpoint {
        /// The URL.
        endpoint: String,
        /// Why.
        problem: String,
    },
    /// tonic refused the TLS settings.
    #[error("TLS settings: {0}")]
    Tls(String),
}

/// PEM file contents, checked to hold at least one block of `kind` (a
/// label such as `CERTIFICATE` or `PRIVATE KEY`, matched at the end of the
/// BEGIN line so `RSA PRIVATE KEY` and `EC PRIVATE KEY` count too).
fn read_pem(key: &'static str, path: &Path, kind: &str) -> Result<Vec<u8>, SecurityError> {
    let bytes = std::fs::read(path).map_err(|source| SecurityError::Read {
        key,
        path: path.to_path_buf(),
        source,
    })?;
    let text = String::from_utf8_lossy(&bytes);
    let found = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("-----BEGIN "))
        .any(|l| l.trim_end_matches('-').ends_with(kind));
    if !found {
        return Err(SecurityError::Invalid {
            key,
            path: path.to_path_buf(),
            problem: format!("holds no PEM block \"{kind}\""),
        });
    }
    Ok(bytes)
}

/// The servers' TLS and token, loaded from the config.
#[derive(Debug, Clone, Default)]
pub struct ServerSecurity {
    tls: Option<ServerTlsConfig>,
    client_certificates: bool,
    token: Option<Token>,
}

/// A tonic server builder with the token check in front of its services.
pub type SecuredServer = Server<Stack<TokenLayer, NoLayer>>;

impl ServerSecurity {
    /// Reads the files `config.tls` (server half) and `config.auth` name.
    pub fn load(config: &TransportConfig) -> Result<Self, SecurityError> {
        Ok(Self {
            tls: server_tls(&config.tls)?,
            client_certificates: config.tls.client_ca_file.is_some(),
            token: Token::load(&config.auth)?,
        })
    }

    /// Whether connections are TLS.
    pub fn tls(&self) -> bool {
        self.tls.is_some()
    }

    /// Whether clients must present a certificate (mutual TLS).
    pub fn client_certificates(&self) -> bool {
        self.client_certificates
    }

    /// Whether guarded calls need a token.
    pub fn token(&self) -> bool {
        self.token.is_some()
    }

    /// A tonic server with TLS when configured, TCP_NODELAY, and a
    /// [`TokenLayer`] that lets the `open` calls through and guards the
    /// rest.
    pub fn builder(&self, open: &'static [&'static str]) -> Result<SecuredServer, SecurityError> {
        let mut builder = Server::builder().tcp_nodelay(true);
        if let Some(tls) = &self.tls {
            builder = builder
                .tls_config(tls.clone())
                .map_err(|e| SecurityError::Tls(error_chain(&e)))?;
        }
        Ok(builder.layer(TokenLayer::new(self.token.clone(), open)))
    }
}

/// The server's TLS settings, when `cert_file` is set.
fn server_tls(tls: &TlsConfig) -> Result<Option<ServerTlsConfig>, SecurityError> {
    let (Some(cert), Some(key)) = (&tls.cert_file, &tls.key_file) else {
        return Ok(None);
    };
    let cert = read_pem("transport.tls.cert_file", cert, "CERTIFICATE")?;
    let key = read_pem("transport.tls.key_file", key, "PRIVATE KEY")?;
    let mut config = ServerTlsConfig::new().identity(Identity::from_pem(cert, key));
    if let Some(ca) = &tls.client_ca_file {
        let ca = read_pem("transport.tls.client_ca_file", ca, "CERTIFICATE")?;
        config = config
            .client_ca_root(Certificate::from_pem(ca))
            .client_auth_optional(false);
    }
    Ok(Some(config))
}

/// The clients' TLS and token, loaded from the config; cheap to clone.
#[derive(Debug, Clone, Default)]
pub struct ClientSecurity {
    tls: Option<ClientTlsConfig>,
    token: Option<Token>,
}

impl ClientSecurity {
    /// Neither TLS nor a token: plain `http://` endpoints, open calls only
    /// where a server wants a token.
    pub fn none() -> Self {
        Self::default()
    }

    /// Reads the files `config.tls` (client half) and `config.auth` name.
    /// TLS applies to `https://` endpoints, which need `tls.ca_file`.
    pub fn load(config: &TransportConfig) -> Result<Self, SecurityError> {
        Ok(Self {
            tls: client_tls(&config.tls)?,
            token: Token::load(&config.auth)?,
        })
    }

    /// The same with `token` instead of the configured one (a `--token`
    /// flag, say).
    pub fn with_token(mut self, token: Option<Token>) -> Self {
        self.token = token;
        self
    }

    /// The token calls carry, if any.
    pub fn token(&self) -> Option<&Token> {
        self.token.as_ref()
    }

    /// The TLS settings for `https://` endpoints, if configured.
    pub(crate) fn tls(&self) -> Option<&ClientTlsConfig> {
        self.tls.as_ref()
    }
}

/// The clients' TLS settings, when `ca_file` is set.
fn client_tls(tls: &TlsConfig) -> Result<Option<ClientTlsConfig>, SecurityError> {
    let Some(ca) = &tls.ca_file else {
        return Ok(None);
    };
    let ca = read_pem("transport.tls.ca_file", ca, "CERTIFICATE")?;
    let mut config = ClientTlsConfig::new().ca_certificate(Certificate::from_pem(ca));
    if let (Some(cert), Some(key)) = (&tls.client_cert_file, &tls.client_key_file) {
        let cert = read_pem("transport.tls.client_cert_file", cert, "CERTIFICATE")?;
        let key = read_pem("transport.tls.client_key_file", key, "PRIVATE KEY")?;
        config = config.identity(Identity::from_pem(cert, key));
    }
    if let Some(name) = &tls.server_name {
        config = config.domain_name(name.clone());
    }
    Ok(Some(config))
}

/// An error and its sources, `: `-separated (tonic's transport errors say
/// little at the top: "transport error").
pub(crate) fn error_chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let s_text = s.to_string();
        if !text.contains(&s_text) {
            text.push_str(": ");
            text.push_str(&s_text);
        }
        source = s.source();
    }
    text
}
