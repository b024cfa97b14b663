//! The CPU features the build was compiled for (`.cargo/config.toml` asks for x86-64-v2), so
//! that the binaries can refuse to run on an older CPU with a clear message instead of dying
//! on an illegal instruction in the middle of a render.

/// `Err` with a one-line explanation when the running CPU lacks a feature this build uses.
pub fn check_cpu_features() -> Result<(), String> {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse4.2", target_feature = "popcnt"))]
    if !(std::is_x86_feature_detected!("sse4.2") && std::is_x86_feature_detected!("popcnt")) {
        return Err("this build of Tessera needs an x86-64-v2 CPU (SSE4.2 and POPCNT); rebuild it for \
                    this machine with RUSTFLAGS=\"-C target-cpu=x86-64\""
            .to_string());
    }
    Ok(())
}
