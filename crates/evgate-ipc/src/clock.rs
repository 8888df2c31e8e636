//! Clocks that mean the same thing in every process of the machine, so a latency can be measured
//! from a timestamp written by another process.

/// CLOCK_MONOTONIC in nanoseconds: system-wide on Linux, unaffected by wall-clock steps.
pub fn monotonic_ns() -> u64 {
    let mut now = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `now` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    let status = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut now) };
    debug_assert_eq!(status, 0);
    now.tv_sec as u64 * 1_000_000_000 + now.tv_nsec as u64
}

/// CLOCK_MONOTONIC in microseconds.
pub fn monotonic_us() -> u64 {
    monotonic_ns() / 1_000
}

/// Wall-clock time in microseconds since the Unix epoch (for logs and cross-machine records).
pub fn wall_us() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|elapsed| elapsed.as_micros() as i64)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_clock_does_not_go_back() {
        let first = monotonic_ns();
        let second = monotonic_ns();
        assert!(second >= first);
        assert!(first > 0);
    }
}
