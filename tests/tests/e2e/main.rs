//! The end-to-end tests, one module per area, in one test binary (one link instead of one per
//! file): they start the real service binaries (built by the harness in `tests/lib.rs`, as
//! `scripts/test.sh` builds them beforehand) and talk to them over real shared memory.

mod dv_network;
mod gate_over_shared_memory;
mod harness;
mod infer_failover;
mod infer_service;
mod metrics;
mod python_consumer;
mod recording_replay;
mod reliability;
mod run_command;
mod rust_consumer;
