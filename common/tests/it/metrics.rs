//! The /metrics endpoint on port 0, scraped over HTTP and parsed.

use bytes::Bytes;
use crossroads_common::metrics::registry;
use crossroads_common::{MetricsServer, Shutdown};
use http_body_util::{BodyExt, Empty};
use hyper::Request;
use hyper_util::rt::TokioIo;
use prometheus::{IntCounter, Opts};

async fn get(addr: std::net::SocketAddr, path: &str) -> (u16, String, String) {
    let stream = tokio::net::TcpStream::connect(addr).await.expect("connect");
    let (mut sender, conn) = hyper::client::conn::http1::handshake(TokioIo::new(stream))
        .await
        .expect("handshake");
    tokio::spawn(conn);
    let req = Request::get(path)
        .header("host", addr.to_string())
        .body(Empty::<Bytes>::new())
        .expect("request");
    let resp = sender.send_request(req).await.expect("response");
    let status = resp.status().as_u16();
    let content_type = resp
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default()
        .to_owned();
    let body = resp.into_body().collect().await.expect("body").to_bytes();
    (
        status,
        content_type,
        String::from_utf8(body.to_vec()).expect("utf-8"),
    )
}

#[tokio::test]
async fn scrape_and_parse_exposition_text() {
    let reg = registry("test").expect("registry");
    let counter = IntCounter::with_opts(Opts::new(
        "crossroads_test_things_total",
        "Things counted by the test",
    ))
    .expect("counter");
    reg.register(Box::new(counter.clone())).expect("register");
    counter.inc_by(7);

    let shutdown = Shutdown::new();
    let server = MetricsServer::start("127.0.0.1:0".parse().expect("addr"), reg, shutdown.clone())
        .await
        .expect("start");
    let addr = server.local_addr();
    assert_ne!(addr.port(), 0, "port 0 resolved to a real port");
    assert!(listening(addr), "{addr} listens while serving");

    let (status, content_type, body) = get(addr, "/metrics").await;
    assert_eq!(status, 200);
    assert!(
        content_type.starts_with("text/plain; version=0.0.4"),
        "{content_type}"
    );

    let lines = body.lines().map(|l| Ok(l.to_owned()));
    let scrape = prometheus_parse::Scrape::parse(lines).expect("valid exposition text");
    let find = |name: &str| {
        scrape
            .samples
            .iter()
            .find(|s| s.metric == name)
            .unwrap_or_else(|| panic!("{name} missing from {body}"))
    };
    match find("crossroads_test_things_total").value {
        prometheus_parse::Value::Counter(v) => assert_eq!(v, 7.0),
        ref other => panic!("expected a counter, got {other:?}"),
    }
    let info = find("crossroads_build_info");
    assert_eq!(info.labels.get("role"), Some("test"));
    assert_eq!(info.labels.get("version"), Some(env!("CARGO_PKG_VERSION")));
    assert!(matches!(info.value, prometheus_parse::Value::Gauge(v) if v == 1.0));
    assert_eq!(
        scrape
            .docs
            .get("crossroads_test_things_total")
            .map(String::as_str),
        Some("Things counted by the test")
    );

    // The value is live: a second scrape sees the new count.
    counter.inc();
    let (_, _, body) = get(addr, "/metrics").await;
    let scrape = prometheus_parse::Scrape::parse(body.lines().map(|l| Ok(l.to_owned())))
        .expect("valid exposition text");
    let v = scrape
        .samples
        .iter()
        .find(|s| s.metric == "crossroads_test_things_total")
        .map(|s| s.value.clone());
    assert!(
        matches!(v, Some(prometheus_parse::Value::Counter(c)) if c == 8.0),
        "{v:?}"
    );

    let (status, _, _) = get(addr, "/nope").await;
    assert_eq!(status, 404);

    shutdown.trigger();
    tokio::time::timeout(std::time::Duration::from_secs(5), server.join())
        .await
        .expect("server stops on shutdown");
    // The listener is released. Not checked by binding the address again
    // or connecting to it: once free, the port may at once be taken by any
    // other socket on the machine (an outgoing connection's ephemeral port
    // made such a bind fail in CI), whereas a listener on it is ours.
    assert!(
        !listening(addr),
        "metrics port {addr} still listening after shutdown"
    );
}

/// Whether a socket listens on the IPv4 `addr` in this network namespace,
/// from /proc/net/tcp (local address as hex `IP:PORT`, state 0A = LISTEN).
fn listening(addr: std::net::SocketAddr) -> bool {
    let std::net::IpAddr::V4(ip) = addr.ip() else {
        panic!("{addr} is not IPv4");
    };
    // The kernel prints the address in host byte order.
    let local = format!(
        "{:08X}:{:04X}",
        u32::from_ne_bytes(ip.octets()),
        addr.port()
    );
    std::fs::read_to_string("/proc/net/tcp")
        .expect("/proc/net/tcp")
        .lines()
        .skip(1)
        .map(|line| line.split_whitespace().collect::<Vec<_>>())
        .any(|f| f.get(1) == Some(&local.as_str()) && f.get(3) == Some(&"0A"))
}

#[tokio::test]
async fn bind_error_names_the_address() {
    let taken = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = taken.local_addr().expect("addr");
    let err = MetricsServer::start(addr, registry("test").expect("registry"), Shutdown::new())
        .await
        .expect_err("address in use");
    assert!(err.to_string().contains(&addr.to_string()), "{err}");
}
