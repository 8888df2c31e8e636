//! Publish and receive through real iceoryx2 shared memory in one process.

use evgate_core::Event;
use evgate_ipc::{
    create_node, BatchHeader, ForecastHeader, LatestPublisher, LatestSubscriber, Overflow,
    PipelineNames, PipelineStats, Qos, SlicePublisher, SliceSubscriber, Stream,
};

fn unique_names(test: &str) -> PipelineNames {
    PipelineNames::new(&format!("ipc-{}-{}", test, std::process::id()), "cam").unwrap()
}

#[test]
fn event_batches_arrive_with_their_header() {
    let node = create_node("ipc-test-events").unwrap();
    let names = unique_names("events");
    let qos = Qos::default();
    let subscriber =
        SliceSubscriber::<Event, BatchHeader>::open(&node, &names, Stream::Events, &qos).unwrap();
    let publisher =
        SlicePublisher::<Event, BatchHeader>::open(&node, &names, Stream::Events, &qos).unwrap();
    let events: Vec<Event> = (0..10_000)
        .map(|i| Event::new(i, (i % 300) as u16, 7, i % 2 == 0))
        .collect();
    let header = BatchHeader {
        sequence: 4,
        event_count: events.len() as u64,
        width: 346,
        height: 260,
        ..Default::default()
    };
    let delivery = publisher.publish(header, &events).unwrap();
    assert_eq!(delivery.recipients, 1);
    assert_eq!(delivery.undelivered, 0);
    let sample = subscriber
        .receive()
        .unwrap()
        .expect("a published batch is waiting");
    assert_eq!(*sample.user_header(), header);
    assert_eq!(sample.payload(), events.as_slice());
    assert!(subscriber.receive().unwrap().is_none());
}

#[test]
fn drop_and_count_reports_undelivered_samples() {
    let node = create_node("ipc-test-drop").unwrap();
    let names = unique_names("drop");
    let reader_qos = Qos {
        buffer_size: 2,
        ..Qos::default()
    };
    let subscriber =
        SliceSubscriber::<Event, BatchHeader>::open(&node, &names, Stream::Kept, &reader_qos)
            .unwrap();
    let publisher = SlicePublisher::<Event, BatchHeader>::open(
        &node,
        &names,
        Stream::Kept,
        &Qos::with_overflow(Overflow::DropAndCount),
    )
    .unwrap();
    let undelivered: usize = (0..5u64)
        .map(|sequence| {
            let header = BatchHeader {
                sequence,
                ..Default::default()
            };
            publisher
                .publish(header, &[Event::new(sequence as i64, 0, 0, true)])
                .unwrap()
                .undelivered
        })
        .sum();
    assert_eq!(undelivered, 3);
    let received: Vec<u64> = std::iter::from_fn(|| {
        subscriber
            .receive()
            .unwrap()
            .map(|s| s.user_header().sequence)
    })
    .collect();
    assert_eq!(received, vec![0, 1]);
}

#[test]
fn forecasts_reach_a_late_subscriber_and_stats_keep_the_newest() {
    let node = create_node("ipc-test-latest").unwrap();
    let names = unique_names("latest");
    let forecasts = SlicePublisher::<u64, ForecastHeader>::open(
        &node,
        &names,
        Stream::Forecast,
        &Qos::default(),
    )
    .unwrap();
    let header = ForecastHeader {
        sequence: 9,
        horizon_count: 1,
        words_per_mask: 2,
        ..Default::default()
    };
    forecasts
        .publish_with(header, 4, |words| words[3] = 0xff)
        .unwrap();
    let late = SliceSubscriber::<u64, ForecastHeader>::open(
        &node,
        &names,
        Stream::Forecast,
        &Qos::default(),
    )
    .unwrap();
    forecasts.update_connections().unwrap();
    let sample = late
        .receive()
        .unwrap()
        .expect("history replays the latest forecast");
    assert_eq!(sample.user_header().sequence, 9);
    assert_eq!(sample.payload(), &[0, 0, 0, 0xff]);

    let stats = LatestPublisher::<PipelineStats>::open(&node, &names, Stream::Stats).unwrap();
    let reader = LatestSubscriber::<PipelineStats>::open(&node, &names, Stream::Stats).unwrap();
    for sequence in 0..40 {
        stats
            .publish(PipelineStats {
                sequence,
                ..PipelineStats::new(1)
            })
            .unwrap();
    }
    assert_eq!(reader.latest().unwrap().map(|s| s.sequence), Some(39));
    assert_eq!(reader.latest().unwrap(), None);
}

/// Issue 15: the end-of-stream marker went through the same discarding path, so a reader
/// that was full for a moment never learnt that the stream had ended.
#[test]
fn the_end_of_stream_marker_waits_for_a_full_reader() {
    let names = unique_names("eos");
    let (ready_sender, ready) = std::sync::mpsc::channel();
    let reader_names = names.clone();
    // Subscribers stay on their thread (they are not Send): this one connects, lets its
    // one-sample buffer fill, stays busy past the publisher's block timeout, then reads.
    let reader = std::thread::spawn(move || {
        let node = create_node("ipc-test-eos-reader").unwrap();
        let reader_qos = Qos {
            buffer_size: 1,
            ..Qos::default()
        };
        let subscriber = SliceSubscriber::<Event, BatchHeader>::open(
            &node,
            &reader_names,
            Stream::Events,
            &reader_qos,
        )
        .unwrap();
        ready_sender.send(()).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(400));
        let mut headers = Vec::new();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
        while std::time::Instant::now() < deadline {
            match subscriber.receive().unwrap() {
                Some(sample) => {
                    headers.push(*sample.user_header());
                    if sample.user_header().is_end_of_stream() {
                        break;
                    }
                }
                None => std::thread::sleep(std::time::Duration::from_millis(1)),
            }
        }
        headers
    });
    ready
        .recv_timeout(std::time::Duration::from_secs(30))
        .unwrap();
    let node = create_node("ipc-test-eos").unwrap();
    let publisher = SlicePublisher::<Event, BatchHeader>::open(
        &node,
        &names,
        Stream::Events,
        &Qos {
            overflow: Overflow::Block,
            block_timeout_ms: 50,
            ..Qos::default()
        },
    )
    .unwrap();
    let data = BatchHeader::default();
    assert_eq!(publisher.publish(data, &[]).unwrap().undelivered, 0);
    let end = BatchHeader {
        sequence: 1,
        flags: evgate_ipc::BatchFlags::END_OF_STREAM,
        ..Default::default()
    };
    // A plain publish would be discarded after 50 ms; this one is retried.
    let delivery = publisher
        .publish_until_delivered(
            &node,
            end,
            &[],
            std::time::Instant::now() + std::time::Duration::from_secs(30),
        )
        .unwrap();
    assert_eq!(delivery.undelivered, 0);
    let headers = reader.join().unwrap();
    assert_eq!(headers.first(), Some(&data));
    assert_eq!(headers.last(), Some(&end));
}
