//! Binary pixel masks packed one bit per pixel (row-major, least significant bit first), the
//! form in which masks travel through shared memory and are looked up by the gate.

use crate::bitset::words_for;
use crate::geometry::SensorSize;

/// Why a mask could not be built or changed.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum MaskError {
    #[error("mask needs a non-empty size, got {size}")]
    EmptySize { size: SensorSize },
    #[error("logit row stride {row_stride} is smaller than the mask width {width}")]
    StrideTooSmall { row_stride: usize, width: u16 },
    #[error(
        "logit map has {actual} values, a {size} mask with row stride {row_stride} needs at \
         least {required}"
    )]
    TooFewLogits {
        actual: usize,
        required: usize,
        size: SensorSize,
        row_stride: usize,
    },
    #[error("a {size} mask takes {expected} u64 words, got {actual}")]
    WordCount {
        expected: usize,
        actual: usize,
        size: SensorSize,
    },
    #[error("word {word} sets bits beyond the last pixel of a {size} mask")]
    BitsBeyondLastPixel { word: usize, size: SensorSize },
    #[error("pixel ({x}, {y}) lies outside the {size} mask")]
    PixelOutside { x: u16, y: u16, size: SensorSize },
    #[error("a mask cannot be drawn from logits binned 0x0 pixels")]
    ZeroDownsample,
}

fn validate_words(size: SensorSize, words: &[u64]) -> Result<(), MaskError> {
    if size.pixels() == 0 {
        return Err(MaskError::EmptySize { size });
    }
    let expected = words_for(size.pixels());
    if words.len() != expected {
        return Err(MaskError::WordCount {
            expected,
            actual: words.len(),
            size,
        });
    }
    let used_bits = size.pixels() % 64;
    if used_bits != 0 && words[expected - 1] >> used_bits != 0 {
        return Err(MaskError::BitsBeyondLastPixel {
            word: expected - 1,
            size,
        });
    }
    Ok(())
}

/// A borrowed bit mask, e.g. over words that live in shared memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MaskView<'a> {
    size: SensorSize,
    words: &'a [u64],
}

impl<'a> MaskView<'a> {
    /// Views `words` as a mask of `size`; the word count must be [`words_for`]`(size.pixels())` and the
    /// bits past the last pixel must be zero.
    pub fn new(size: SensorSize, words: &'a [u64]) -> Result<Self, MaskError> {
        validate_words(size, words)?;
        Ok(Self { size, words })
    }

    pub fn size(&self) -> SensorSize {
        self.size
    }

    pub fn as_words(&self) -> &'a [u64] {
        self.words
    }

    /// The bit of pixel (x, y); pixels outside the mask read as not set.
    pub fn get(&self, x: u16, y: u16) -> bool {
        if x >= self.size.width || y >= self.size.height {
            return false;
        }
        let index = self.size.index(x, y);
        self.words[index / 64] >> (index % 64) & 1 == 1
    }

    /// Number of set pixels.
    /// One flag per pixel, row-major, for code that scores masks pixel by pixel.
    pub fn to_bools(&self) -> Vec<bool> {
        (0..self.size.pixels())
            .map(|pixel| self.words[pixel / 64] >> (pixel % 64) & 1 == 1)
            .collect()
    }

    pub fn count_ones(&self) -> usize {
        self.words
            .iter()
            .map(|word| word.count_ones() as usize)
            .sum()
    }
}

/// An owned bit mask.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BitMask {
    size: SensorSize,
    words: Vec<u64>,
}

impl BitMask {
    /// An all-clear mask.
    pub fn new(size: SensorSize) -> Result<Self, MaskError> {
        if size.pixels() == 0 {
            return Err(MaskError::EmptySize { size });
        }
        Ok(Self {
            size,
            words: vec![0; words_for(size.pixels())],
        })
    }

    /// Thresholds a logit map: pixel (x, y) is set when `logits[y · row_stride + x] >
    /// threshold_logit` (NaN is never set). With a threshold of 0 this is sigmoid(l) > 0.5,
    /// the paper's prediction rule. `row_stride` lets the map be wider than the mask, as the
    /// network's padded output is.
    pub fn from_logits(
        logits: &[f32],
        size: SensorSize,
        row_stride: usize,
        threshold_logit: f32,
    ) -> Result<Self, MaskError> {
        let mut mask = Self::new(size)?;
        mask.fill_from_logits(logits, row_stride, threshold_logit)?;
        Ok(mask)
    }

    /// [`from_logits`](Self::from_logits) into this mask's buffer, without allocating.
    pub fn fill_from_logits(
        &mut self,
        logits: &[f32],
        row_stride: usize,
        threshold_logit: f32,
    ) -> Result<(), MaskError> {
        let size = self.size;
        let width = usize::from(size.width);
        check_logits(logits, size, row_stride)?;
        // Comparisons in fixed blocks of 32, which the compiler turns into vector compares and
        // sign-bit moves, packed into words by a running writer: 640×480 × 9 planes took 4.3 ms
        // per window bit by bit (`git show dd99da7:BENCHMARKS.md`, "Inference").
        let mut writer = BitWriter::new(&mut self.words);
        for row in logits.chunks(row_stride).take(usize::from(size.height)) {
            let mut blocks = row[..width].chunks_exact(32);
            for block in &mut blocks {
                let block: &[f32; 32] = block.try_into().expect("chunks_exact gives 32");
                writer.push(bits_above(block, threshold_logit), 32);
            }
            let rest = blocks.remainder();
            writer.push(bits_above(rest, threshold_logit), rest.len() as u32);
        }
        writer.finish();
        Ok(())
    }

    /// Fills this mask from logits over its pixels binned `downsample`×`downsample`
    /// ([`SensorSize::binned`]): every pixel takes the verdict of its cell, so that events are
    /// still judged at full resolution when the network ran on a binned grid.
    pub fn fill_from_binned_logits(
        &mut self,
        logits: &[f32],
        row_stride: usize,
        threshold_logit: f32,
        downsample: u16,
    ) -> Result<(), MaskError> {
        match downsample {
            0 => return Err(MaskError::ZeroDownsample),
            1 => return self.fill_from_logits(logits, row_stride, threshold_logit),
            _ => {}
        }
        let size = self.size;
        let cells = size.binned(downsample);
        check_logits(logits, cells, row_stride)?;
        let (width, height) = (usize::from(size.width), usize::from(size.height));
        let factor = usize::from(downsample);
        // One row of cells expands to one row of pixels, which `downsample` rows repeat.
        let mut row_words = vec![0; words_for(width)];
        let mut writer = BitWriter::new(&mut self.words);
        for (cell_row, row) in logits
            .chunks(row_stride)
            .take(usize::from(cells.height))
            .enumerate()
        {
            let mut row_writer = BitWriter::new(&mut row_words);
            for (cell, &logit) in row[..usize::from(cells.width)].iter().enumerate() {
                let pixels = factor.min(width - cell * factor);
                row_writer.push_run(logit > threshold_logit, pixels);
            }
            row_writer.finish();
            let rows = factor.min(height - cell_row * factor);
            for _ in 0..rows {
                writer.push_words(&row_words, width);
            }
        }
        writer.finish();
        Ok(())
    }

    /// Takes ownership of packed words (see [`MaskView::new`] for the checks).
    pub fn from_words(size: SensorSize, words: Vec<u64>) -> Result<Self, MaskError> {
        validate_words(size, &words)?;
        Ok(Self { size, words })
    }

    pub fn view(&self) -> MaskView<'_> {
        MaskView {
            size: self.size,
            words: &self.words,
        }
    }

    pub fn size(&self) -> SensorSize {
        self.size
    }

    pub fn as_words(&self) -> &[u64] {
        &self.words
    }

    /// The bit of pixel (x, y); pixels outside the mask read as not set.
    pub fn get(&self, x: u16, y: u16) -> bool {
        self.view().get(x, y)
    }

    /// Sets or clears pixel (x, y).
    pub fn set(&mut self, x: u16, y: u16, value: bool) -> Result<(), MaskError> {
        if x >= self.size.width || y >= self.size.height {
            return Err(MaskError::PixelOutside {
                x,
                y,
                size: self.size,
            });
        }
        let index = self.size.index(x, y);
        let bit = 1u64 << (index % 64);
        if value {
            self.words[index / 64] |= bit;
        } else {
            self.words[index / 64] &= !bit;
        }
        Ok(())
    }

    /// Number of set pixels.
    pub fn count_ones(&self) -> usize {
        self.view().count_ones()
    }
}

/// A `size` map of logits with `row_stride` values per row must hold the last row's pixels.
fn check_logits(logits: &[f32], size: SensorSize, row_stride: usize) -> Result<(), MaskError> {
    let width = usize::from(size.width);
    if row_stride < width {
        return Err(MaskError::StrideTooSmall {
            row_stride,
            width: size.width,
        });
    }
    let required = (usize::from(size.height) - 1) * row_stride + width;
    if logits.len() < required {
        return Err(MaskError::TooFewLogits {
            actual: logits.len(),
            required,
            size,
            row_stride,
        });
    }
    Ok(())
}

/// Bit i set when `logits[i] > threshold_logit` (NaN never), for up to 64 logits. Inlined, so
/// that a fixed-size block compiles to vector compares.
#[inline(always)]
fn bits_above(logits: &[f32], threshold_logit: f32) -> u64 {
    logits.iter().enumerate().fold(0, |bits, (bit, &logit)| {
        bits | u64::from(logit > threshold_logit) << bit
    })
}

/// Appends runs of up to 32 bits to consecutive words, least significant bit first.
struct BitWriter<'a> {
    words: &'a mut [u64],
    next: usize,
    pending: u64,
    filled: u32,
}

impl<'a> BitWriter<'a> {
    fn new(words: &'a mut [u64]) -> Self {
        Self {
            words,
            next: 0,
            pending: 0,
            filled: 0,
        }
    }

    /// Appends the low `count` bits of `bits` (the bits above them must be clear).
    fn push(&mut self, bits: u64, count: u32) {
        debug_assert!(count <= 32 && (count == 32 || bits >> count == 0));
        self.pending |= bits << self.filled;
        self.filled += count;
        if self.filled >= 64 {
            self.words[self.next] = self.pending;
            self.next += 1;
            self.filled -= 64;
            // The bits that did not fit in the stored word start the next one.
            self.pending = if self.filled == 0 {
                0
            } else {
                bits >> (count - self.filled)
            };
        }
    }

    /// Appends `count` copies of `bit`.
    fn push_run(&mut self, bit: bool, mut count: usize) {
        while count > 0 {
            let chunk = count.min(32) as u32;
            self.push(if bit { u64::MAX >> (64 - chunk) } else { 0 }, chunk);
            count -= chunk as usize;
        }
    }

    /// Appends the first `bits` bits of `words`.
    fn push_words(&mut self, words: &[u64], bits: usize) {
        for (index, &word) in words.iter().enumerate() {
            let count = (bits - index * 64).min(64) as u32;
            let low = count.min(32);
            self.push(word & (u64::MAX >> (64 - low)), low);
            if count > 32 {
                let high = count - 32;
                self.push((word >> 32) & (u64::MAX >> (64 - high)), high);
            }
        }
    }

    /// Stores the partial last word and clears the words after it.
    fn finish(self) {
        let mut next = self.next;
        if self.filled > 0 {
            self.words[next] = self.pending;
            next += 1;
        }
        self.words[next..].fill(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn logits_threshold_at_zero_with_stride() {
        let size = SensorSize::new(3, 2);
        // Stride 4: the fourth column is padding and must be ignored.
        let logits = [
            0.1,
            -0.1,
            0.0,
            9.0, //
            f32::NAN,
            5.0,
            -3.0,
            9.0,
        ];
        let mask = BitMask::from_logits(&logits, size, 4, 0.0).unwrap();
        let set: Vec<_> = (0..2)
            .flat_map(|y| (0..3).map(move |x| (x, y)))
            .filter(|&(x, y)| mask.get(x, y))
            .collect();
        assert_eq!(set, [(0, 0), (1, 1)]);
        assert_eq!(mask.count_ones(), 2);
        assert!(!mask.get(3, 0));
    }

    /// A reproducible stream of pseudo-random words (xorshift64) for logit maps.
    fn xorshift(seed: u64) -> impl Iterator<Item = u64> {
        let mut x = seed | 1;
        std::iter::repeat_with(move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        })
    }

    proptest! {
        #[test]
        fn every_pixel_takes_the_verdict_of_its_binned_cell(
            width in 1u16..300,
            height in 1u16..12,
            downsample in 1u16..40,
            padding in 0usize..20,
            seed in any::<u64>(),
        ) {
            let size = SensorSize::new(width, height);
            let cells = size.binned(downsample);
            let row_stride = usize::from(cells.width) + padding;
            let logits: Vec<f32> = xorshift(seed)
                .take(row_stride * usize::from(cells.height))
                .map(|x| (x % 2001) as f32 / 1000.0 - 1.0)
                .collect();
            let mut mask = BitMask::new(size).unwrap();
            mask.fill_from_logits(&vec![1.0; size.pixels()], usize::from(width), 0.0).unwrap();
            mask.fill_from_binned_logits(&logits, row_stride, 0.25, downsample).unwrap();
            for y in 0..height {
                for x in 0..width {
                    let cell = usize::from(y / downsample) * row_stride + usize::from(x / downsample);
                    prop_assert_eq!(mask.get(x, y), logits[cell] > 0.25, "pixel ({}, {})", x, y);
                }
            }
            prop_assert!(validate_words(size, mask.as_words()).is_ok());
        }
    }

    proptest! {
        #[test]
        fn blockwise_thresholding_sets_exactly_the_pixels_above_the_threshold(
            width in 1u16..200,
            height in 1u16..6,
            padding in 0usize..40,
            threshold_logit in -1.0f32..1.0,
            seed in any::<u64>(),
        ) {
            let size = SensorSize::new(width, height);
            let row_stride = usize::from(width) + padding;
            let logits: Vec<f32> = xorshift(seed)
                .take(row_stride * usize::from(height))
                .map(|x| {
                    match x % 17 {
                        0 => f32::NAN,
                        1 => threshold_logit,
                        _ => (x % 2001) as f32 / 1000.0 - 1.0,
                    }
                })
                .collect();
            // Start from a full mask: every bit must be rewritten.
            let mut words = vec![u64::MAX; words_for(size.pixels())];
            let used_bits = size.pixels() % 64;
            if used_bits != 0 {
                *words.last_mut().unwrap() = (1u64 << used_bits) - 1;
            }
            let mut mask = BitMask::from_words(size, words).unwrap();
            mask.fill_from_logits(&logits, row_stride, threshold_logit).unwrap();
            for y in 0..height {
                for x in 0..width {
                    let logit = logits[usize::from(y) * row_stride + usize::from(x)];
                    prop_assert_eq!(mask.get(x, y), logit > threshold_logit, "pixel ({}, {})", x, y);
                }
            }
            prop_assert_eq!(
                mask.count_ones() as usize,
                (0..usize::from(height))
                    .flat_map(|y| logits[y * row_stride..y * row_stride + usize::from(width)].iter())
                    .filter(|&&logit| logit > threshold_logit)
                    .count()
            );
        }
    }

    #[test]
    fn bad_logit_maps_are_rejected() {
        let size = SensorSize::new(3, 2);
        assert_eq!(
            BitMask::from_logits(&[0.0; 6], size, 2, 0.0).unwrap_err(),
            MaskError::StrideTooSmall {
                row_stride: 2,
                width: 3
            }
        );
        assert!(matches!(
            BitMask::from_logits(&[0.0; 6], size, 4, 0.0),
            Err(MaskError::TooFewLogits {
                actual: 6,
                required: 7,
                ..
            })
        ));
    }

    #[test]
    fn words_are_validated() {
        let size = SensorSize::new(10, 7);
        assert_eq!(words_for(size.pixels()), 2);
        assert!(matches!(
            BitMask::from_words(size, vec![0]),
            Err(MaskError::WordCount {
                expected: 2,
                actual: 1,
                ..
            })
        ));
        assert!(matches!(
            MaskView::new(size, &[0, 1 << 6]),
            Err(MaskError::BitsBeyondLastPixel { word: 1, .. })
        ));
        assert!(MaskView::new(size, &[0, 1 << 5]).unwrap().get(9, 6));
    }

    #[test]
    fn set_outside_is_an_error() {
        let mut mask = BitMask::new(SensorSize::new(4, 4)).unwrap();
        assert!(matches!(
            mask.set(4, 0, true),
            Err(MaskError::PixelOutside { x: 4, y: 0, .. })
        ));
    }

    proptest! {
        #[test]
        fn set_get_and_word_round_trip(
            width in 1u16..80, height in 1u16..20,
            pixels in prop::collection::vec((0u16..80, 0u16..20, any::<bool>()), 0..100),
        ) {
            let size = SensorSize::new(width, height);
            let mut mask = BitMask::new(size).unwrap();
            let mut expected = vec![false; size.pixels()];
            for (x, y, value) in pixels {
                if x < width && y < height {
                    mask.set(x, y, value).unwrap();
                    expected[size.index(x, y)] = value;
                }
            }
            for y in 0..height {
                for x in 0..width {
                    prop_assert_eq!(mask.get(x, y), expected[size.index(x, y)]);
                }
            }
            prop_assert_eq!(mask.count_ones(), expected.iter().filter(|&&b| b).count());
            let copy = BitMask::from_words(size, mask.as_words().to_vec()).unwrap();
            prop_assert_eq!(&copy, &mask);
        }
    }
}
