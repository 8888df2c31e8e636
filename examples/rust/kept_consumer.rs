//! Reads the events an evgate gate keeps, in place from shared memory.
//!
//! Start it before (or while) the pipeline runs, as the same user:
//!
//! ```text
//! cargo run --example kept_consumer -p evgate-examples -- DOMAIN CAMERA
//! evgate run --domain DOMAIN --camera CAMERA      # in another terminal
//! ```
//!
//! DOMAIN and CAMERA default to the services' own defaults, `evgate` and `cam0`. It prints one
//! line per second and, at the end of the stream (or after 10 s without a batch), a JSON
//! summary on stdout.

use std::time::{Duration, Instant};

use evgate_ipc::consumer::{EventBatches, EventStream};
use evgate_ipc::{create_node, PipelineNames};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let domain = args.next().unwrap_or_else(|| "evgate".to_owned());
    let camera = args.next().unwrap_or_else(|| "cam0".to_owned());

    let node = create_node("kept-consumer")?;
    let names = PipelineNames::new(&domain, &camera)?;
    let kept = EventBatches::open(&node, &names, EventStream::Kept)?;
    eprintln!("kept_consumer: reading {domain}/{camera}/kept");

    let (mut batches, mut events, mut on_events) = (0u64, 0u64, 0u64);
    let mut last_report = Instant::now();
    let mut ended_by = "idle";
    while let Some(batch) = kept.next(Duration::from_secs(10))? {
        // The events stay in shared memory: `batch.events()` borrows them until `batch` drops.
        batches += 1;
        events += batch.events().len() as u64;
        on_events += batch.events().iter().filter(|event| event.is_on()).count() as u64;
        if last_report.elapsed() >= Duration::from_secs(1) {
            eprintln!(
                "kept_consumer: {events} events in {batches} batches, latest at t = {} µs",
                batch.header().t_end_us
            );
            last_report = Instant::now();
        }
        if batch.header().is_end_of_stream() {
            ended_by = "end-of-stream";
            break;
        }
    }
    println!(
        "{{\"batches\": {batches}, \"events\": {events}, \"on-events\": {on_events}, \
         \"ended-by\": \"{ended_by}\"}}"
    );
    Ok(())
}
