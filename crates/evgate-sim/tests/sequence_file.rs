//! A simulated sequence fills every key of docs/sequence-format.md consistently and survives a
//! round trip through the `.npz` writer and reader.

use evgate_core::SensorSize;
use evgate_io::LabelledSequence;
use evgate_sim::sequence::{GT_PERIOD_US, MAX_HORIZON_US, REFERENCE_PERIOD_US};
use evgate_sim::{simulate_sequence, Intrinsics, Preset, SequenceOptions};

#[test]
fn sequence_has_every_array_on_its_grid_and_round_trips() {
    let mut config = Preset::Table.config();
    config.sensor = SensorSize::new(86, 65);
    config.intrinsics = Intrinsics {
        fx: 60.75,
        fy: 60.75,
        cx: 43.0,
        cy: 32.5,
    };
    let options = SequenceOptions {
        duration_us: 260_000,
        horizons_per_reference: 3,
    };
    let mut last_progress = 0;
    let (sequence, report) = simulate_sequence(&config, 9, &options, &mut |done, total| {
        assert!(done >= last_progress && done <= total);
        last_progress = done;
    })
    .expect("simulates");
    let start = sequence.events[0].t;
    assert!(sequence
        .gt_ts
        .iter()
        .enumerate()
        .all(|(i, &t)| t == start + i as i64 * GT_PERIOD_US));
    assert_eq!(*sequence.gt_ts.last().unwrap(), start + 25 * GT_PERIOD_US);
    assert_eq!(
        sequence.ref_ts,
        vec![
            start + REFERENCE_PERIOD_US,
            start + 2 * REFERENCE_PERIOD_US,
            start + 3 * REFERENCE_PERIOD_US
        ]
    );
    assert_eq!(sequence.horizon_us.len(), 9);
    assert!(sequence
        .horizon_us
        .iter()
        .all(|h| (0..=MAX_HORIZON_US).contains(h)));
    assert!(sequence
        .horizon_us
        .chunks(3)
        .all(|k| k[0] <= k[1] && k[1] <= k[2]));
    assert_eq!(sequence.labels.len(), sequence.events.len());
    assert_eq!(report.stats.events as usize, sequence.events.len());
    assert!(
        sequence.depth.iter().all(|d| *d > 0.1 && *d < 10.0),
        "depth outside the room"
    );
    let max_id = *sequence.masks.iter().max().unwrap();
    assert!(max_id as usize <= report.object_count);
    assert!(sequence.future_flow.iter().all(|f| f.is_finite()));
    let meta: serde_json::Value = serde_json::from_str(&sequence.meta).expect("meta is JSON");
    assert_eq!(meta["preset"], "table");
    assert_eq!(meta["seed"], 9);

    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("sequence.npz");
    sequence.write(&path).expect("writes");
    let back = LabelledSequence::read(&path).expect("reads");
    assert_eq!(back.events, sequence.events);
    assert_eq!(back.labels, sequence.labels);
    assert_eq!(back.masks, sequence.masks);
    assert_eq!(back.future_mask, sequence.future_mask);
    assert_eq!(back.intrinsics, sequence.intrinsics);
}

#[test]
fn too_short_a_sequence_is_rejected_with_the_minimum() {
    let options = SequenceOptions {
        duration_us: 100_000,
        horizons_per_reference: 2,
    };
    let error = simulate_sequence(&Preset::Boxes.config(), 1, &options, &mut |_, _| {})
        .expect_err("rejected");
    assert!(error.to_string().contains("150000"), "{error}");
}
