//! Generates the `tessera.v1` messages and services with the vendored `protoc` (no system
//! protoc needed).

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut config = tonic_prost_build::Config::new();
    config.protoc_executable(protoc_bin_vendored::protoc_bin_path()?);
    // large byte payloads (tile sums, scene files, blobs) decode without copying
    config.bytes(["."]);
    // the descriptors, for gRPC server reflection (grpcurl, Postman, Evans)
    config.file_descriptor_set_path(std::path::PathBuf::from(std::env::var("OUT_DIR")?).join("tessera_descriptor.bin"));
    tonic_prost_build::configure().compile_with_config(
        config,
        &["tessera/v1/common.proto", "tessera/v1/jobs.proto", "tessera/v1/worker.proto"],
        &["."],
    )?;
    Ok(())
}
