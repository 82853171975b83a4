//! The choice, made once a process at run time, between portable loops, AVX2 code and
//! AVX-512 code: the tile compositor's projection and pixel loop ([`crate::splat::tiled`]) and
//! the cells of a transfer-function ramp in classification ([`crate::classify`]) have portable
//! and AVX2 forms, the pixel loop an AVX-512 form too, and each gives the same results.

/// The environment variable that chooses the vector code below what the processor has:
/// `off` keeps the portable loops on any processor, `avx2` the AVX2 code where AVX-512 is
/// there too, so that each is tested on a machine that has the next (CI runs the image tests
/// and the classification's each way); `on` (or unset) takes the widest the processor has.
/// Read once a process.
pub const SIMD_VAR: &str = "SPLATSCENE_SIMD";

/// The widest vector code [`SIMD_VAR`] allows.
#[cfg(target_arch = "x86_64")]
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Widest {
    Portable,
    Avx2,
    Avx512,
}

#[cfg(target_arch = "x86_64")]
fn widest_allowed() -> Widest {
    static WIDEST: std::sync::OnceLock<Widest> = std::sync::OnceLock::new();
    *WIDEST.get_or_init(|| match std::env::var(SIMD_VAR).as_deref() {
        Ok("off") => Widest::Portable,
        Ok("avx2") => Widest::Avx2,
        Ok("on") | Err(_) => Widest::Avx512,
        Ok(other) => {
            eprintln!("warning: {SIMD_VAR}={other:?} has no effect: give off, avx2 or on");
            Widest::Avx512
        }
    })
}

/// Whether the AVX2 code runs: the processor has AVX2, FMA and POPCNT, and [`SIMD_VAR`] does
/// not turn it off.
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_avx2() -> bool {
    static USE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *USE.get_or_init(|| {
        widest_allowed() >= Widest::Avx2
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("popcnt")
    })
}

/// Whether the AVX-512 code runs: the processor has AVX-512F, DQ and BW beside what
/// [`has_avx2`] asks, and [`SIMD_VAR`] allows it.
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_avx512() -> bool {
    static USE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *USE.get_or_init(|| {
        widest_allowed() >= Widest::Avx512
            && has_avx2()
            && std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512dq")
            && std::arch::is_x86_feature_detected!("avx512bw")
    })
}
