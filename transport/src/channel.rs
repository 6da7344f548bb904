//! The one place a gRPC channel is built: [`connect`] gives the replay's
//! and the learner's clients a lazily connecting channel to a URL, with
//! TLS for `https://` endpoints and the token on every call, as a
//! [`ClientSecurity`] says.
//!
//! Channels keep HTTP/2 connections alive with pings. An `https://`
//! endpoint without a CA (`transport.tls.ca_file`) is refused, and so is
//! an `http://` one when a CA is set.

use std::time::Duration;

use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Channel, Endpoint};

use crate::auth::Credentials;
use crate::security::{ClientSecurity, SecurityError, error_chain};

/// A channel whose every call carries the token, if any.
pub type AuthChannel = InterceptedService<Channel, Credentials>;

/// A channel to `url` (`http://host:port` or `https://host:port`) that
/// connects on first use, so a server that is not up yet fails calls with a
/// retryable error rather than this function. `https://` needs TLS settings
/// (`transport.tls.ca_file`); `http://` with them is refused too, since
/// TLS was meant. Must be called inside a tokio runtime.
pub fn connect(
    url: &str,
    security: &ClientSecurity,
    connect_timeout: Duration,
) -> Result<AuthChannel, SecurityError> {
    let invalid = |problem: String| SecurityError::Endpoint {
        endpoint: url.to_owned(),
        problem,
    };
    let mut endpoint = Endpoint::from_shared(url.to_owned())
        .map_err(|e| invalid(error_chain(&e)))?
        .connect_timeout(connect_timeout)
        .tcp_nodelay(true)
        // A connection cut without a word (a partition) is found dead
        // within 10 s and replaced, rather than waiting out TCP's growing
        // retransmission intervals after the network heals.
        .http2_keep_alive_interval(Duration::from_secs(5))
        .keep_alive_timeout(Duration::from_secs(5));
    match (url.starts_with("https://"), security.tls()) {
        (true, Some(tls)) => {
            endpoint = endpoint
                .tls_config(tls.clone())
                .map_err(|e| invalid(error_chain(&e)))?;
        }
        (true, None) => {
            return Err(invalid(
                "https:// needs the CA that signed the server's certificate: set \
                 transport.tls.ca_file"
                    .to_owned(),
            ));
        }
        (false, Some(_)) => {
            return Err(invalid(
                "transport.tls.ca_file is set, so TLS is meant, but the endpoint is plain \
                 http://; use https://"
                    .to_owned(),
            ));
        }
        (false, None) => {}
    }
    let credentials = Credentials::new(security.token())?;
    Ok(InterceptedService::new(
        endpoint.connect_lazy(),
        credentials,
    ))
}
