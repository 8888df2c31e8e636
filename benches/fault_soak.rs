//! Fault soak: the real ingest (replaying a recording in a loop), infer and gate run for
//! `--seconds` (default 600) while one service at a time, chosen at random, is SIGKILLed and
//! restarted or SIGSTOPped for up to 2 s and continued, with a random pause of 0.5-3 s between
//! faults.
//!
//! A service that ends by itself meanwhile is a failure (it is recorded and restarted).
//! Throughout, the gate's stats are read every few milliseconds and each snapshot must balance
//! (`input = kept + suppressed + unjudged passed + unjudged dropped + dropped`). At the end every
//! service runs again, the ingest is stopped with SIGTERM (it sends its end-of-stream marker),
//! and the gate's summary must account for every event the last ingest published since the gate
//! joined its stream: `published - joined - (kept + suppressed + unjudged + dropped)` is the
//! unaccounted count, and it must be 0. Events of a stream that a killed gate took with it, or
//! that were published while no gate ran, are reported per stream as `between-gates` (the gate
//! that joins later counts from its first batch, by design).
//!
//! `cargo bench -p evgate-benches --bench fault_soak -- [--seconds 600] [--seed 1]
//!  [--input ../shared/data/real/evt2_640x480.raw] [--model models/evgate-S-640x480.onnx]
//!  [--out target/bench/fault_soak.json]`

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use evgate_benches::{flag_value, write_report, BenchResult};
use evgate_e2e::{start_service, u64_at, unique_names, workspace_root, Process};
use evgate_ipc::{create_node, LatestSubscriber, PipelineNames, PipelineStats, Stream};
use rand::{Rng, SeedableRng};
use serde_json::json;

const EXIT_TIMEOUT: Duration = Duration::from_secs(120);
const STATS_POLL: Duration = Duration::from_millis(2);

/// One service of the pipeline, restarted with the same arguments after each kill.
struct Service {
    package: &'static str,
    args: Vec<String>,
    process: Process,
    kills: u64,
    stops: u64,
    /// Exit statuses of the times the service ended without being killed.
    unexpected_exits: Vec<String>,
}

impl Service {
    fn start(package: &'static str, names: &PipelineNames, args: Vec<String>) -> BenchResult<Self> {
        let process = spawn(package, names, &args)?;
        Ok(Self {
            package,
            args,
            process,
            kills: 0,
            stops: 0,
            unexpected_exits: Vec::new(),
        })
    }

    fn restart(&mut self, names: &PipelineNames) -> BenchResult<()> {
        self.process = spawn(self.package, names, &self.args)?;
        Ok(())
    }

    /// Records and restarts a service that ended by itself: none should while its stream runs.
    fn ensure_running(&mut self, names: &PipelineNames) -> BenchResult<()> {
        if let Some(status) = self.process.try_status() {
            eprintln!(
                "\nsoak: {} ended by itself ({status}); restarting it",
                self.package
            );
            self.unexpected_exits.push(status.to_string());
            self.restart(names)?;
        }
        Ok(())
    }
}

fn spawn(package: &str, names: &PipelineNames, args: &[String]) -> BenchResult<Process> {
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    Ok(start_service(package, names, &args)?)
}

fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|arg| (*arg).to_owned()).collect()
}

/// The last stats snapshot of each (stream, gate incarnation) the soak saw, and the checks made.
#[derive(Default)]
struct StatsWatch {
    last: BTreeMap<(u64, u64), PipelineStats>,
    snapshots: u64,
    unbalanced: u64,
}

impl StatsWatch {
    fn poll(&mut self, stats: &LatestSubscriber<PipelineStats>) -> BenchResult<()> {
        if let Some(snapshot) = stats.latest()? {
            self.snapshots += 1;
            // A gate publishes stats before its first batch too; they belong to no stream.
            if snapshot.input_batches == 0 {
                return Ok(());
            }
            if !snapshot.is_balanced() {
                self.unbalanced += 1;
                eprintln!("soak: UNBALANCED stats snapshot {snapshot:?}");
            }
            self.last.insert(
                (snapshot.stream_id, snapshot.joined_at_event_index),
                snapshot,
            );
        }
        Ok(())
    }

    /// Polls the stats for `duration`.
    fn watch_for(
        &mut self,
        stats: &LatestSubscriber<PipelineStats>,
        duration: Duration,
    ) -> BenchResult<()> {
        let until = Instant::now() + duration;
        while Instant::now() < until {
            self.poll(stats)?;
            std::thread::sleep(STATS_POLL);
        }
        Ok(())
    }

    /// Per input stream: the gates that counted it, what they counted, and the events between
    /// the end of one gate's count and the next gate's join.
    fn streams(&self) -> Vec<serde_json::Value> {
        let mut by_stream: BTreeMap<u64, Vec<&PipelineStats>> = BTreeMap::new();
        for ((stream, _), snapshot) in &self.last {
            by_stream.entry(*stream).or_default().push(snapshot);
        }
        by_stream
            .into_iter()
            .map(|(stream, gates)| {
                let mut between_gates = 0;
                let mut counted_until: Option<u64> = None;
                for gate in &gates {
                    if let Some(end) = counted_until {
                        between_gates += gate.joined_at_event_index.saturating_sub(end);
                    }
                    counted_until = Some(gate.joined_at_event_index + gate.input_events);
                }
                json!({
                    "stream-id": stream,
                    "gates": gates.len(),
                    "input-events": gates.iter().map(|g| g.input_events).sum::<u64>(),
                    "kept": gates.iter().map(|g| g.kept_events).sum::<u64>(),
                    "suppressed": gates.iter().map(|g| g.suppressed_events).sum::<u64>(),
                    "unjudged": gates.iter().map(|g| g.unjudged_passed_events + g.unjudged_dropped_events).sum::<u64>(),
                    "dropped": gates.iter().map(|g| g.dropped_events).sum::<u64>(),
                    "between-gates": between_gates,
                })
            })
            .collect()
    }
}

fn main() -> BenchResult<()> {
    let root = workspace_root();
    let seconds: f64 = flag_value("--seconds").map_or(Ok(600.0), |v| v.parse())?;
    let seed: u64 = flag_value("--seed").map_or(Ok(1), |v| v.parse())?;
    let input = flag_value("--input").map_or_else(
        || root.join("../shared/data/real/evt2_640x480.raw"),
        Into::into,
    );
    let model =
        flag_value("--model").map_or_else(|| root.join("models/evgate-S-640x480.onnx"), Into::into);
    let out =
        root.join(flag_value("--out").unwrap_or_else(|| "target/bench/fault_soak.json".to_owned()));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);

    let names = unique_names("soak");
    let node = create_node("fault-soak")?;
    let stats = LatestSubscriber::<PipelineStats>::open(&node, &names, Stream::Stats)?;
    let input = input.canonicalize()?.display().to_string();
    let model = model.canonicalize()?.display().to_string();
    let mut services = [
        Service::start(
            "evgate-gate",
            &names,
            strings(&[
                "--json",
                "--exit-at-end-of-stream",
                "--stats-interval-ms",
                "10",
            ]),
        )?,
        Service::start(
            "evgate-infer",
            &names,
            strings(&[
                "--model",
                &model,
                "--exit-at-end",
                "--stats-interval-s",
                "0",
            ]),
        )?,
        Service::start(
            "evgate-ingest",
            &names,
            strings(&["--json", "--input", &input, "--loop"]),
        )?,
    ];

    let mut watch = StatsWatch::default();
    let started = Instant::now();
    let deadline = started + Duration::from_secs_f64(seconds);
    let mut faults = 0u64;
    while Instant::now() < deadline {
        watch.watch_for(&stats, Duration::from_millis(rng.gen_range(500..3000)))?;
        let service = &mut services[rng.gen_range(0..3)];
        faults += 1;
        if rng.gen_bool(0.5) {
            service.process.signal(libc::SIGKILL);
            service.process.wait(EXIT_TIMEOUT)?;
            service.kills += 1;
            service.restart(&names)?;
        } else {
            service.process.signal(libc::SIGSTOP);
            service.stops += 1;
            let stopped_for = Duration::from_millis(rng.gen_range(50..2000));
            watch.watch_for(&stats, stopped_for)?;
            service.process.signal(libc::SIGCONT);
        }
        // A service may also have ended by itself (a peer it could not reach); that is a finding.
        for service in &mut services {
            service.ensure_running(&names)?;
        }
        eprint!(
            "\rsoak: {:>4.0} / {seconds:.0} s, {faults} faults, {} stats snapshots, {} unbalanced ",
            started.elapsed().as_secs_f64(),
            watch.snapshots,
            watch.unbalanced
        );
    }
    eprintln!();

    // The last stream must be counted from the gate's join to the ingest's end-of-stream.
    watch.watch_for(&stats, Duration::from_secs(3))?;
    let [gate, infer, ingest] = &mut services;
    ingest.process.signal(libc::SIGTERM);
    let ingest_summary = ingest.process.summary(EXIT_TIMEOUT)?;
    let gate_summary = gate.process.summary(EXIT_TIMEOUT)?;
    infer.process.signal(libc::SIGTERM);
    infer.process.wait(EXIT_TIMEOUT)?;
    watch.poll(&stats)?;

    let published = u64_at(&ingest_summary, "/events-published");
    let joined = u64_at(&gate_summary, "/stats/joined-at-event-index");
    let fates = [
        "kept-events",
        "suppressed-events",
        "unjudged-passed-events",
        "unjudged-dropped-events",
        "dropped-events",
    ]
    .iter()
    .map(|field| u64_at(&gate_summary, &format!("/stats/{field}")))
    .sum::<u64>();
    let same_stream =
        u64_at(&gate_summary, "/stats/stream-id") == u64_at(&ingest_summary, "/stream-id");
    let unaccounted = published as i128 - joined as i128 - fates as i128;
    let unexpected_exits: usize = services.iter().map(|s| s.unexpected_exits.len()).sum();
    let report = json!({
        "bench": "fault_soak",
        "seconds": seconds,
        "seed": seed,
        "input": input,
        "model": model,
        "faults": faults,
        "per-service": services.iter().map(|s| json!({
            "service": s.package, "sigkill-and-restart": s.kills, "sigstop-and-continue": s.stops,
            "unexpected-exits": s.unexpected_exits,
        })).collect::<Vec<_>>(),
        "stats-snapshots": watch.snapshots,
        "unbalanced-snapshots": watch.unbalanced,
        "streams": watch.streams(),
        "last-stream": {
            "stream-id": u64_at(&ingest_summary, "/stream-id"),
            "gate-counted-the-ingest's-stream": same_stream,
            "published": published,
            "gate-joined-at": joined,
            "kept+suppressed+unjudged+dropped": fates,
            "unaccounted": unaccounted,
        },
        "passed": same_stream && unaccounted == 0 && watch.unbalanced == 0 && unexpected_exits == 0,
    });
    write_report(&out, &report)?;
    if report["passed"] != true {
        return Err("fault soak: events unaccounted for or services ended (see the report)".into());
    }
    Ok(())
}
