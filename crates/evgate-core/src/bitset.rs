//! Packed bit arrays, the layout of masks, keep bitmaps and pass bits alike: bit i lives in word
//! i / 64 at position i % 64, and the bits past the last one of the last word are clear.

/// Words that hold `bits` bits.
pub const fn words_for(bits: usize) -> usize {
    bits.div_ceil(64)
}

/// Bit `index` of `words`.
#[inline(always)]
pub fn bit(words: &[u64], index: usize) -> bool {
    words[index / 64] >> (index % 64) & 1 == 1
}

/// Sets bit `index` of `words`.
#[inline(always)]
pub fn set_bit(words: &mut [u64], index: usize) {
    words[index / 64] |= 1 << (index % 64);
}

/// Clears `words` and sizes it for `bits` bits.
pub fn reset(words: &mut Vec<u64>, bits: usize) {
    words.clear();
    words.resize(words_for(bits), 0);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_round_up_and_bits_land_in_their_word() {
        assert_eq!((words_for(0), words_for(64), words_for(65)), (0, 1, 2));
        let mut words = Vec::new();
        reset(&mut words, 130);
        assert_eq!(words.len(), 3);
        set_bit(&mut words, 0);
        set_bit(&mut words, 64);
        set_bit(&mut words, 129);
        assert_eq!(words, [1, 1, 2]);
        assert!(bit(&words, 129) && !bit(&words, 128));
        reset(&mut words, 10);
        assert_eq!(words, [0]);
    }
}
