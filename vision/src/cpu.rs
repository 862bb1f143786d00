//! What the processor offers, for the hot loops built twice (baseline and AVX2, same results).

/// Whether the processor has AVX2. Callers check once, when they make their buffers, and
/// keep the answer.
pub(crate) fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    return false;
}
