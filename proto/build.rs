//! Generates the prost messages and tonic services at build time, with the
//! protoc binary shipped by protoc-bin-vendored (no system protoc needed).

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // SAFETY-free: build scripts are single-threaded, so setting the variable
    // that prost-build reads cannot race.
    let protoc = protoc_bin_vendored::protoc_bin_path()?;
    // PROTOC is read by prost-build; a user-provided one wins.
    if std::env::var_os("PROTOC").is_none() {
        // Edition 2024 makes set_var unsafe because of other threads; a build
        // script runs on one thread.
        #[allow(unsafe_code)]
        unsafe {
            std::env::set_var("PROTOC", protoc);
        }
    }
    let protos = [
        "proto/crossroads/v1/schema.proto",
        "proto/crossroads/v1/replay.proto",
        "proto/crossroads/v1/learner.proto",
    ];
    tonic_prost_build::configure()
        .build_client(true)
        .build_server(true)
        // tonic-prost's codec answers undecodable bytes with INTERNAL; ours
        // with INVALID_ARGUMENT (src/codec.rs).
        .codec_path("crate::codec::Codec")
        .compile_protos(&protos, &["proto"])?;
    for p in protos {
        println!("cargo:rerun-if-changed={p}");
    }
    Ok(())
}
