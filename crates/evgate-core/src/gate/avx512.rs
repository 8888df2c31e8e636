//! The judged and keep bits of 64 events against one mask and time interval, eight events per
//! AVX-512 step: two loads hold eight 16-byte records, one two-source permute each separates
//! their times and coordinates, one gather fetches the mask words, and the comparisons give the
//! bits directly as mask registers. The scalar path (`MaskLookup::bits`) is the reference; the
//! tests hold the two equal.

use std::arch::x86_64::*;

use crate::event::Event;

use super::avx2::CHUNK;
use super::MaskLookup;

/// `[keep, judged]` bits of the 64 events of `chunk` (bit i for event i).
///
/// # Safety
/// The CPU must support AVX-512F (`is_x86_feature_detected!("avx512f")`).
#[target_feature(enable = "avx512f")]
pub unsafe fn chunk_bits(
    chunk: &[Event; CHUNK],
    lookup: &MaskLookup<'_>,
    first: i64,
    last: i64,
    inversion: u64,
) -> [u64; 2] {
    let words = lookup.words.as_ptr().cast::<i64>();
    let width = _mm512_set1_epi64(i64::from(lookup.width));
    let height = _mm512_set1_epi64(i64::from(lookup.height));
    let first = _mm512_set1_epi64(first);
    let last = _mm512_set1_epi64(last);
    let low16 = _mm512_set1_epi64(0xFFFF);
    let low6 = _mm512_set1_epi64(63);
    let one = _mm512_set1_epi64(1);
    // Quadwords 0..8 of the first load and 8..16 of the second: a record's time, then its
    // coordinates.
    let time_lanes = _mm512_setr_epi64(0, 2, 4, 6, 8, 10, 12, 14);
    let coordinate_lanes = _mm512_setr_epi64(1, 3, 5, 7, 9, 11, 13, 15);
    let (mut keep, mut judged) = (0u64, 0u64);
    let records = chunk.as_ptr().cast::<__m512i>();
    for step in 0..CHUNK / 8 {
        // SAFETY: `chunk` holds 64 records of 16 bytes: steps 0..8 read its 64-byte quarters.
        let (first_four, last_four) = unsafe {
            (
                _mm512_loadu_si512(records.add(2 * step)),
                _mm512_loadu_si512(records.add(2 * step + 1)),
            )
        };
        let times = _mm512_permutex2var_epi64(first_four, time_lanes, last_four);
        let coordinates = _mm512_permutex2var_epi64(first_four, coordinate_lanes, last_four);
        let x = _mm512_and_si512(coordinates, low16);
        let y = _mm512_and_si512(_mm512_srli_epi64::<16>(coordinates), low16);
        let inside = _mm512_cmplt_epi64_mask(x, width) & _mm512_cmplt_epi64_mask(y, height);
        // Off-sensor events read pixel 0 (the mask is never empty) and are masked out below.
        let pixel = _mm512_maskz_add_epi64(inside, _mm512_mul_epu32(y, width), x);
        // SAFETY: every pixel index is below width × height, so its word lies in the mask.
        let word = unsafe { _mm512_i64gather_epi64::<8>(_mm512_srli_epi64::<6>(pixel), words) };
        let bit = _mm512_srlv_epi64(word, _mm512_and_si512(pixel, low6));
        let set = _mm512_test_epi64_mask(bit, one);
        let in_interval =
            _mm512_cmpge_epi64_mask(times, first) & _mm512_cmple_epi64_mask(times, last);
        let judged_lanes = inside & in_interval;
        let keep_lanes = judged_lanes & if inversion == 0 { set } else { !set };
        let shift = 8 * step;
        judged |= u64::from(judged_lanes) << shift;
        keep |= u64::from(keep_lanes) << shift;
    }
    [keep, judged]
}
