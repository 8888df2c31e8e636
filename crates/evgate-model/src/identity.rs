//! A stable 64-bit identifier of a model file, so forecasts, stats and logs can tell models
//! apart without carrying a path.

/// FNV-1a over the file's bytes: stable across Rust versions and platforms, unlike std's
/// hasher, and fast enough for a once-per-load pass over a few megabytes.
pub fn model_id(bytes: &[u8]) -> u64 {
    const OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    bytes.iter().fold(OFFSET_BASIS, |hash, &byte| {
        (hash ^ u64::from(byte)).wrapping_mul(PRIME)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_published_fnv1a_vectors() {
        assert_eq!(model_id(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(model_id(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(model_id(b"foobar"), 0x8594_4171_f739_67e8);
    }
}
