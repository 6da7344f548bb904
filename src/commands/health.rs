//! `crossroads health`: whether a role's process on this host is alive, by
//! its `/healthz` endpoint (next to `/metrics`). For container health checks,
//! where the image has no HTTP client of its own.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use crossroads_config::Config;

use crate::cli::HealthArgs;

/// Exits 0 when `/healthz` answers 200 within the timeout, 1 otherwise,
/// saying why on stderr.
pub fn run(config: &Config, args: &HealthArgs) -> anyhow::Result<ExitCode> {
    let addr = args
        .addr
        .unwrap_or_else(|| local(config.telemetry.metrics_addr));
    let timeout = Duration::from_millis(args.timeout_ms);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    match runtime.block_on(crossroads_common::metrics::get(addr, "/healthz", timeout)) {
        Ok(_) => {
            if !args.quiet {
                println!("ok: http://{addr}/healthz");
            }
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("unhealthy: {e}");
            Ok(ExitCode::FAILURE)
        }
    }
}

/// The address to reach a server bound to `addr` from this host: an
/// unspecified address (0.0.0.0, ::) becomes loopback.
fn local(addr: SocketAddr) -> SocketAddr {
    if addr.ip().is_unspecified() {
        SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), addr.port())
    } else {
        addr
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unspecified_bind_address_is_reached_on_loopback() {
        assert_eq!(
            local("0.0.0.0:9100".parse().unwrap()),
            "127.0.0.1:9100".parse().unwrap()
        );
        assert_eq!(
            local("[::]:9100".parse().unwrap()),
            "127.0.0.1:9100".parse().unwrap()
        );
        assert_eq!(
            local("10.0.0.2:9100".parse().unwrap()),
            "10.0.0.2:9100".parse().unwrap()
        );
    }
}
