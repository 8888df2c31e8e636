//! examples/rust/kept_consumer.rs, the consumer users copy, reads every event the gate keeps
//! from a real pipeline; the typed subscribers of `evgate_ipc::consumer` read the other outputs.

use std::time::Duration;

use evgate_e2e::{
    consume_kept_stream, example, start_service, start_simulated_burst, u64_at, unique_names,
    wait_until,
};
use evgate_ipc::create_node;

const TIMEOUT: Duration = Duration::from_secs(90);

#[test]
fn the_rust_example_receives_every_kept_event() {
    let run = consume_kept_stream(&example("kept_consumer").unwrap(), |names| {
        vec![names.domain.clone(), names.camera.clone()]
    });
    let passed = run.passed();
    assert!(passed > 0);
    assert_eq!(run.consumer["ended-by"], "end-of-stream");
    assert_eq!(u64_at(&run.consumer, "/events"), passed);
    assert_eq!(
        u64_at(&run.consumer, "/batches"),
        u64_at(&run.ingest, "/batches-published")
    );
}

#[test]
fn the_typed_subscribers_read_suppressed_events_keep_bitmaps_and_stats() {
    use evgate_ipc::consumer::{EventBatches, EventStream, KeepBitmaps, StatsReader};

    let names = unique_names("typed-consumer");
    let node = create_node("typed-consumer-test").unwrap();
    let kept = EventBatches::open(&node, &names, EventStream::Kept).unwrap();
    let suppressed = EventBatches::open(&node, &names, EventStream::Suppressed).unwrap();
    let bitmaps = KeepBitmaps::open(&node, &names).unwrap();
    let stats = StatsReader::open(&node, &names).unwrap();
    let mut gate = start_service(
        "evgate-gate",
        &names,
        &[
            "--json",
            "--exit-at-end-of-stream",
            "--outputs",
            "kept,suppressed,keep-bitmap",
            "--no-forecast",
            "pass",
            "--overflow",
            "block",
        ],
    )
    .unwrap();
    let mut ingest = start_simulated_burst(&names, 1).unwrap();

    // Without a forecast under --no-forecast pass, every event passes.
    let (mut kept_events, mut suppressed_events, mut passed_bits) = (0, 0, 0);
    let mut ended = [false; 3];
    let mut latest_stats = None;
    wait_until("every stream's end", TIMEOUT, || {
        while let Some(batch) = kept.try_next().unwrap() {
            kept_events += batch.events().len();
            ended[0] |= batch.header().is_end_of_stream();
        }
        while let Some(batch) = suppressed.try_next().unwrap() {
            suppressed_events += batch.events().len();
            ended[1] |= batch.header().is_end_of_stream();
        }
        while let Some(bitmap) = bitmaps.try_next().unwrap() {
            let events = bitmap.header().event_count as usize;
            passed_bits += (0..events).filter(|&index| bitmap.passed(index)).count();
            ended[2] |= bitmap.header().is_end_of_stream();
        }
        if let Some(fresh) = stats.latest().unwrap() {
            latest_stats = Some(fresh);
        }
        ended.iter().all(|&end| end) && latest_stats.is_some_and(|s| s.end_of_stream == 1)
    })
    .unwrap();
    let ingest_summary = ingest.summary(TIMEOUT).unwrap();
    gate.summary(TIMEOUT).unwrap();
    let published = u64_at(&ingest_summary, "/events-published");
    let stats = latest_stats.unwrap();
    assert!(published > 0);
    assert_eq!(kept_events as u64, published);
    assert_eq!(passed_bits as u64, published);
    assert_eq!(suppressed_events, 0);
    assert_eq!(stats.input_events, published);
    assert_eq!(stats.unjudged_passed_events, published);
}
