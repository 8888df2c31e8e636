//! Thresholding one logit plane of the network's output into a bit mask (`BitMask::
//! fill_from_logits`), as the infer service does for the current mask and every horizon, and
//! the keep region of one horizon (`dilate_logits`, then the threshold) at the shipped exports'
//! radii: 12 pixels for the DAVIS346 size from the 352-wide padded output, 16 for 640×480.
//!
//! Run: `cargo bench -p evgate-benches --bench threshold`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use evgate_core::{dilate_logits, BitMask, DilationScratch, SensorSize};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn threshold(criterion: &mut Criterion) {
    let mut group = criterion.benchmark_group("threshold");
    for (sensor, row_stride, padded_height, keep_dilation_px) in [
        (SensorSize::new(346, 260), 352usize, 272usize, 12usize),
        (SensorSize::new(640, 480), 640, 480, 16),
    ] {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let logits: Vec<f32> = (0..row_stride * padded_height)
            .map(|_| rng.gen_range(-4.0..2.0))
            .collect();
        let mut mask = BitMask::new(sensor).expect("sensor is non-empty");
        group.throughput(Throughput::Elements(sensor.pixels() as u64));
        group.bench_function(format!("{sensor}"), |bencher| {
            bencher.iter(|| {
                mask.fill_from_logits(black_box(&logits), row_stride, 0.0)
                    .expect("the plane covers the mask");
                black_box(&mask);
            })
        });
        let (mut scratch, mut dilated) = (DilationScratch::default(), Vec::new());
        group.bench_function(
            format!("{sensor} keep region {keep_dilation_px} px"),
            |bencher| {
                bencher.iter(|| {
                    dilate_logits(
                        black_box(&logits),
                        row_stride,
                        padded_height,
                        keep_dilation_px,
                        &mut scratch,
                        &mut dilated,
                    );
                    mask.fill_from_logits(&dilated, row_stride, 0.0)
                        .expect("the plane covers the mask");
                    black_box(&mask);
                })
            },
        );
    }
    group.finish();
}

criterion_group!(benches, threshold);
criterion_main!(benches);
