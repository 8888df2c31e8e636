//! Events reach the caller either through the simulator's queue (when a call ends inside a
//! render step) or straight from the step that produced them: the stream and its counters must
//! not depend on which.

use evgate_sim::{Preset, Simulator};

fn simulator() -> Simulator {
    Simulator::new(Preset::Fast.config().at_reduced_resolution(3), 12).expect("valid config")
}

#[test]
fn uneven_calls_deliver_the_stream_and_counts_of_one_call() {
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
