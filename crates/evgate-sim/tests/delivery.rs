//! Events reach the caller either through the simulator's queue (when a call ends inside a
//! render step) or straight from the step that produced them: the stream and its counters must
//! not depend on which.

use evgate_sim::{Preset, Simulator};

fn simulator(timestamp_jitter_us: f32) -> Simulator {
    let mut config = Preset::Fast.config().at_reduced_resolution(3);
    config.events.timestamp_jitter_us = timestamp_jitter_us;
    Simulator::new(config, 12).expect("valid config")
}

#[test]
fn uneven_calls_deliver_the_stream_and_counts_of_one_call() {
    uneven_calls_deliver_one_calls_stream(0.0);
}

#[test]
fn uneven_calls_deliver_one_calls_stream_under_timestamp_jitter() {
    uneven_calls_deliver_one_calls_stream(150.0);
}

#[test]
fn timestamp_jitter_delays_events_and_keeps_them_in_order() {
    let (mut exact, mut jittered) = (Vec::new(), Vec::new());
    simulator(0.0).advance(60_000, &mut exact);
    simulator(80.0).advance(60_000, &mut jittered);
    assert!(jittered
        .windows(2)
        .all(|w| (w[0].event.t, w[0].event.y, w[0].event.x)
            <= (w[1].event.t, w[1].event.y, w[1].event.x)));
    let mean_t = |events: &[evgate_sim::LabelledEvent]| {
        events.iter().map(|e| e.event.t as f64).sum::<f64>() / events.len() as f64
    };
    // The same crossings, each a little later; those delayed past the end are held back.
    let held = exact.len() - jittered.len();
    assert!(
        held > 0 && held < exact.len() / 50,
        "{held} of {} held",
        exact.len()
    );
    let shift = mean_t(&jittered) - mean_t(&exact[..jittered.len()]);
    assert!(shift > 20.0 && shift < 140.0, "mean shift {shift} µs");
}

fn uneven_calls_deliver_one_calls_stream(timestamp_jitter_us: f32) {
    let simulator = || simulator(timestamp_jitter_us);
    let mut whole = Vec::new();
    let mut one_call = simulator();
    one_call.advance(90_000, &mut whole);

    let mut pieces = Vec::new();
    let mut split = simulator();
    // Ends inside steps, on step boundaries by chance, repeated, and far beyond several steps.
    for end in [1, 700, 700, 2_345, 2_346, 19_000, 19_001, 55_555, 90_000] {
        split.advance(end, &mut pieces);
        assert!(pieces.iter().all(|e| e.event.t <= end), "event after {end}");
        assert_eq!(
            split.stats().events as usize,
            pieces.len(),
            "count at {end}"
        );
    }
    assert!(
        whole.len() > 1_000,
        "too few events ({}) to check",
        whole.len()
    );
    assert_eq!(whole, pieces);
    assert_eq!(one_call.stats(), split.stats());
    let on = whole.iter().filter(|e| e.event.is_on()).count();
    let object = whole.iter().filter(|e| e.label != 0).count();
    assert_eq!(
        (one_call.stats().on_events, one_call.stats().object_events),
        (on as u64, object as u64)
    );
}
