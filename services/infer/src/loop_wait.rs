//! How the service loop waits between polls (`--wait`): a sleep of `--cycle-us` on the node
//! (which also notices SIGINT/SIGTERM), or busy-polling with a spin-then-yield back-off.

use std::time::Duration;

use evgate_ipc::{Backoff, Node, StopChecks, WaitStrategy};

pub struct LoopWait {
    strategy: WaitStrategy,
    cycle: Duration,
    backoff: Backoff,
    stop_checks: StopChecks,
}

impl LoopWait {
    pub fn new(strategy: WaitStrategy, cycle: Duration) -> Self {
        Self {
            strategy,
            cycle,
            backoff: Backoff::default(),
            stop_checks: StopChecks::default(),
        }
    }

    /// Called before each poll: under `event` it sleeps one cycle; true when SIGINT or
    /// SIGTERM asked the service to stop.
    pub fn stop_requested(&mut self, node: &Node) -> bool {
        match self.strategy {
            WaitStrategy::Event => evgate_ipc::stop_requested(node, self.cycle),
            WaitStrategy::BusyPoll => self.stop_checks.requested(node),
        }
    }

    /// After a poll that received batches or published forecasts.
    pub fn worked(&mut self) {
        self.backoff.reset();
    }

    /// After a poll that found nothing to do.
    pub fn idle(&mut self) {
        if self.strategy == WaitStrategy::BusyPoll {
            self.backoff.idle();
        }
    }
}
