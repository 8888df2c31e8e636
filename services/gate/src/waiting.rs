//! The gate's two ways of waiting for work (`--wait`): sleeping in an iceoryx2 WaitSet until a
//! notification, or busy-polling its subscribers.

use std::time::Duration;

use evgate_core::Event;
use evgate_ipc::{Backoff, BatchHeader, ForecastHeader, SliceSubscriber};
use iceoryx2::prelude::{CallbackProgression, WaitSetAttachmentId, WaitSetBuilder};
use iceoryx2::waitset::WaitSetRunResult;

use crate::{Config, Drained, Gate, RunError};

/// How the gate's run ended: `end-of-stream` or `signal`.
pub type EndedBy = &'static str;

impl Gate {
    /// Sleeps in a WaitSet until a batch, a forecast, the stats interval or the missed wake-up
    /// poll wakes it.
    pub(crate) fn run_on_events(
        &mut self,
        node: &evgate_ipc::Node,
        events: &SliceSubscriber<Event, BatchHeader>,
        forecasts: &SliceSubscriber<u64, ForecastHeader>,
        args: &Config,
    ) -> Result<EndedBy, RunError> {
        let waitset = WaitSetBuilder::new()
            .create::<evgate_ipc::Service>()
            .map_err(RunError::WaitSetCreate)?;
        let events_guard = waitset
            .attach_notification(events.listener())
            .map_err(|source| RunError::WaitSetAttach {
                what: "events listener",
                source,
            })?;
        let forecast_guard =
            waitset
                .attach_notification(forecasts.listener())
                .map_err(|source| RunError::WaitSetAttach {
                    what: "forecast listener",
                    source,
                })?;
        let stats_tick = waitset
            .attach_interval(Duration::from_millis(args.stats_interval_ms))
            .map_err(|source| RunError::WaitSetAttach {
                what: "stats interval",
                source,
            })?;
        let missed_wakeup_poll = waitset
            .attach_interval(evgate_ipc::MISSED_WAKEUP_POLL)
            .map_err(|source| RunError::WaitSetAttach {
                what: "missed wake-up poll",
                source,
            })?;

        let mut failure = None;
        let mut reached_end = false;
        let mut stopped_by_signal = false;
        let on_wakeup = |attachment: WaitSetAttachmentId<evgate_ipc::Service>| {
            // The poll reads both streams as if both had notified.
            let polled = attachment.has_event_from(&missed_wakeup_poll);
            let mut step = Ok(false);
            if polled || attachment.has_event_from(&forecast_guard) {
                forecasts.clear_wakeups();
                step = self
                    .take_forecasts(forecasts)
                    .and_then(|_| self.release_held(node, false));
            }
            if step.as_ref().is_ok_and(|ended| !ended)
                && (polled || attachment.has_event_from(&events_guard))
            {
                events.clear_wakeups();
                step =
                    self.drain_events(node, events, forecasts)
                        .map(|(drained, _)| match drained {
                            Drained::EndOfStream => true,
                            Drained::Signal => {
                                stopped_by_signal = true;
                                true
                            }
                            Drained::Empty => false,
                        });
            }
            if attachment.has_event_from(&stats_tick) {
                step = step.and_then(|ended| self.publish_stats().map(|()| ended));
            }
            match step {
                Ok(true) if stopped_by_signal => CallbackProgression::Stop,
                Ok(true) if args.exit_at_end_of_stream => {
                    reached_end = true;
                    CallbackProgression::Stop
                }
                Ok(_) => CallbackProgression::Continue,
                Err(error) => {
                    failure = Some(error);
                    CallbackProgression::Stop
                }
            }
        };
        let outcome =
            evgate_ipc::run_until_stopped(&waitset, on_wakeup).map_err(RunError::WaitSetRun)?;
        drop(events_guard);
        drop(forecast_guard);
        drop(stats_tick);
        drop(missed_wakeup_poll);
        self.publish_stats()?;
        if let Some(error) = failure {
            return Err(error);
        }
        Ok(match outcome {
            WaitSetRunResult::TerminationRequest => "signal",
            _ if reached_end => "end-of-stream",
            _ => "signal",
        })
    }

    /// Polls the forecast and event subscribers without sleeping, with a spin-then-yield
    /// back-off between empty polls; stats go out on their interval as in the WaitSet loop.
    pub(crate) fn run_busy_polling(
        &mut self,
        node: &evgate_ipc::Node,
        events: &SliceSubscriber<Event, BatchHeader>,
        forecasts: &SliceSubscriber<u64, ForecastHeader>,
        args: &Config,
    ) -> Result<EndedBy, RunError> {
        let mut backoff = Backoff::default();
        let ended_by = loop {
            let forecasts_taken = self.take_forecasts(forecasts)?;
            let (drained, batches) = self.drain_events(node, events, forecasts)?;
            match drained {
                Drained::Signal => break "signal",
                Drained::EndOfStream if args.exit_at_end_of_stream => break "end-of-stream",
                Drained::EndOfStream | Drained::Empty => {}
            }
            if self.stats_published_at.elapsed() >= self.stats_interval {
                self.publish_stats()?;
            }
            // Nobody waits on the listeners: the notifications of the samples just taken are
            // dropped once their batches went out. Draining on every empty poll stretched each
            // poll by two system calls (about 2 µs of a 1 k-event round trip); draining only
            // every few dozen samples slowed the 10 k-event round trip twofold.
            if batches > 0 {
                events.clear_wakeups();
            }
            if forecasts_taken > 0 {
                forecasts.clear_wakeups();
            }
            if forecasts_taken + batches > 0 {
                backoff.reset();
            } else {
                backoff.idle();
            }
            if self.stop_checks.requested(node) {
                break "signal";
            }
        };
        self.publish_stats()?;
        Ok(ended_by)
    }
}
