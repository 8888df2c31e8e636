//! `evgate-ingest` as a library (a typed [`Config`] and [`run`]): publishes events from a recording or the built-in simulated camera on the
//! `<domain>/<camera>/events` stream (and their ground-truth labels on `.../labels` when the
//! source knows them), batched by duration or count, paced by the event timestamps or as fast as
//! possible.

mod batcher;
mod error;
mod network;
mod pacing;
mod source;

pub use error::RunError;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Parser;
use evgate_core::Event;
use evgate_ipc::{
    clock, create_node, BatchFlags, BatchHeader, Overflow, PipelineNames, Qos, SlicePublisher,
    Stream,
};
use evgate_sim::Preset;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use tracing::{info, warn};

use batcher::{BatchSize, Batcher};
use evgate_io::network::Endpoint;
use network::NetworkStream;
use pacing::Pacer;
use source::{EventSource, InMemory, Recording, SimulatedCamera};

/// Publish events into an evgate pipeline over shared memory.
#[derive(Parser, Debug, Clone, Serialize)]
#[command(name = "evgate-ingest", version, about)]
#[serde(rename_all = "kebab-case")]
pub struct Config {
    /// TOML file of defaults: its keys are this command's flags without the dashes, a string
    /// or number for a flag that takes a value (an array for a list), true or false for a
    /// switch; a flag given on the command line overrides its key.
    #[arg(long)]
    #[serde(skip)]
    pub config: Option<PathBuf>,
    /// Pipeline domain: the first part of every service name (use a unique one per pipeline).
    #[arg(long, default_value = "evgate")]
    pub domain: String,
    /// Camera name within the domain: the second part of every service name.
    #[arg(long, default_value = "cam0")]
    pub camera: String,
    /// Event file to publish: any format evgate-io decodes (EVT 2.0/3.0 RAW, DAT, AEDAT 4, CSV,
    /// .evg, EVIMO .npz), or a labelled-sequence .npz, published with its labels; or a live
    /// AEDAT 4 network stream, tcp://HOST:PORT or unix:///PATH (a DV runtime network output,
    /// dv-processing's NetworkWriter), published as it arrives and reconnected when the peer
    /// drops. Without it, the built-in simulated camera is used.
    #[arg(long)]
    pub input: Option<PathBuf>,
    /// Sensor size of --input as WIDTHxHEIGHT: required for files that give none (text), and
    /// overrides the file's otherwise.
    #[arg(long, value_parser = evgate_io::header::parse_sensor_flag)]
    #[serde(serialize_with = "evgate_ipc::config_file::sensor_as_flag")]
    pub sensor: Option<evgate_core::SensorSize>,
    /// Scene of the simulated camera: boxes, floor, wall, table, fast, tabletop or driving.
    #[arg(long, default_value = "boxes")]
    pub preset: Preset,
    /// Seed of the simulated scene (same seed, same events).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulated time per pass of the simulated camera, seconds.
    #[arg(long, default_value_t = 10.0)]
    pub sim_duration_s: f64,
    /// Worker threads of the simulated camera's renderer.
    #[arg(long, default_value_t = 1)]
    pub sim_threads: usize,
    /// Batch span in milliseconds (batches cut by time; ignored with --batch-events).
    #[arg(long, default_value_t = 1.0)]
    pub batch_ms: f64,
    /// Cut batches of this many events instead of by time.
    #[arg(long)]
    pub batch_events: Option<usize>,
    /// Publish as fast as possible instead of at the pace of the event timestamps.
    #[arg(long)]
    pub fast: bool,
    /// Replay speed when pacing by timestamps: stream seconds per wall-clock second.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Start over when the source ends, until stopped (stream time keeps increasing).
    #[arg(long = "loop")]
    #[serde(rename = "loop")]
    pub repeat: bool,
    /// Do not publish ground-truth labels even when the source knows them.
    #[arg(long)]
    pub no_labels: bool,
    /// Wait until this many subscribers listen to the events stream before publishing.
    #[arg(long, default_value_t = 0)]
    pub wait_for_subscribers: usize,
    /// Longest wait for those subscribers, seconds (then publish anyway).
    #[arg(long, default_value_t = 30.0)]
    pub wait_timeout_s: f64,
    /// What to do when a subscriber's buffer is full: block (up to --block-timeout-ms, then
    /// drop and count) or drop-and-count.
    #[arg(long, value_enum, default_value = "block")]
    pub overflow: Overflow,
    /// Longest wait for a full subscriber under --overflow block, milliseconds.
    #[arg(long, default_value_t = 500)]
    pub block_timeout_ms: u64,
    /// After the end of the stream, keep the publisher open until every events subscriber has
    /// left or this many milliseconds passed: iceoryx2 drops the samples of a publisher that
    /// leaves before a reader has connected to it, so a short recording could vanish unread.
    #[arg(long, default_value_t = 2000)]
    pub linger_ms: u64,
    /// Print a JSON summary on stdout when done.
    #[arg(long)]
    pub json: bool,
}

/// What the run did, printed at exit.
#[derive(Debug, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct IngestSummary {
    pub stream_id: u64,
    pub source: String,
    pub sensor_width: u16,
    pub sensor_height: u16,
    pub events_published: u64,
    pub batches_published: u64,
    pub labels_published: bool,
    pub passes: i64,
    /// Event batches some subscriber did not get (full buffer under the overflow policy).
    pub undelivered_batches: u64,
    /// Start of the first non-empty batch's span, microseconds.
    pub first_batch_begin_us: Option<i64>,
    /// End (exclusive) of the last non-empty batch's span, microseconds.
    pub last_batch_end_us: Option<i64>,
    pub wall_s: f64,
    pub events_per_s: f64,
    /// `end-of-stream` or `signal`.
    pub ended_by: &'static str,
    /// What the file's decoder dropped, skipped or found out of order (last pass; null for the
    /// simulated camera and labelled sequences).
    pub input_report: Option<evgate_io::DecodeReport>,
}

/// The endpoint `--input` names, if it names one rather than a file.
fn network_input(args: &Config) -> Option<Result<Endpoint, evgate_io::network::NetworkError>> {
    Endpoint::parse(args.input.as_ref()?.to_str()?)
}

fn validate(args: &Config) -> Result<(), RunError> {
    let setting = |flag, value: String, problem| RunError::Setting {
        flag,
        value,
        problem,
    };
    if args.repeat && network_input(args).is_some() {
        return Err(setting(
            "loop",
            "true".to_owned(),
            "replays files; --input names a live network stream",
        ));
    }
    if !(args.batch_ms > 0.0 && args.batch_ms.is_finite()) {
        let problem = "must be a positive number of milliseconds";
        return Err(setting("batch-ms", args.batch_ms.to_string(), problem));
    }
    if args.batch_events == Some(0) {
        return Err(setting(
            "batch-events",
            "0".to_owned(),
            "must be at least 1",
        ));
    }
    if !(args.speed > 0.0 && args.speed.is_finite()) {
        let problem = "must be a positive factor";
        return Err(setting("speed", args.speed.to_string(), problem));
    }
    if !(args.sim_duration_s > 0.0 && args.sim_duration_s.is_finite()) {
        let problem = "must be a positive number of seconds";
        return Err(setting(
            "sim-duration-s",
            args.sim_duration_s.to_string(),
            problem,
        ));
    }
    Ok(())
}

fn open_source(args: &Config) -> Result<(Box<dyn EventSource>, String), RunError> {
    if let Some(endpoint) = network_input(args) {
        let endpoint = endpoint?;
        let description = endpoint.to_string();
        let source = NetworkStream::connect(endpoint, args.sensor, network::stop_flag()?)?;
        return Ok((Box::new(source), description));
    }
    match &args.input {
        Some(path) if evgate_io::LabelledSequence::is_labelled_sequence(path) => {
            let source = InMemory::labelled_sequence(path)?;
            Ok((
                Box::new(source),
                format!("{} (labelled sequence)", path.display()),
            ))
        }
        Some(path) => {
            let source = Recording::open(path, args.sensor)?;
            Ok((Box::new(source), path.display().to_string()))
        }
        None => {
            let duration_us = (args.sim_duration_s * 1e6).round() as i64;
            let mut camera = SimulatedCamera::new(args.preset, args.seed, duration_us, 1_000);
            camera.set_threads(args.sim_threads);
            Ok((
                Box::new(camera),
                format!(
                    "simulated camera, preset {} seed {}",
                    args.preset, args.seed
                ),
            ))
        }
    }
}

/// An id that differs between runs, so readers notice a restarted ingest; never 0, which
/// forecasts may not name.
fn new_stream_id() -> u64 {
    let mixed =
        clock::monotonic_ns() ^ (u64::from(std::process::id()) << 40) ^ clock::wall_us() as u64;
    // SplitMix64 finaliser: spreads nearby inputs over the whole range.
    let mut z = mixed.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    (z ^ (z >> 31)).max(1)
}

/// Publishes the source's events until it ends (or SIGINT/SIGTERM) and returns what it did.
pub fn run(args: &Config) -> Result<IngestSummary, RunError> {
    validate(args)?;
    let names = PipelineNames::new(&args.domain, &args.camera)?;
    let node = create_node("evgate-ingest")?;
    let (mut source, description) = open_source(args)?;
    let sensor = source.sensor();
    let qos = Qos {
        overflow: args.overflow,
        block_timeout_ms: args.block_timeout_ms,
        initial_max_slice_len: args.batch_events.unwrap_or(4096),
        ..Qos::default()
    };
    let events = SlicePublisher::<Event, BatchHeader>::open(&node, &names, Stream::Events, &qos)?;
    let labels = if source.has_labels() && !args.no_labels {
        Some(SlicePublisher::<u16, BatchHeader>::open(
            &node,
            &names,
            Stream::Labels,
            &qos,
        )?)
    } else {
        None
    };
    info!(service = events.service_name(), source = %description, %sensor, "publishing");
    if !wait_for_subscribers(&node, &events, args)? {
        let nothing = Totals::default();
        return Ok(summary_of(
            &description,
            sensor,
            0,
            &nothing,
            Instant::now(),
            "signal",
            labels.is_some(),
        ));
    }

    let stream_id = new_stream_id();
    let size = match args.batch_events {
        Some(count) => BatchSize::Count { events: count },
        None if network_input(args).is_some() => BatchSize::Arrival,
        None => BatchSize::Duration {
            micros: ((args.batch_ms * 1e3).round() as i64).max(1),
        },
    };
    let mut batcher = Batcher::new(size);
    let mut pacer = Pacer::new(args.speed);
    let progress = ProgressBar::new_spinner();
    progress.set_style(ProgressStyle::with_template(
        "{spinner} {elapsed} {human_pos} events published ({per_sec})",
    )?);
    let live = network_input(args).is_some();
    let mut totals = Totals::default();
    let mut restarted = false;
    let started = Instant::now();
    let mut ended_by = "end-of-stream";
    loop {
        let Some(batch) = batcher.next_batch(source.as_mut())? else {
            if args.repeat {
                totals.passes += 1;
                source.restart(totals.passes)?;
                batcher.resume();
                restarted = true;
                continue;
            }
            break;
        };
        // A live stream arrives at its own pace.
        let wait = if args.fast || live {
            Duration::ZERO
        } else {
            pacer.wait_before(batch.t_end_us, Instant::now())
        };
        if evgate_ipc::stop_requested(&node, wait) {
            ended_by = "signal";
            break;
        }
        let mut flags = 0;
        if batch.last && !args.repeat {
            flags |= BatchFlags::END_OF_STREAM;
        }
        if std::mem::take(&mut restarted) {
            flags |= BatchFlags::STREAM_RESTARTED;
        }
        let mut header = BatchHeader {
            stream_id,
            sequence: totals.batches,
            first_event_index: totals.events,
            event_count: batch.events.len() as u64,
            t_begin_us: batch.t_begin_us,
            t_end_us: batch.t_end_us,
            published_at_monotonic_ns: 0,
            width: sensor.width,
            height: sensor.height,
            flags,
        };
        if let Some(labels) = &labels {
            // Labels go first so a reader joining by sequence never waits for them.
            labels.publish(header, batch.labels)?;
        }
        header.published_at_monotonic_ns = clock::monotonic_ns();
        let delivery = events.publish(header, batch.events)?;
        totals.record(&header, delivery.undelivered);
        if delivery.undelivered > 0 {
            // A reader that stopped taking samples may have died: free its port so later
            // batches do not wait for it.
            node.try_cleanup_dead_nodes();
        }
        progress.set_position(totals.events);
        // A flagged last batch some reader did not get is followed by a marker it will get.
        if header.is_end_of_stream() && delivery.undelivered == 0 {
            totals.end_of_stream_sent = true;
        }
    }
    if !totals.end_of_stream_sent {
        let deadline =
            Instant::now() + Duration::from_millis(args.linger_ms.max(args.block_timeout_ms));
        publish_end_of_stream(
            &node,
            &events,
            labels.as_ref(),
            stream_id,
            sensor,
            &mut totals,
            deadline,
        )?;
    }
    progress.finish_and_clear();
    let mut summary = summary_of(
        &description,
        sensor,
        stream_id,
        &totals,
        started,
        ended_by,
        labels.is_some(),
    );
    summary.input_report = source.decode_report();
    if let Some(report) = summary
        .input_report
        .as_ref()
        .filter(|report| !report.is_clean())
    {
        warn!(
            dropped_out_of_sensor = report.dropped_out_of_sensor,
            dropped_out_of_time_range = report.dropped_out_of_time_range,
            time_regressions = report.time_regressions,
            skipped_words = report.skipped_words,
            implausible_time_jumps = report.implausible_time_jumps,
            "the input needed repairs (see input-report in the summary)"
        );
    }
    if ended_by == "end-of-stream" {
        linger_until_subscribers_leave(&node, &events, Duration::from_millis(args.linger_ms));
    }
    Ok(summary)
}

/// Counts of what was published.
#[derive(Default)]
struct Totals {
    events: u64,
    batches: u64,
    undelivered: u64,
    first_begin: Option<i64>,
    last_end: Option<i64>,
    end_of_stream_sent: bool,
    /// Completed restarts of a looping source.
    passes: i64,
}

impl Totals {
    fn record(&mut self, header: &BatchHeader, undelivered: usize) {
        self.events += header.event_count;
        self.batches += 1;
        self.undelivered += (undelivered > 0) as u64;
        if header.event_count > 0 {
            self.first_begin.get_or_insert(header.t_begin_us);
            self.last_end = Some(header.t_end_us);
        }
    }
}

/// An empty batch flagged end-of-stream tells every reader that nothing follows; it is sent
/// again until every reader has it (or `deadline`), since readers wait for it.
fn publish_end_of_stream(
    node: &evgate_ipc::Node,
    events: &SlicePublisher<Event, BatchHeader>,
    labels: Option<&SlicePublisher<u16, BatchHeader>>,
    stream_id: u64,
    sensor: evgate_core::SensorSize,
    totals: &mut Totals,
    deadline: Instant,
) -> Result<(), RunError> {
    let t = totals.last_end.unwrap_or(0);
    let mut header = BatchHeader {
        stream_id,
        sequence: totals.batches,
        first_event_index: totals.events,
        event_count: 0,
        t_begin_us: t,
        t_end_us: t,
        published_at_monotonic_ns: 0,
        width: sensor.width,
        height: sensor.height,
        flags: BatchFlags::END_OF_STREAM,
    };
    if let Some(labels) = labels {
        labels.publish_until_delivered(node, header, &[], deadline)?;
    }
    header.published_at_monotonic_ns = clock::monotonic_ns();
    let delivery = events.publish_until_delivered(node, header, &[], deadline)?;
    if delivery.undelivered > 0 {
        warn!(
            readers = delivery.undelivered,
            "the end-of-stream marker did not reach every reader"
        );
    }
    totals.record(&header, delivery.undelivered);
    Ok(())
}

/// Waits (sleeping in short node cycles, so signals still end it) until enough subscribers are
/// connected; false when a signal arrived.
fn wait_for_subscribers(
    node: &evgate_ipc::Node,
    events: &SlicePublisher<Event, BatchHeader>,
    args: &Config,
) -> Result<bool, RunError> {
    if args.wait_for_subscribers == 0 {
        return Ok(true);
    }
    let deadline = Instant::now() + Duration::from_secs_f64(args.wait_timeout_s.max(0.0));
    while events.subscriber_count() < args.wait_for_subscribers {
        if Instant::now() >= deadline {
            warn!(
                connected = events.subscriber_count(),
                wanted = args.wait_for_subscribers,
                "publishing before every expected subscriber connected"
            );
            return Ok(true);
        }
        if evgate_ipc::stop_requested(node, Duration::from_millis(10)) {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Keeps the events publisher (and so its unread samples) alive until the readers have left,
/// the linger time has passed, or a signal arrived.
fn linger_until_subscribers_leave(
    node: &evgate_ipc::Node,
    events: &SlicePublisher<Event, BatchHeader>,
    linger: Duration,
) {
    let deadline = Instant::now() + linger;
    while events.subscriber_count() > 0 && Instant::now() < deadline {
        if evgate_ipc::stop_requested(node, Duration::from_millis(5)) {
            return;
        }
    }
    if events.subscriber_count() > 0 {
        info!(
            subscribers = events.subscriber_count(),
            linger_ms = linger.as_millis() as u64,
            "readers still connected at the end of the linger time"
        );
    }
}

fn summary_of(
    description: &str,
    sensor: evgate_core::SensorSize,
    stream_id: u64,
    totals: &Totals,
    started: Instant,
    ended_by: &'static str,
    labels_published: bool,
) -> IngestSummary {
    let wall_s = started.elapsed().as_secs_f64();
    IngestSummary {
        stream_id,
        source: description.to_owned(),
        sensor_width: sensor.width,
        sensor_height: sensor.height,
        events_published: totals.events,
        batches_published: totals.batches,
        labels_published,
        passes: totals.passes + 1,
        undelivered_batches: totals.undelivered,
        first_batch_begin_us: totals.first_begin,
        last_batch_end_us: totals.last_end,
        wall_s,
        events_per_s: if wall_s > 0.0 {
            totals.events as f64 / wall_s
        } else {
            0.0
        },
        ended_by,
        input_report: None,
    }
}
