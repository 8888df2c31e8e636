//! The simulator's output for a fixed preset and seed is pinned: the generated suite
//! (`SUITE_VERSION`) stays valid only while the same configuration and seed give the same
//! events and masks, so a speed-up must not change a bit of them.

use evgate_sim::{Preset, Simulator, SUITE_VERSION};

/// FNV-1a, 64 bit: a hash whose definition does not depend on the Rust version.
struct Fnv1a(u64);

impl Fnv1a {
    fn new() -> Fnv1a {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            self.0 = (self.0 ^ byte as u64).wrapping_mul(0x0100_0000_01b3);
        }
    }
}

fn output_hash(preset: Preset, seed: u64, threads: usize) -> (usize, u64) {
    let config = preset.config().at_reduced_resolution(3);
    let mut simulator = Simulator::new(config, seed).expect("valid config");
    simulator.set_threads(threads);
    let mut events = Vec::new();
    simulator.advance(150_000, &mut events);
    let mut hash = Fnv1a::new();
    for labelled in &events {
        let e = labelled.event;
        hash.write(&e.t.to_le_bytes());
        hash.write(&e.x.to_le_bytes());
        hash.write(&e.y.to_le_bytes());
        hash.write(&[e.polarity]);
        hash.write(&labelled.label.to_le_bytes());
    }
    let frame = simulator.frame_at(75_000);
    for (&log, (&surface, &depth)) in frame
        .log_intensity
        .iter()
        .zip(frame.surface.iter().zip(&frame.depth))
    {
        hash.write(&log.to_bits().to_le_bytes());
        hash.write(&surface.to_le_bytes());
        hash.write(&depth.to_bits().to_le_bytes());
    }
    (events.len(), hash.0)
}

#[test]
fn output_for_a_fixed_seed_is_pinned_and_independent_of_the_thread_count() {
    let pinned = [
        (Preset::Boxes, PINNED_BOXES),
        (Preset::Fast, PINNED_FAST),
        (Preset::Wall, PINNED_WALL),
    ];
    for (preset, expected) in pinned {
        for threads in [1, 3] {
            assert_eq!(
                output_hash(preset, 1, threads),
                expected,
                "{preset} seed 1 with {threads} threads: the output changed; if that is \
                 intended, bump SUITE_VERSION (now {SUITE_VERSION}) and update the pinned values"
            );
        }
    }
}

const PINNED_BOXES: (usize, u64) = (7351, 9257564918790070203);
const PINNED_FAST: (usize, u64) = (21192, 9574667889919772253);
const PINNED_WALL: (usize, u64) = (10459, 11764016455467960202);
