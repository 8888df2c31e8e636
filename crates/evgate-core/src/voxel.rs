//! The network's input representation: a voxel grid of `B` time bins over the sensor, padded
//! at the right and bottom to a multiple of 16, stored `[B, H, W]` row-major in f32 so it can be
//! handed to ONNX Runtime as is. A downsampled grid bins the sensor's pixels N×N, so that a
//! sensor larger than the model's input still runs.

use std::borrow::Cow;

use crate::event::Event;
use crate::geometry::SensorSize;
use crate::window::TimeSpan;

/// The network's encoder halves the resolution four times.
pub const PADDING_MULTIPLE: u16 = 16;

/// Why a voxel grid could not be built or filled.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum VoxelError {
    #[error("voxel grid needs at least 1 time bin, got 0")]
    ZeroBins,
    #[error("voxel grid needs a non-empty sensor, got {sensor}")]
    EmptySensor { sensor: SensorSize },
    #[error("voxel grid downsampling must bin at least 1x1 pixels, got --downsample 0")]
    ZeroDownsample,
    #[error(
        "voxel grid cannot pad a {sensor} sensor to multiples of {PADDING_MULTIPLE}: a side \
         would pass 65535 (is the sensor size known? text event files need --sensor)"
    )]
    SensorTooLarge { sensor: SensorSize },
    #[error(
        "a {sensor} sensor pads to {padded}, larger than the {input} input the model takes; \
         export one for this size, pass another model or bin the sensor (--downsample)"
    )]
    InputTooSmall {
        sensor: SensorSize,
        padded: SensorSize,
        input: SensorSize,
    },
}

/// How many events one [`VoxelGrid::accumulate`] call splatted or skipped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SplatCounts {
    pub splatted: u64,
    /// Events whose pixel lies outside the sensor.
    pub outside_sensor: u64,
    /// Events on the sensor whose time lies outside the window.
    pub outside_window: u64,
}

impl std::ops::AddAssign for SplatCounts {
    fn add_assign(&mut self, other: Self) {
        self.splatted += other.splatted;
        self.outside_sensor += other.outside_sensor;
        self.outside_window += other.outside_window;
    }
}

/// A `[B, H, W]` voxel grid; reuse one across windows with [`clear`](Self::clear) to avoid
/// allocating.
#[derive(Clone, Debug)]
pub struct VoxelGrid {
    bins: usize,
    sensor: SensorSize,
    /// Side of the square of sensor pixels one cell bins (1: a cell per pixel).
    downsample: u16,
    padded: SensorSize,
    cells: Vec<f32>,
    counts: SplatCounts,
}

/// Mean and standard deviation of the non-zero cells, as used by [`VoxelGrid::normalise`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NonZeroStats {
    pub non_zero_cells: usize,
    pub mean: f64,
    /// Sample standard deviation (n − 1 denominator); 0 when fewer than two cells are non-zero.
    pub std: f64,
}

impl VoxelGrid {
    /// An all-zero grid of `bins` time bins over `sensor`, padded to multiples of 16.
    pub fn new(sensor: SensorSize, bins: usize) -> Result<Self, VoxelError> {
        Self::downsampled(sensor, bins, 1)
    }

    /// An all-zero grid whose cells each bin `downsample`×`downsample` pixels of `sensor`
    /// (the last column and row of cells take what is left), padded to multiples of 16.
    pub fn downsampled(
        sensor: SensorSize,
        bins: usize,
        downsample: u16,
    ) -> Result<Self, VoxelError> {
        if bins == 0 {
            return Err(VoxelError::ZeroBins);
        }
        if downsample == 0 {
            return Err(VoxelError::ZeroDownsample);
        }
        if sensor.pixels() == 0 {
            return Err(VoxelError::EmptySensor { sensor });
        }
        let padded = sensor
            .binned(downsample)
            .padded_to(PADDING_MULTIPLE)
            .ok_or(VoxelError::SensorTooLarge { sensor })?;
        Ok(Self {
            bins,
            sensor,
            downsample,
            padded,
            cells: vec![0.0; bins * padded.pixels()],
            counts: SplatCounts::default(),
        })
    }

    pub fn bins(&self) -> usize {
        self.bins
    }

    /// The sensor the events come from (before binning).
    pub fn sensor(&self) -> SensorSize {
        self.sensor
    }

    /// Side of the square of sensor pixels one cell bins.
    pub fn downsample(&self) -> u16 {
        self.downsample
    }

    /// The stored (padded) plane size: the `H`, `W` of the `[B, H, W]` layout.
    pub fn padded(&self) -> SensorSize {
        self.padded
    }

    /// The shape `[B, H, W]` of [`as_slice`](Self::as_slice).
    pub fn shape(&self) -> [usize; 3] {
        [
            self.bins,
            usize::from(self.padded.height),
            usize::from(self.padded.width),
        ]
    }

    /// Splat and skip counts accumulated since the last [`clear`](Self::clear).
    pub fn counts(&self) -> SplatCounts {
        self.counts
    }

    /// Zeroes every cell and the counts, keeping the allocation.
    pub fn clear(&mut self) {
        self.cells.fill(0.0);
        self.counts = SplatCounts::default();
    }

    /// Adds the events of `window` to the grid.
    ///
    /// Each event adds its polarity value (+1 ON, −1 OFF) split linearly between the two bins
    /// around its normalised time t* = (B − 1)(t − start)/(end − start). The paper splats
    /// trilinearly in (x, y, t*); event coordinates are integers, so the x and y weights put all
    /// of the value on the event's own pixel and only the time axis is interpolated.
    /// Events with `start ≤ t ≤ end` count (end included so that a window `[t − 50 ms, t]`
    /// keeps the event at the reference time); others are skipped and counted, as are events
    /// outside the sensor.
    /// Downsampled, an event adds to the cell that bins its pixel.
    pub fn accumulate(&mut self, events: &[Event], window: TimeSpan) -> SplatCounts {
        let counts = match self.downsample {
            1 => self.accumulate_cells(events, window, |x, y| (x, y)),
            factor => {
                let factor = u32::from(factor);
                self.accumulate_cells(events, window, |x, y| (x / factor, y / factor))
            }
        };
        self.counts += counts;
        counts
    }

    /// `cell_of` maps a pixel on the sensor to its cell; passed as a closure so that the
    /// per-pixel grid keeps a path without the division.
    #[inline(always)]
    fn accumulate_cells(
        &mut self,
        events: &[Event],
        window: TimeSpan,
        cell_of: impl Fn(u32, u32) -> (u32, u32),
    ) -> SplatCounts {
        if self.bins == 1 {
            self.accumulate_single_bin(events, window, cell_of)
        } else {
            self.accumulate_interpolated(events, window, cell_of)
        }
    }

    #[inline(always)]
    fn accumulate_single_bin(
        &mut self,
        events: &[Event],
        window: TimeSpan,
        cell_of: impl Fn(u32, u32) -> (u32, u32),
    ) -> SplatCounts {
        let (width, height) = (u32::from(self.sensor.width), u32::from(self.sensor.height));
        let row_stride = usize::from(self.padded.width);
        let span = window.duration();
        let mut counts = SplatCounts::default();
        for event in events {
            let (x, y) = (u32::from(event.x), u32::from(event.y));
            if x >= width || y >= height {
                counts.outside_sensor += 1;
                continue;
            }
            let since_start = event.t.wrapping_sub(window.start);
            if !(0..=span).contains(&since_start) {
                counts.outside_window += 1;
                continue;
            }
            let (x, y) = cell_of(x, y);
            self.cells[y as usize * row_stride + x as usize] += polarity_value(event);
            counts.splatted += 1;
        }
        counts
    }

    #[inline(always)]
    fn accumulate_interpolated(
        &mut self,
        events: &[Event],
        window: TimeSpan,
        cell_of: impl Fn(u32, u32) -> (u32, u32),
    ) -> SplatCounts {
        // With the paper's two bins every event's lower bin is 0; a constant bound lets the
        // compiler drop the floor and the clamp from the per-event path (same arithmetic).
        if self.bins == 2 {
            self.splat_between_bins(events, window, 0, cell_of)
        } else {
            self.splat_between_bins(events, window, self.bins - 2, cell_of)
        }
    }

    /// The interpolating splat; `last_lower_bin` is B − 2, passed in so that it can be a
    /// constant after inlining.
    #[inline(always)]
    fn splat_between_bins(
        &mut self,
        events: &[Event],
        window: TimeSpan,
        last_lower_bin: usize,
        cell_of: impl Fn(u32, u32) -> (u32, u32),
    ) -> SplatCounts {
        let (width, height) = (u32::from(self.sensor.width), u32::from(self.sensor.height));
        let row_stride = usize::from(self.padded.width);
        let plane = self.padded.pixels();
        let span = window.duration();
        // Relative times up to 2^24 µs (16 s) are exact in f32; windows are tens of ms.
        let scale = (self.bins - 1) as f32 / span as f32;
        let mut counts = SplatCounts::default();
        let cells = self.cells.as_mut_slice();
        for event in events {
            let (x, y) = (u32::from(event.x), u32::from(event.y));
            let since_start = event.t.wrapping_sub(window.start);
            // One well-predicted branch for both rare cases keeps the common path straight.
            if (x >= width) | (y >= height) | !(0..=span).contains(&since_start) {
                if x >= width || y >= height {
                    counts.outside_sensor += 1;
                } else {
                    counts.outside_window += 1;
                }
                continue;
            }
            let normalised_time = since_start as f32 * scale;
            // Truncation is floor here (t* ≥ 0); the min keeps t* = B − 1 in the last pair.
            let lower_bin = (normalised_time as usize).min(last_lower_bin);
            let upper_weight = normalised_time - lower_bin as f32;
            let value = polarity_value(event);
            let (x, y) = cell_of(x, y);
            let index = lower_bin * plane + y as usize * row_stride + x as usize;
            debug_assert!(index + plane < cells.len());
            // SAFETY: x < width and y < height, so their cell lies within the binned sensor,
            // whose padded size is the plane's (row_stride and its height); and
            // lower_bin ≤ B − 2, so index + plane < B · plane = cells.len().
            unsafe {
                *cells.get_unchecked_mut(index) += value - value * upper_weight;
                *cells.get_unchecked_mut(index + plane) += value * upper_weight;
            }
        }
        counts.splatted = events.len() as u64 - counts.outside_sensor - counts.outside_window;
        counts
    }

    /// Mean and sample standard deviation of the non-zero cells (zero cells, the padding among
    /// them, do not count).
    pub fn non_zero_stats(&self) -> NonZeroStats {
        // Branch-free sums over lanes: about half the cells of a busy window are zero, in no
        // predictable order, so a branch per cell would mispredict constantly; the lanes let
        // the compiler vectorise (the sums are f64, so their order barely matters).
        let mut counts = [0usize; LANES];
        let mut sums = [0.0f64; LANES];
        let mut chunks = self.cells.chunks_exact(LANES);
        for chunk in &mut chunks {
            for ((count, sum), &cell) in counts.iter_mut().zip(&mut sums).zip(chunk) {
                *count += usize::from(cell != 0.0);
                *sum += f64::from(cell);
            }
        }
        for &cell in chunks.remainder() {
            counts[0] += usize::from(cell != 0.0);
            sums[0] += f64::from(cell);
        }
        let count: usize = counts.iter().sum();
        let sum: f64 = sums.iter().sum();
        if count == 0 {
            return NonZeroStats {
                non_zero_cells: 0,
                mean: 0.0,
                std: 0.0,
            };
        }
        let mean = sum / count as f64;
        // Second pass around the mean: a one-pass sum of squares loses precision when the
        // mean is large against the spread.
        let mut squared_deviations = [0.0f64; LANES];
        let mut chunks = self.cells.chunks_exact(LANES);
        for chunk in &mut chunks {
            for (squares, &cell) in squared_deviations.iter_mut().zip(chunk) {
                *squares += non_zero_deviation(cell, mean).powi(2);
            }
        }
        for &cell in chunks.remainder() {
            squared_deviations[0] += non_zero_deviation(cell, mean).powi(2);
        }
        let squared_deviations: f64 = squared_deviations.iter().sum();
        let std = if count > 1 {
            (squared_deviations / (count - 1) as f64).sqrt()
        } else {
            0.0
        };
        NonZeroStats {
            non_zero_cells: count,
            mean,
            std,
        }
    }

    /// Normalises the non-zero cells to zero mean and unit standard deviation; zero cells stay
    /// zero. With a standard deviation of 0 the mean is only subtracted. This is the
    /// normalisation of the reference code (E-RAFT's voxel grid: `torch.std`, i.e. n − 1).
    pub fn normalise(&mut self) -> NonZeroStats {
        let stats = self.non_zero_stats();
        let inverse_std = if stats.std > 0.0 {
            1.0 / stats.std
        } else {
            1.0
        };
        for cell in &mut self.cells {
            // A select, not a branch, for the same reason as in `non_zero_stats`.
            *cell = (non_zero_deviation(*cell, stats.mean) * inverse_std) as f32;
        }
        stats
    }

    /// The cells, `[B, H, W]` row-major with the padded `H`, `W`.
    pub fn as_slice(&self) -> &[f32] {
        &self.cells
    }

    /// The cells as a model's `input`-sized grid: zero-padded further at the right and bottom
    /// when the input is larger than this grid's padded size (the contract's own padding, so
    /// a 320×240 sensor runs on a network exported for 352×272). The normalisation is
    /// unchanged: it reads only non-zero cells.
    pub fn as_input(&self, input: SensorSize) -> Result<Cow<'_, [f32]>, VoxelError> {
        let padded = self.padded;
        if padded == input {
            return Ok(Cow::Borrowed(&self.cells));
        }
        if padded.width > input.width || padded.height > input.height {
            return Err(VoxelError::InputTooSmall {
                sensor: self.sensor,
                padded,
                input,
            });
        }
        let (from_width, to_width) = (usize::from(padded.width), usize::from(input.width));
        let mut fitted = vec![0.0; self.bins * input.pixels()];
        for (plane, target) in self
            .cells
            .chunks(padded.pixels())
            .zip(fitted.chunks_mut(input.pixels()))
        {
            for (row, values) in plane.chunks(from_width).enumerate() {
                target[row * to_width..row * to_width + from_width].copy_from_slice(values);
            }
        }
        Ok(Cow::Owned(fitted))
    }
}

/// Independent accumulators of the statistics passes.
const LANES: usize = 8;

/// `cell − mean` for a non-zero cell, 0 for a zero cell (which stays out of the statistics).
#[inline(always)]
fn non_zero_deviation(cell: f32, mean: f64) -> f64 {
    if cell != 0.0 {
        f64::from(cell) - mean
    } else {
        0.0
    }
}

/// +1 for ON, −1 for OFF: 1.0 with the sign bit set for OFF. The arithmetic form
/// `f32::from(on) * 2.0 - 1.0` was compiled into a branch on the polarity, which real and
/// synthetic streams alike leave unpredictable (`git show dd99da7:BENCHMARKS.md`, "Core kernels"); the sign
/// bit form compiles to a `sete` and a table load.
#[inline(always)]
fn polarity_value(event: &Event) -> f32 {
    const ONE_BITS: u32 = 0x3f80_0000;
    f32::from_bits(ONE_BITS | (u32::from(event.polarity == 0) << 31))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn a_larger_model_input_gets_the_grid_zero_padded() {
        let mut voxel = VoxelGrid::new(SensorSize::new(16, 16), 2).unwrap();
        voxel.accumulate(
            &[Event::new(10, 15, 15, true)],
            TimeSpan::new(0, 20).unwrap(),
        );
        let fitted = voxel.as_input(SensorSize::new(32, 48)).unwrap();
        assert_eq!(fitted.len(), 2 * 32 * 48);
        let sum_of = |values: &[f32]| values.iter().map(|v| v.abs()).sum::<f32>();
        assert!(sum_of(voxel.as_slice()) > 0.0);
        assert_eq!(sum_of(&fitted), sum_of(voxel.as_slice()));
        for bin in 0..2 {
            for row in 0..16 {
                let source = &voxel.as_slice()[bin * 256 + row * 16..bin * 256 + row * 16 + 16];
                let target = &fitted[bin * 1536 + row * 32..bin * 1536 + row * 32 + 16];
                assert_eq!(source, target);
            }
        }
        assert!(matches!(
            voxel.as_input(voxel.padded()).unwrap(),
            Cow::Borrowed(_)
        ));
        assert_eq!(
            voxel
                .as_input(SensorSize::new(32, 8))
                .unwrap_err()
                .to_string(),
            "a 16x16 sensor pads to 16x16, larger than the 32x8 input the model takes; export \
             one for this size, pass another model or bin the sensor (--downsample)"
        );
    }

    const SENSOR: SensorSize = SensorSize::new(21, 13);

    fn window() -> TimeSpan {
        TimeSpan::new(0, 1_000).unwrap()
    }

    #[test]
    fn grid_is_padded_to_sixteen() {
        let grid = VoxelGrid::new(SENSOR, 2).unwrap();
        assert_eq!(grid.shape(), [2, 16, 32]);
        assert_eq!(grid.as_slice().len(), 2 * 16 * 32);
    }

    #[test]
    fn a_sensor_that_cannot_be_padded_is_an_error() {
        let message = VoxelGrid::new(SensorSize::new(u16::MAX, u16::MAX), 2)
            .unwrap_err()
            .to_string();
        assert!(message.contains("65535x65535"), "{message}");
    }

    #[test]
    fn time_is_split_linearly_between_bins() {
        let mut grid = VoxelGrid::new(SENSOR, 3).unwrap();
        // t* = 2 · 250 / 1000 = 0.5: half in bin 0, half in bin 1.
        grid.accumulate(&[Event::new(250, 4, 2, true)], window());
        // t* = 2 exactly: all in the last bin.
        grid.accumulate(&[Event::new(1_000, 5, 2, false)], window());
        let plane = grid.padded().pixels();
        let at = |bin: usize, x: usize, y: usize| grid.as_slice()[bin * plane + y * 32 + x];
        assert_eq!((at(0, 4, 2), at(1, 4, 2), at(2, 4, 2)), (0.5, 0.5, 0.0));
        assert_eq!((at(0, 5, 2), at(1, 5, 2), at(2, 5, 2)), (0.0, 0.0, -1.0));
    }

    #[test]
    fn polarity_values_are_plus_and_minus_one() {
        assert_eq!(polarity_value(&Event::new(0, 0, 0, true)), 1.0);
        assert_eq!(polarity_value(&Event::new(0, 0, 0, false)), -1.0);
    }

    #[test]
    fn single_bin_grid_counts_polarities() {
        let mut grid = VoxelGrid::new(SENSOR, 1).unwrap();
        let events = [Event::new(10, 1, 1, true), Event::new(20, 1, 1, true)];
        grid.accumulate(&events, window());
        assert_eq!(grid.as_slice()[32 + 1], 2.0);
    }

    #[test]
    fn events_outside_sensor_or_window_are_counted_not_splatted() {
        let mut grid = VoxelGrid::new(SENSOR, 2).unwrap();
        let events = [
            Event::new(0, 21, 0, true),
            Event::new(0, 0, 13, true),
            Event::new(-1, 0, 0, true),
            Event::new(1_001, 0, 0, true),
            Event::new(500, 0, 0, true),
        ];
        let counts = grid.accumulate(&events, window());
        assert_eq!(
            counts,
            SplatCounts {
                splatted: 1,
                outside_sensor: 2,
                outside_window: 2
            }
        );
        assert_eq!(grid.as_slice().iter().sum::<f32>(), 1.0);
        grid.clear();
        assert!(grid.as_slice().iter().all(|&cell| cell == 0.0));
        assert_eq!(grid.counts(), SplatCounts::default());
    }

    #[test]
    fn constant_non_zero_cells_only_lose_their_mean() {
        let mut grid = VoxelGrid::new(SENSOR, 1).unwrap();
        grid.accumulate(
            &[Event::new(0, 0, 0, true), Event::new(0, 3, 3, true)],
            window(),
        );
        let stats = grid.normalise();
        assert_eq!((stats.non_zero_cells, stats.mean, stats.std), (2, 1.0, 0.0));
        assert!(grid.as_slice().iter().all(|&cell| cell == 0.0));
    }

    #[test]
    fn bad_shapes_are_rejected() {
        assert_eq!(VoxelGrid::new(SENSOR, 0).unwrap_err(), VoxelError::ZeroBins);
        assert!(matches!(
            VoxelGrid::new(SensorSize::new(0, 5), 2),
            Err(VoxelError::EmptySensor { .. })
        ));
        assert_eq!(
            VoxelGrid::downsampled(SENSOR, 2, 0).unwrap_err(),
            VoxelError::ZeroDownsample
        );
    }

    #[test]
    fn a_downsampled_grid_is_the_binned_sensor_padded() {
        let grid = VoxelGrid::downsampled(SensorSize::new(1280, 720), 2, 2).unwrap();
        assert_eq!(grid.shape(), [2, 368, 640]);
        assert_eq!(grid.sensor(), SensorSize::new(1280, 720));
        assert_eq!(grid.downsample(), 2);
    }

    fn arbitrary_events() -> impl Strategy<Value = Vec<Event>> {
        prop::collection::vec(
            (
                0i64..=1_000,
                0u16..SENSOR.width,
                0u16..SENSOR.height,
                any::<bool>(),
            )
                .prop_map(|(t, x, y, on)| Event::new(t, x, y, on)),
            1..400,
        )
    }

    fn padding_is_zero(grid: &VoxelGrid) -> bool {
        let [bins, height, width] = grid.shape();
        (0..bins * height).all(|row| {
            let y = row % height;
            let cells = &grid.as_slice()[row * width..(row + 1) * width];
            if y >= usize::from(SENSOR.height) {
                cells.iter().all(|&cell| cell == 0.0)
            } else {
                cells[usize::from(SENSOR.width)..]
                    .iter()
                    .all(|&cell| cell == 0.0)
            }
        })
    }

    proptest! {
        #[test]
        fn a_downsampled_cell_holds_the_sum_of_its_pixels(
            events in arbitrary_events(),
            bins in 1usize..5,
            factor in 1u16..5,
        ) {
            let mut per_pixel = VoxelGrid::new(SENSOR, bins).unwrap();
            per_pixel.accumulate(&events, window());
            let mut binned = VoxelGrid::downsampled(SENSOR, bins, factor).unwrap();
            binned.accumulate(&events, window());
            let [_, pixel_rows, pixel_stride] = per_pixel.shape();
            let [_, cell_rows, cell_stride] = binned.shape();
            let mut expected = vec![0.0f32; binned.as_slice().len()];
            let factor = usize::from(factor);
            for bin in 0..bins {
                for y in 0..usize::from(SENSOR.height) {
                    for x in 0..usize::from(SENSOR.width) {
                        let value = per_pixel.as_slice()[(bin * pixel_rows + y) * pixel_stride + x];
                        expected[(bin * cell_rows + y / factor) * cell_stride + x / factor] += value;
                    }
                }
            }
            for (cell, want) in binned.as_slice().iter().zip(&expected) {
                prop_assert!((cell - want).abs() < 1e-4, "{} against {}", cell, want);
            }
            prop_assert_eq!(binned.counts(), per_pixel.counts());
        }

        #[test]
        fn total_equals_on_minus_off(events in arbitrary_events(), bins in 1usize..5) {
            let mut grid = VoxelGrid::new(SENSOR, bins).unwrap();
            grid.accumulate(&events, window());
            let total: f64 = grid.as_slice().iter().map(|&cell| f64::from(cell)).sum();
            let on = events.iter().filter(|e| e.is_on()).count() as f64;
            let off = events.len() as f64 - on;
            prop_assert!((total - (on - off)).abs() < 1e-3 * events.len() as f64);
            prop_assert!(padding_is_zero(&grid));
        }

        #[test]
        fn normalised_non_zero_cells_are_standardised(events in arbitrary_events()) {
            let mut grid = VoxelGrid::new(SENSOR, 2).unwrap();
            grid.accumulate(&events, window());
            let before = grid.normalise();
            prop_assert!(padding_is_zero(&grid));
            let after = grid.non_zero_stats();
            // A cell equal to the mean becomes zero and leaves the non-zero set, so the check
            // is done over the cells that were non-zero before.
            prop_assert!(after.non_zero_cells <= before.non_zero_cells);
            if before.std > 0.0 {
                let values: Vec<f64> = grid.as_slice().iter().map(|&c| f64::from(c)).collect();
                let sum: f64 = values.iter().sum();
                let squares: f64 = values.iter().map(|v| v * v).sum();
                let n = before.non_zero_cells as f64;
                let mean = sum / n;
                prop_assert!(mean.abs() < 1e-4, "mean {}", mean);
                if before.non_zero_cells > 1 {
                    let std = ((squares - n * mean * mean) / (n - 1.0)).sqrt();
                    prop_assert!((std - 1.0).abs() < 1e-3, "std {}", std);
                }
            }
        }
    }
}
