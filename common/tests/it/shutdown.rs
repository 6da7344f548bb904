//! The shutdown signal: by call, by child, and by a real SIGTERM.

use std::time::Duration;

use crossroads_common::Shutdown;

#[tokio::test]
async fn trigger_reaches_every_clone_and_child() {
    let shutdown = Shutdown::new();
    let clone = shutdown.clone();
    let child = shutdown.child();
    assert!(!clone.is_triggered());
    let waiter = tokio::spawn(async move { child.wait().await });
    shutdown.trigger();
    tokio::time::timeout(Duration::from_secs(5), waiter)
        .await
        .expect("child fired")
        .expect("task");
    assert!(clone.is_triggered());
    assert!(!clone.by_signal());
}

#[tokio::test]
async fn child_fires_alone_without_stopping_the_parent() {
    let parent = Shutdown::new();
    let child = parent.child();
    child.trigger();
    assert!(child.is_triggered());
    assert!(!parent.is_triggered());
}

#[tokio::test]
async fn sigterm_fires_the_signal() {
    let shutdown = Shutdown::on_signals().expect("handlers");
    // The handlers are installed: a real SIGTERM to this process is caught.
    // Sent twice at once (as coreutils `timeout` does), it is one request,
    // not the second signal that exits at once: this test would not finish.
    let pid = std::process::id().to_string();
    let status = std::process::Command::new("kill")
        .args(["-TERM", &pid, &pid])
        .status()
        .expect("run kill");
    assert!(status.success());
    tokio::time::timeout(Duration::from_secs(5), shutdown.wait())
        .await
        .expect("SIGTERM fired the shutdown signal");
    assert!(shutdown.by_signal());
    // This sleep is the test: were the second SIGTERM counted as a second
    // request, it would end the process within it.
    tokio::time::sleep(Duration::from_millis(300)).await;
}
