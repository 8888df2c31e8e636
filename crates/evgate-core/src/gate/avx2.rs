//! The judged and keep bits of 64 events against one mask and time interval, four events per
//! AVX2 step: the events' coordinates are deinterleaved from their 16-byte records, the mask
//! words fetched with one gather, and the bits packed with a movemask. The scalar path
//! (`MaskLookup::bits`) is the reference; the tests hold the two equal.

use std::arch::x86_64::*;

use crate::event::Event;

use super::MaskLookup;

/// Events per call: one word of bits.
pub const CHUNK: usize = 64;

/// `[keep, judged]` bits of the 64 events of `chunk` (bit i for event i).
///
/// # Safety
/// The CPU must support AVX2 (`is_x86_feature_detected!("avx2")`).
#[target_feature(enable = "avx2")]
pub unsafe fn chunk_bits(
    chunk: &[Event; CHUNK],
    lookup: &MaskLookup<'_>,
    first: i64,
    last: i64,
    inversion: u64,
) -> [u64; 2] {
    let words = lookup.words.as_ptr().cast::<i64>();
    let width = _mm256_set1_epi64x(i64::from(lookup.width));
    let height = _mm256_set1_epi64x(i64::from(lookup.height));
    let first = _mm256_set1_epi64x(first);
    let last = _mm256_set1_epi64x(last);
    let low16 = _mm256_set1_epi64x(0xFFFF);
    let low6 = _mm256_set1_epi64x(63);
    let one = _mm256_set1_epi64x(1);
    let inversion = _mm256_set1_epi64x(inversion as i64);
    let (mut keep, mut judged) = (0u64, 0u64);
    let records = chunk.as_ptr().cast::<__m256i>();
    for step in 0..CHUNK / 4 {
        // SAFETY: `chunk` holds 64 records of 16 bytes: steps 0..16 read its 32-byte pairs.
        let (pair01, pair23) = unsafe {
            (
                _mm256_loadu_si256(records.add(2 * step)),
                _mm256_loadu_si256(records.add(2 * step + 1)),
            )
        };
        // Per 128-bit lane: [t0, t2] and [t1, t3]; the permute restores the order 0, 1, 2, 3.
        let times =
            _mm256_permute4x64_epi64::<0b11_01_10_00>(_mm256_unpacklo_epi64(pair01, pair23));
        let coordinates =
            _mm256_permute4x64_epi64::<0b11_01_10_00>(_mm256_unpackhi_epi64(pair01, pair23));
        let x = _mm256_and_si256(coordinates, low16);
        let y = _mm256_and_si256(_mm256_srli_epi64::<16>(coordinates), low16);
        let inside = _mm256_and_si256(_mm256_cmpgt_epi64(width, x), _mm256_cmpgt_epi64(height, y));
        // Off-sensor events read pixel 0 (the mask is never empty) and are masked out below.
        let pixel = _mm256_and_si256(_mm256_add_epi64(_mm256_mul_epu32(y, width), x), inside);
        // SAFETY: every pixel index is below width × height, so its word lies in the mask.
        let word = unsafe { _mm256_i64gather_epi64::<8>(words, _mm256_srli_epi64::<6>(pixel)) };
        let bit = _mm256_and_si256(_mm256_srlv_epi64(word, _mm256_and_si256(pixel, low6)), one);
        let outside_interval = _mm256_or_si256(
            _mm256_cmpgt_epi64(first, times),
            _mm256_cmpgt_epi64(times, last),
        );
        let judged_lanes = _mm256_andnot_si256(outside_interval, inside);
        let keep_lanes = _mm256_and_si256(
            _mm256_cmpeq_epi64(_mm256_xor_si256(bit, inversion), one),
            judged_lanes,
        );
        let shift = 4 * step;
        judged |= (_mm256_movemask_pd(_mm256_castsi256_pd(judged_lanes)) as u64) << shift;
        keep |= (_mm256_movemask_pd(_mm256_castsi256_pd(keep_lanes)) as u64) << shift;
    }
    [keep, judged]
}
