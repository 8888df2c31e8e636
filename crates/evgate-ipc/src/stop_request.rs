//! Telling a request to stop (SIGINT, SIGTERM) from any other signal that cuts a wait short.
//!
//! iceoryx2 reports every interrupted sleep as an interrupt: `Node::wait` as
//! `NodeWaitFailure::Interrupt`, `WaitSet::wait_and_process` as `WaitSetRunResult::Interrupt`.
//! SIGCONT after a SIGSTOP (job control, a debugger, a supervisor pausing the process) and
//! signals such as SIGWINCH interrupt a sleep too, and a service that ended on those would end
//! its stream in the middle. Only SIGINT and SIGTERM, which iceoryx2 records as a termination
//! request, stop an evgate service.

use std::time::{Duration, Instant};

use iceoryx2::node::NodeWaitFailure;
use iceoryx2::prelude::{CallbackProgression, WaitSet, WaitSetAttachmentId};
use iceoryx2::waitset::{WaitSetRunError, WaitSetRunResult};

use crate::{Node, Service};

/// Sleeps on `node` for `cycle`; true when SIGINT or SIGTERM asked the process to stop. A sleep
/// cut short by any other signal returns false early.
pub fn stop_requested(node: &Node, cycle: Duration) -> bool {
    match node.wait(cycle) {
        Ok(()) => false,
        Err(NodeWaitFailure::TerminationRequest) => true,
        // The interrupting signal may itself have been SIGINT: a wait of no time checks the
        // termination request before it sleeps.
        Err(_) => matches!(
            node.wait(Duration::ZERO),
            Err(NodeWaitFailure::TerminationRequest)
        ),
    }
}

/// How often a loop that never sleeps (a flood, or busy-polling) looks for SIGINT/SIGTERM.
/// The look is a zero-length `nanosleep`, a system call that the kernel's timer slack can
/// stretch to tens of microseconds, so it is paced by time rather than done per batch.
pub const STOP_CHECK_PERIOD: Duration = Duration::from_millis(5);

/// Paces the stop checks of a loop that does not sleep: [`StopChecks::requested`] looks at
/// most once per [`STOP_CHECK_PERIOD`] and costs a clock read otherwise.
#[derive(Debug)]
pub struct StopChecks {
    next: Instant,
}

impl Default for StopChecks {
    fn default() -> Self {
        Self {
            next: Instant::now(),
        }
    }
}

impl StopChecks {
    /// True when SIGINT or SIGTERM asked the process to stop (looked at if a period passed).
    pub fn requested(&mut self, node: &Node) -> bool {
        let now = Instant::now();
        if now < self.next {
            return false;
        }
        self.next = now + STOP_CHECK_PERIOD;
        stop_requested(node, Duration::ZERO)
    }
}

/// Runs `waitset`, calling `on_wakeup` for every attachment that fired, until `on_wakeup` stops
/// it or SIGINT or SIGTERM arrives; a wait cut short by any other signal resumes.
pub fn run_until_stopped<F>(
    waitset: &WaitSet<Service>,
    mut on_wakeup: F,
) -> Result<WaitSetRunResult, WaitSetRunError>
where
    F: FnMut(WaitSetAttachmentId<Service>) -> CallbackProgression,
{
    loop {
        // After an interrupt the next call reports a pending termination request first.
        match waitset.wait_and_process(&mut on_wakeup)? {
            WaitSetRunResult::Interrupt => continue,
            outcome => return Ok(outcome),
        }
    }
}
