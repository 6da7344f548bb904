//! Prometheus metrics: a registry per process and the `/metrics` endpoint
//! that serves it in the text exposition format.
//!
//! Metric names are a public API: `crossroads_<component>_<thing>_<unit>`,
//! `_total` for counters and `_seconds` for durations. Every registry starts
//! with `crossroads_build_info` and `crossroads_start_time_seconds`.
//!
//! The same endpoint answers `/healthz` (liveness, for `crossroads health`
//! and container health checks). [`get`] and [`scrape`] read another
//! process's endpoints, for `crossroads train`, `crossroads health` and the
//! deployment tests.

use std::convert::Infallible;
use std::net::SocketAddr;
use std::time::{SystemTime, UNIX_EPOCH};

use bytes::Bytes;
use http_body_util::Full;
use hyper::body::Incoming;
use hyper::header::{CONTENT_TYPE, HeaderValue};
use hyper::service::service_fn;
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::TokioIo;
use prometheus::{Encoder, Gauge, IntGaugeVec, Opts, Registry, TextEncoder};
use tokio::net::TcpListener;
use tokio::task::JoinHandle;
use tokio_util::task::TaskTracker;

use crate::shutdown::Shutdown;

/// Why the metrics endpoint could not start.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    /// The address could not be bound.
    #[error("cannot listen for /metrics on {addr}: {source}")]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A metric could not be registered (duplicate name, bad label).
    #[error("cannot register metric: {0}")]
    Register(#[from] prometheus::Error),
}

/// Reads `http://addr/metrics` and returns the exposition text; every step
/// (connect, answer, body) is bounded by `timeout`. For tools that watch
/// other processes, like `crossroads train`.
pub async fn scrape(addr: SocketAddr, timeout: std::time::Duration) -> Result<String, String> {
    get(addr, "/metrics", timeout).await
}

/// GETs `http://addr{path}` and returns the body of a 200 answer; every
/// step (connect, answer, body) is bounded by `timeout`, and an error names
/// the URL and the step that failed.
pub async fn get(
    addr: SocketAddr,
    path: &str,
    timeout: std::time::Duration,
) -> Result<String, String> {
    use http_body_util::{BodyExt, Empty};
    let fetch = async {
        let stream = tokio::net::TcpStream::connect(addr)
            .await
            .map_err(|e| format!("connecting: {e}"))?;
        let (mut sender, conn) = hyper::client::conn::http1::handshake(TokioIo::new(stream))
            .await
            .map_err(|e| format!("handshake: {e}"))?;
        tokio::spawn(conn);
        let req = Request::get(path)
            .header("host", addr.to_string())
            .body(Empty::<Bytes>::new())
            .map_err(|e| e.to_string())?;
        let resp = sender
            .send_request(req)
            .await
            .map_err(|e| format!("request: {e}"))?;
        if resp.status() != StatusCode::OK {
            return Err(format!("status {}", resp.status()));
        }
        let body = resp
            .into_body()
            .collect()
            .await
            .map_err(|e| format!("body: {e}"))?
            .to_bytes();
        String::from_utf8(body.to_vec()).map_err(|e| format!("body is not UTF-8: {e}"))
    };
    match tokio::time::timeout(timeout, fetch).await {
        Ok(r) => r.map_err(|e| format!("http://{addr}{path}: {e}")),
        Err(_) => Err(format!("http://{addr}{path}: no answer within {timeout:?}")),
    }
}

/// A fresh registry holding the process-wide metrics of `role` (`replay`,
/// `learner`, `actor`, `train`, ...).
pub fn registry(role: &str) -> Result<Registry, MetricsError> {
    let registry = Registry::new();
    let info = IntGaugeVec::new(
        Opts::new(
            "crossroads_build_info",
            "Build of this process; the value is always 1",
        ),
        &["version", "role"],
    )?;
    info.with_label_values(&[env!("CARGO_PKG_VERSION"), role])
        .set(1);
    registry.register(Box::new(info))?;
    let start = Gauge::new(
        "crossroads_start_time_seconds",
        "Start time of this process, seconds since the Unix epoch",
    )?;
    start.set(
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_secs_f64())
            .unwrap_or(0.0),
    );
    registry.register(Box::new(start))?;
    Ok(registry)
}

/// Renders every metric of `registry` in the text exposition format.
pub fn render(registry: &Registry) -> String {
    let mut buf = Vec::new();
    // Encoding into a Vec cannot fail on I/O; a metric with invalid
    // content is skipped by the encoder's error, which we log.
    if let Err(e) = TextEncoder::new().encode(&registry.gather(), &mut buf) {
        tracing::warn!(error = %e, "encoding metrics");
    }
    String::from_utf8(buf).unwrap_or_default()
}

/// A running `/metrics` endpoint. It stops when the shutdown signal fires;
/// [`MetricsServer::join`] waits for that.
#[derive(Debug)]
pub struct MetricsServer {
    addr: SocketAddr,
    task: JoinHandle<()>,
}

impl MetricsServer {
    /// Binds `addr` (port 0 picks a free port) and serves `registry` until
    /// `shutdown` fires. Must be called inside a tokio runtime.
    pub async fn start(
        addr: SocketAddr,
        registry: Registry,
        shutdown: Shutdown,
    ) -> Result<Self, MetricsError> {
        let listener = TcpListener::bind(addr)
            .await
            .map_err(|source| MetricsError::Bind { addr, source })?;
        let addr = listener
            .local_addr()
            .map_err(|source| MetricsError::Bind { addr, source })?;
        let task = tokio::spawn(serve(listener, registry, shutdown));
        tracing::info!(%addr, "serving metrics at http://{addr}/metrics");
        Ok(Self { addr, task })
    }

    /// The address actually bound.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Waits until the server has stopped (after shutdown fired).
    pub async fn join(self) {
        if let Err(e) = self.task.await {
            tracing::warn!(error = %e, "metrics server task failed");
        }
    }
}

async fn serve(listener: TcpListener, registry: Registry, shutdown: Shutdown) {
    let connections = TaskTracker::new();
    loop {
        let stream = tokio::select! {
            _ = shutdown.wait() => break,
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => stream,
                Err(e) => {
                    // Per-connection errors (EMFILE, resets) must not end
                    // the server; back off a little and go on.
                    tracing::warn!(error = %e, "accepting a metrics connection");
                    tokio::time::sleep(std::time::Duration::from_millis(50)).await;
                    continue;
                }
            },
        };
        let registry = registry.clone();
        let shutdown = shutdown.clone();
        connections.spawn(async move {
            let service = service_fn(move |req| {
                let registry = registry.clone();
                async move { Ok::<_, Infallible>(respond(&req, &registry)) }
            });
            let conn = hyper::server::conn::http1::Builder::new()
                .serve_connection(TokioIo::new(stream), service);
            tokio::pin!(conn);
            tokio::select! {
                result = conn.as_mut() => {
                    if let Err(e) = result {
                        tracing::debug!(error = %e, "metrics connection");
                    }
                }
                _ = shutdown.wait() => conn.as_mut().graceful_shutdown(),
            }
        });
    }
    connections.close();
    connections.wait().await;
}

fn respond(req: &Request<Incoming>, registry: &Registry) -> Response<Full<Bytes>> {
    let (status, content_type, body) = match (req.method(), req.uri().path()) {
        (&Method::GET, "/metrics") => (StatusCode::OK, prometheus::TEXT_FORMAT, render(registry)),
        // Liveness: the endpoint lives exactly as long as its role.
        (&Method::GET, "/healthz") => (
            StatusCode::OK,
            "text/plain; charset=utf-8",
            "ok\n".to_owned(),
        ),
        (&Method::GET, "/") => (
            StatusCode::OK,
            "text/plain; charset=utf-8",
            "crossroads: metrics at /metrics, liveness at /healthz\n".to_owned(),
        ),
        (&Method::GET, _) => (
            StatusCode::NOT_FOUND,
            "text/plain; charset=utf-8",
            "not found; metrics are at /metrics\n".to_owned(),
        ),
        _ => (
            StatusCode::METHOD_NOT_ALLOWED,
            "text/plain; charset=utf-8",
            "only GET is served\n".to_owned(),
        ),
    };
    let mut response = Response::new(Full::new(Bytes::from(body)));
    *response.status_mut() = status;
    response
        .headers_mut()
        .insert(CONTENT_TYPE, HeaderValue::from_static(content_type));
    response
}
