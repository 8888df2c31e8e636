//! A tiny hand-built labelled sequence for tests: one 6×6 object sliding right at 200 px/s
//! over a 128×32 sensor for 400 ms, with edge events on the object and scattered background
//! events.

use evgate_core::{Event, SensorSize};
use evgate_io::sequence::LabelledSequence;

pub const SIZE: SensorSize = SensorSize::new(128, 32);
const DURATION_US: i64 = 400_000;
const SIDE: u16 = 6;
const TOP: u16 = 12;

/// Left edge of the object at time `t_us`: 4 px + 0.2 px/ms.
pub fn object_left(t_us: i64) -> u16 {
    (4 + t_us / 5_000) as u16
}

fn mask_at(t_us: i64) -> Vec<u8> {
    let mut mask = vec![0u8; SIZE.pixels()];
    let left = object_left(t_us);
    for y in TOP..TOP + SIDE {
        for x in left..left + SIDE {
            mask[SIZE.index(x, y)] = 1;
        }
    }
    mask
}

pub fn sequence() -> LabelledSequence {
    let mut events = Vec::new();
    let mut labels = Vec::new();
    for step in 0..DURATION_US / 500 {
        let t = step * 500;
        let left = object_left(t);
        for y in TOP..TOP + SIDE {
            events.push(Event::new(t, left + SIDE - 1, y, true));
            labels.push(1);
            events.push(Event::new(t, left, y, false));
            labels.push(1);
        }
        for k in 0..3 {
            let n = step * 3 + k;
            events.push(Event::new(
                t,
                (n * 37 % 128) as u16,
                (n * 11 % 32) as u16,
                n % 2 == 0,
            ));
            labels.push(0);
        }
    }
    let gt_ts: Vec<i64> = (0..=DURATION_US / 10_000).map(|k| k * 10_000).collect();
    let masks: Vec<u8> = gt_ts.iter().flat_map(|&t| mask_at(t)).collect();
    let ref_ts: Vec<i64> = (1..=DURATION_US / 50_000).map(|k| k * 50_000).collect();
    let horizon_us: Vec<i64> = ref_ts.iter().flat_map(|_| [30_000, 80_000]).collect();
    let future_mask: Vec<u8> = ref_ts
        .iter()
        .flat_map(|&t| [mask_at(t + 30_000), mask_at(t + 80_000)].concat())
        .collect();
    LabelledSequence {
        events,
        labels,
        sensor_size: SIZE,
        intrinsics: [[100.0, 0.0, 64.0], [0.0, 100.0, 16.0], [0.0, 0.0, 1.0]],
        depth: vec![1.0; masks.len()],
        gt_ts,
        masks,
        horizons_per_reference: 2,
        future_flow: vec![0.0; future_mask.len() * 2],
        future_mask,
        horizon_us,
        ref_ts,
        meta: r#"{"preset": "slide", "seed": 1}"#.to_owned(),
    }
}
