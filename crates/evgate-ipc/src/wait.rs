//! How a service waits for its next sample, and pinning its waiting thread to a core.
//!
//! `event` sleeps until a publisher's notification wakes the thread: no CPU while idle, but every
//! hop pays the kernel's wake-up (tens of microseconds). `busy-poll` never sleeps: the thread
//! polls its subscribers, spinning, then yielding the core after a run of empty polls, so each
//! hop costs a shared-memory read. It burns its core whole, so it belongs on a core of its own
//! (`--cpu`).

use std::thread;
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// How a service waits for its next sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "service", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum WaitStrategy {
    /// Sleep until a publisher's notification (no CPU while idle).
    #[default]
    Event,
    /// Poll the subscribers without sleeping (lowest latency; one core at 100 %).
    BusyPoll,
}

/// How often a `WaitSet` loop reads its subscribers whether a notification woke it or not.
///
/// An iceoryx2 0.10 listener can stop waking its `WaitSet` for good. Its notifiers send a
/// datagram only while the listener's shared flag is not yet "notified", and the listener resets
/// the flag before it empties its socket: a notification in between sets the flag again and has
/// its datagram emptied with the others, so every later notifier skips the datagram and the
/// socket stays silent. Each read of the listener ([`crate::SliceSubscriber::clear_wakeups`])
/// resets the flag, so polling at this period bounds such a stall to one period; without it
/// the gate would never read another batch, and its full input buffer would hold the ingest back.
/// 5 ms stays below what 16 buffered batches of the ingest's default 1 ms span can absorb, at
/// about 0.75 % of a core for an idle gate (1 ms cost 3 %, no poll 0.1 %).
pub const MISSED_WAKEUP_POLL: Duration = Duration::from_millis(5);

/// Empty polls spent spinning before a busy-polling thread starts yielding its core on each
/// one: a sample that follows within about a microsecond is met without a scheduler call.
const SPINNING_POLLS: u32 = 256;

/// The back-off between empty polls of a busy-polling loop: spin, then yield. It never sleeps,
/// so a sample is met within one poll plus one yield.
#[derive(Debug, Default)]
pub struct Backoff {
    empty_polls: u32,
}

impl Backoff {
    /// After a poll that found nothing.
    #[inline]
    pub fn idle(&mut self) {
        if self.empty_polls < SPINNING_POLLS {
            std::hint::spin_loop();
        } else {
            thread::yield_now();
        }
        self.empty_polls = self.empty_polls.saturating_add(1);
    }

    /// After a poll that found work.
    #[inline]
    pub fn reset(&mut self) {
        self.empty_polls = 0;
    }
}

/// Why the calling thread could not be pinned.
#[derive(Debug, thiserror::Error)]
pub enum PinError {
    #[error("--cpu {cpu}: this machine has CPUs 0 to {last}")]
    NoSuchCpu { cpu: usize, last: usize },
    #[error("--cpu {cpu}: sched_setaffinity failed: {source}")]
    Affinity { cpu: usize, source: std::io::Error },
}

/// Pins the calling thread to `cpu` (Linux `sched_setaffinity`).
pub fn pin_current_thread(cpu: usize) -> Result<(), PinError> {
    let limit = (libc::CPU_SETSIZE as usize).min(cpu_count_online());
    if cpu >= limit {
        return Err(PinError::NoSuchCpu {
            cpu,
            last: limit - 1,
        });
    }
    // SAFETY: a zeroed cpu_set_t is the empty set; CPU_SET writes bit `cpu`, which is below
    // CPU_SETSIZE; sched_setaffinity(0, ...) reads the set for the calling thread only.
    let result = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    if result != 0 {
        return Err(PinError::Affinity {
            cpu,
            source: std::io::Error::last_os_error(),
        });
    }
    Ok(())
}

/// CPUs online (a CPU this process's affinity excludes is refused by sched_setaffinity).
fn cpu_count_online() -> usize {
    // SAFETY: sysconf has no preconditions.
    let online = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) };
    usize::try_from(online).unwrap_or(1).max(1)
}

/// The CPU the calling thread runs on now.
pub fn current_cpu() -> Option<usize> {
    // SAFETY: sched_getcpu has no preconditions.
    usize::try_from(unsafe { libc::sched_getcpu() }).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pinned_thread_runs_on_its_cpu() {
        thread::spawn(|| {
            pin_current_thread(0).unwrap();
            for _ in 0..100 {
                thread::yield_now();
                assert_eq!(current_cpu(), Some(0));
            }
        })
        .join()
        .unwrap();
    }

    #[test]
    fn a_cpu_beyond_the_machine_is_refused_with_the_range() {
        let error = pin_current_thread(100_000).unwrap_err();
        assert!(
            error
                .to_string()
                .starts_with("--cpu 100000: this machine has CPUs 0 to "),
            "{error}"
        );
    }

    #[test]
    fn backoff_spins_then_yields_and_starts_over_after_work() {
        let mut backoff = Backoff::default();
        for _ in 0..SPINNING_POLLS + 3 {
            backoff.idle();
        }
        assert_eq!(backoff.empty_polls, SPINNING_POLLS + 3);
        backoff.reset();
        assert_eq!(backoff.empty_polls, 0);
    }
}
