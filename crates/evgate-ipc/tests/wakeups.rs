//! A publisher that starts sending the moment it sees a subscriber must still wake that
//! subscriber: a short recording can be published in full within milliseconds of the reader
//! appearing, and a reader that misses those wake-ups sleeps beside waiting samples forever.

use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use evgate_core::Event;
use evgate_ipc::{
    create_node, BatchHeader, PipelineNames, Qos, SlicePublisher, SliceSubscriber, Stream,
};

const ROUNDS: usize = 30;
const WATCHDOG: Duration = Duration::from_secs(20);

/// Publishes one batch as soon as a subscriber is visible, the way `evgate-ingest
/// --wait-for-subscribers` does, and stays open until `release` (iceoryx2 drops the samples of
/// a publisher that leaves before the reader connected, which is not what this test is about).
fn publish_on_first_subscriber(
    names: PipelineNames,
    opened: mpsc::Sender<()>,
    published: mpsc::Sender<()>,
    release: mpsc::Receiver<()>,
) {
    let node = create_node("wakeup-test-publisher").unwrap();
    let publisher =
        SlicePublisher::<Event, BatchHeader>::open(&node, &names, Stream::Events, &Qos::default())
            .unwrap();
    opened.send(()).unwrap();
    let deadline = Instant::now() + WATCHDOG;
    while publisher.subscriber_count() == 0 {
        assert!(Instant::now() < deadline, "no subscriber appeared");
        std::hint::spin_loop();
    }
    let header = BatchHeader {
        event_count: 1,
        width: 346,
        height: 260,
        ..Default::default()
    };
    publisher
        .publish(header, &[Event::new(1, 2, 3, true)])
        .unwrap();
    published.send(()).unwrap();
    release.recv_timeout(WATCHDOG).unwrap();
}

#[test]
fn a_batch_sent_the_moment_the_subscriber_appears_wakes_its_listener() {
    let node = create_node("wakeup-test-subscriber").unwrap();
    for round in 0..ROUNDS {
        let names =
            PipelineNames::new(&format!("ipc-wakeup-{}-{round}", std::process::id()), "cam")
                .unwrap();
        let (opened, publisher_opened) = mpsc::channel();
        let (published, batch_published) = mpsc::channel();
        let (release, released) = mpsc::channel();
        let publisher = {
            let names = names.clone();
            thread::spawn(move || publish_on_first_subscriber(names, opened, published, released))
        };
        publisher_opened.recv_timeout(WATCHDOG).unwrap();
        let subscriber = SliceSubscriber::<Event, BatchHeader>::open(
            &node,
            &names,
            Stream::Events,
            &Qos::default(),
        )
        .unwrap();
        batch_published.recv_timeout(WATCHDOG).unwrap();
        let mut woken = false;
        subscriber.listener().try_wait(|_| woken = true).unwrap();
        assert!(woken, "round {round}: the listener missed the wake-up");
        assert!(subscriber.receive().unwrap().is_some());
        release.send(()).unwrap();
        publisher.join().unwrap();
    }
}
