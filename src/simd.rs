//! The choice, made once a process at run time, between portable loops and AVX2 code: the
//! tile compositor's projection and pixel loop ([`crate::splat::tiled`]) and the cells of a
//! transfer-function ramp in classification ([`crate::classify`]) have both, and give the same
//! results either way.

/// The environment variable that, set to `off`, keeps the portable loops on any processor, so
/// that they are tested where AVX2 is there too (CI runs the image tests and the
/// classification's both ways). Read once a process.
pub const SIMD_VAR: &str = "SPLATSCENE_SIMD";

/// Whether the AVX2 code runs: the processor has AVX2, FMA and POPCNT, and [`SIMD_VAR`] does
/// not turn it off.
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_avx2() -> bool {
    static USE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *USE.get_or_init(|| {
        let wanted = match std::env::var(SIMD_VAR).as_deref() {
            Ok("off") => false,
            Ok("on") | Err(_) => true,
            Ok(other) => {
                eprintln!("warning: {SIMD_VAR}={other:?} has no effect: give off or on");
                true
            }
        };
        wanted
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("popcnt")
    })
}
