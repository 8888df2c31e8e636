//! Eight lanes of indices into a table, as the AVX2 passes receive them: checked before any
//! gather reads the table, and tested for the common case of one index in every lane (whose
//! table entry is then broadcast rather than gathered).

/// The index in the first lane and whether every lane holds it.
///
/// # Panics
/// Unless every lane lies in `0..count`; `what` names the indices in the message.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn checked_first_and_uniform(
    indices: std::arch::x86_64::__m256i,
    count: usize,
    what: &str,
) -> (usize, bool) {
    use std::arch::x86_64::*;
    let count = i32::try_from(count).expect("tables of the simulator under 2^31 entries");
    let valid = _mm256_andnot_si256(
        _mm256_cmpgt_epi32(_mm256_setzero_si256(), indices),
        _mm256_cmpgt_epi32(_mm256_set1_epi32(count), indices),
    );
    assert!(
        _mm256_movemask_epi8(valid) == -1,
        "{what} index out of 0..{count}"
    );
    let first_lane = _mm256_permutevar8x32_epi32(indices, _mm256_setzero_si256());
    let uniform = _mm256_movemask_epi8(_mm256_cmpeq_epi32(indices, first_lane)) == -1;
    (_mm256_cvtsi256_si32(indices) as usize, uniform)
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use std::arch::x86_64::_mm256_setr_epi32;

    #[test]
    fn uniform_lanes_are_told_from_mixed_ones_and_bad_indices_refused() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        // SAFETY: the CPU has AVX2 (checked above).
        unsafe {
            assert_eq!(
                checked_first_and_uniform(_mm256_setr_epi32(3, 3, 3, 3, 3, 3, 3, 3), 4, "t"),
                (3, true)
            );
            assert_eq!(
                checked_first_and_uniform(_mm256_setr_epi32(2, 2, 2, 2, 2, 2, 2, 0), 4, "t"),
                (2, false)
            );
        }
        for bad in [4, -1] {
            let refused = std::panic::catch_unwind(|| {
                // SAFETY: as above.
                unsafe {
                    checked_first_and_uniform(_mm256_setr_epi32(0, 1, 2, 3, 0, 1, 2, bad), 4, "t")
                }
            });
            assert!(refused.is_err(), "lane index {bad} accepted");
        }
    }
}
