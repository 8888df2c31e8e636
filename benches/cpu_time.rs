//! A criterion measurement of the benchmark thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`)
//! instead of wall time: on a machine shared with other jobs the thread's time off the core
//! does not count, so the figure moves far less with the load (cache contention still shows).

use criterion::measurement::{Measurement, ValueFormatter};
use criterion::Throughput;

/// CPU time of the calling thread, in nanoseconds.
pub struct ThreadCpuTime;

fn thread_cpu_ns() -> u64 {
    let mut now = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `now` is a valid timespec to write into; the clock id is a constant Linux knows.
    let status = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut now) };
    assert_eq!(status, 0, "CLOCK_THREAD_CPUTIME_ID is unavailable");
    now.tv_sec as u64 * 1_000_000_000 + now.tv_nsec as u64
}

impl Measurement for ThreadCpuTime {
    type Intermediate = u64;
    type Value = u64;

    fn start(&self) -> u64 {
        thread_cpu_ns()
    }

    fn end(&self, started: u64) -> u64 {
        thread_cpu_ns() - started
    }

    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }

    fn zero(&self) -> u64 {
        0
    }

    fn to_f64(&self, value: &u64) -> f64 {
        *value as f64
    }

    fn formatter(&self) -> &dyn ValueFormatter {
        &CpuNanosFormatter
    }
}

struct CpuNanosFormatter;

impl ValueFormatter for CpuNanosFormatter {
    fn scale_values(&self, typical_ns: f64, values: &mut [f64]) -> &'static str {
        let (factor, unit) = match typical_ns {
            ns if ns < 1e3 => (1.0, "ns cpu"),
            ns if ns < 1e6 => (1e-3, "µs cpu"),
            ns if ns < 1e9 => (1e-6, "ms cpu"),
            _ => (1e-9, "s cpu"),
        };
        values.iter_mut().for_each(|value| *value *= factor);
        unit
    }

    fn scale_throughputs(
        &self,
        typical_ns: f64,
        throughput: &Throughput,
        values: &mut [f64],
    ) -> &'static str {
        let (per_iteration, names) = match *throughput {
            Throughput::Bytes(bytes) | Throughput::BytesDecimal(bytes) => {
                (bytes as f64, ["B/s", "KB/s", "MB/s", "GB/s"])
            }
            Throughput::Elements(elements) => {
                (elements as f64, ["elem/s", "Kelem/s", "Melem/s", "Gelem/s"])
            }
        };
        let per_second = per_iteration * 1e9 / typical_ns;
        let (divisor, unit) = match per_second {
            rate if rate < 1e3 => (1.0, names[0]),
            rate if rate < 1e6 => (1e3, names[1]),
            rate if rate < 1e9 => (1e6, names[2]),
            _ => (1e9, names[3]),
        };
        for value in values.iter_mut() {
            *value = per_iteration * 1e9 / *value / divisor;
        }
        unit
    }

    fn scale_for_machines(&self, _values: &mut [f64]) -> &'static str {
        "ns"
    }
}

/// `criterion_main!` for a bench function generic over the measurement, run twice: under wall
/// time as group `$wall_group`, and under the thread's CPU time as group `$cpu_group`.
#[macro_export]
macro_rules! wall_and_cpu_time_main {
    ($bench:ident, $wall_group:literal, $cpu_group:literal) => {
        fn wall_time(criterion: &mut criterion::Criterion) {
            $bench(criterion, $wall_group);
        }

        fn cpu_time(criterion: &mut criterion::Criterion<cpu_time::ThreadCpuTime>) {
            $bench(criterion, $cpu_group);
        }

        criterion::criterion_group!(wall, wall_time);
        criterion::criterion_group!(
            name = cpu;
            config = criterion::Criterion::default().with_measurement(cpu_time::ThreadCpuTime);
            targets = cpu_time
        );
        criterion::criterion_main!(wall, cpu);
    };
}
