//! scripts/setup-libtorch.sh refuses wheels whose sha256 does not match.

use std::path::Path;
use std::process::Command;

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/setup-libtorch.sh");

#[test]
fn checksum_mismatch_fails_clearly_and_moves_the_wheel_aside() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = dir.path().join("cache");
    std::fs::create_dir(&cache).expect("cache dir");
    let wheel = "torch-2.13.0-cp311-cp311-manylinux_2_28_x86_64.whl";
    std::fs::write(cache.join(wheel), b"not really a wheel").expect("fake wheel");
    let sums = dir.path().join("sums");
    let recorded = "60fcdcb2f3876e21146cb4524ef06397d727ca9ad5f020818547e25075fe3cb7";
    std::fs::write(&sums, format!("{recorded}  {wheel}\n")).expect("sums");
    let dest = dir.path().join("libtorch");

    let out = Command::new("bash")
        .arg(SCRIPT)
        .arg(&dest)
        .env("CROSSROADS_WHEEL_CACHE", &cache)
        .env("CROSSROADS_LIBTORCH_SUMS", &sums)
        .output()
        .expect("run the script");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "a corrupt wheel must fail: {stderr}");
    assert!(stderr.contains("checksum mismatch"), "{stderr}");
    assert!(stderr.contains(wheel), "names the wheel: {stderr}");
    assert!(
        stderr.contains(recorded),
        "shows the expected sum: {stderr}"
    );
    assert!(!dest.exists(), "nothing assembled from a bad wheel");
    assert!(
        !cache.join(wheel).exists(),
        "bad wheel moved out of the way"
    );
    assert!(cache.join(format!("{wheel}.bad")).exists());
}

#[test]
fn assembled_libtorch_is_reused() {
    // `make test` ran the script before building; a second run must find
    // the folder complete and leave it alone.
    let libtorch = Path::new(env!("CARGO_MANIFEST_DIR")).join(".libtorch");
    if std::env::var_os("LIBTORCH").is_some_and(|l| Path::new(&l) != libtorch) {
        eprintln!("skipped: LIBTORCH points elsewhere");
        return;
    }
    let out = Command::new("bash")
        .arg(SCRIPT)
        .output()
        .expect("run the script");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("already assembled"), "{stderr}");
    for lib in [
        "libtorch.so",
        "libtorch_cpu.so",
        "libc10.so",
        "libgomp.so.1",
    ] {
        assert!(libtorch.join("lib").join(lib).exists(), "{lib} missing");
    }
}
