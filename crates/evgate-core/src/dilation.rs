//! Square dilation of a map: every cell takes the maximum over the (2r + 1)-cell square around
//! it, clipped to the map. On mask logits this draws the gate's keep regions from the
//! forecasts before thresholding; on a binary mask it is the binary dilation by the same square.

/// A value a map may hold: ordered by [`Dilatable::max`], with a value no cell is below.
trait Dilatable: Copy {
    /// Below or equal to every value, so that it stands for the cells outside the map.
    const LOWEST: Self;
    fn max(self, other: Self) -> Self;
}

impl Dilatable for f32 {
    const LOWEST: Self = f32::NEG_INFINITY;
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        // A select rather than `f32::max`, so that the loops compile to vector compares.
        if other > self {
            other
        } else {
            self
        }
    }
}

impl Dilatable for bool {
    const LOWEST: Self = false;
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        self | other
    }
}

/// Buffers the dilations reuse from call to call.
#[derive(Debug)]
pub struct DilationScratch<T> {
    line: Vec<T>,
    spare_line: Vec<T>,
    rows: Vec<T>,
    spare_rows: Vec<T>,
}

impl<T> Default for DilationScratch<T> {
    fn default() -> Self {
        Self {
            line: Vec::new(),
            spare_line: Vec::new(),
            rows: Vec::new(),
            spare_rows: Vec::new(),
        }
    }
}

/// Mask logits dilated by `radius` cells (see `dilate_square` below): a keep region before its
/// threshold.
pub fn dilate_logits(
    values: &[f32],
    width: usize,
    height: usize,
    radius: usize,
    scratch: &mut DilationScratch<f32>,
    out: &mut Vec<f32>,
) {
    dilate_square(values, width, height, radius, scratch, out);
}

/// A binary mask dilated by `radius` cells (see `dilate_square` below).
pub fn dilate_mask(
    values: &[bool],
    width: usize,
    height: usize,
    radius: usize,
    scratch: &mut DilationScratch<bool>,
    out: &mut Vec<bool>,
) {
    dilate_square(values, width, height, radius, scratch, out);
}

/// A `width`×`height` row-major map (`values.len()` must be `width · height`) dilated by
/// `radius` cells into `out` (resized as needed).
///
/// Separable (rows, then columns), each direction padded with [`Dilatable::LOWEST`] and
/// reduced by doubling: maxima over spans of 1, 2, 4, … cells, each one pass over the data,
/// until the span s is the largest power of two within the window w = 2r + 1; the window is
/// then the union of the spans starting at its two ends, [x, x + s) ∪ [x + w − s, x + w). So a
/// radius of 12 costs 5 passes per direction, not 24, and every pass is a vectorised maximum
/// of two slices.
// Generic code is compiled where it is instantiated; the two concrete entry points above keep it
// in this crate, which test builds optimise (the workspace's dev profile).
fn dilate_square<T: Dilatable>(
    values: &[T],
    width: usize,
    height: usize,
    radius: usize,
    scratch: &mut DilationScratch<T>,
    out: &mut Vec<T>,
) {
    assert_eq!(values.len(), width * height, "a {width}x{height} map");
    out.clear();
    out.extend_from_slice(values);
    if radius == 0 || values.is_empty() {
        return;
    }
    let window = 2 * radius + 1;
    let padded_width = width + 2 * radius;
    for (row, source) in out.chunks_exact_mut(width).zip(values.chunks_exact(width)) {
        let line = &mut scratch.line;
        line.clear();
        line.resize(radius, T::LOWEST);
        line.extend_from_slice(source);
        line.resize(padded_width, T::LOWEST);
        let (spans, span) = span_maxima(line, &mut scratch.spare_line, 1, window);
        let spans = &spans[..];
        max_of_pair(
            row,
            &spans[..width],
            &spans[window - span..window - span + width],
        );
    }

    // The same down the columns, a row of cells at a time.
    let rows = &mut scratch.rows;
    rows.clear();
    rows.resize(radius * width, T::LOWEST);
    rows.extend_from_slice(out);
    rows.resize((height + 2 * radius) * width, T::LOWEST);
    let (spans, span) = span_maxima(rows, &mut scratch.spare_rows, width, window);
    let spans = &spans[..];
    let offset = (window - span) * width;
    max_of_pair(
        out,
        &spans[..height * width],
        &spans[offset..offset + height * width],
    );
}

/// Turns `data`, a sequence of units of `unit` cells, into the maxima over spans of `s` units
/// (s the largest power of two ≤ `window`), ping-ponging with `spare`; returns the buffer that
/// holds them and s. The last units' spans are cut short by the end of the data.
fn span_maxima<'a, T: Dilatable>(
    data: &'a mut Vec<T>,
    spare: &'a mut Vec<T>,
    unit: usize,
    window: usize,
) -> (&'a mut Vec<T>, usize) {
    let (mut current, mut next) = (data, spare);
    let mut span = 1;
    while 2 * span <= window {
        let shift = span * unit;
        let length = current.len() - shift;
        // Every cell is written below; only the first use sizes the buffer.
        next.resize(current.len(), T::LOWEST);
        max_of_pair(&mut next[..length], &current[..length], &current[shift..]);
        next[length..].copy_from_slice(&current[length..]);
        std::mem::swap(&mut current, &mut next);
        span *= 2;
    }
    (current, span)
}

#[inline(always)]
fn max_of_pair<T: Dilatable>(target: &mut [T], left: &[T], right: &[T]) {
    for ((value, &a), &b) in target.iter_mut().zip(left).zip(right) {
        *value = a.max(b);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn dilated_by_definition(
        values: &[f32],
        width: usize,
        height: usize,
        radius: usize,
    ) -> Vec<f32> {
        let mut out = Vec::with_capacity(values.len());
        for y in 0..height {
            for x in 0..width {
                let ys = y.saturating_sub(radius)..=(y + radius).min(height - 1);
                let xs = x.saturating_sub(radius)..=(x + radius).min(width - 1);
                let maximum = ys
                    .flat_map(|yy| xs.clone().map(move |xx| values[yy * width + xx]))
                    .fold(f32::NEG_INFINITY, f32::max);
                out.push(maximum);
            }
        }
        out
    }

    proptest! {
        #[test]
        fn every_cell_takes_the_maximum_of_its_clipped_square(
            (width, height, values) in (1usize..24, 1usize..24).prop_flat_map(|(w, h)| {
                (Just(w), Just(h), proptest::collection::vec(-50i8..50, w * h))
            }),
            radius in 0usize..18,
        ) {
            let values: Vec<f32> = values.into_iter().map(f32::from).collect();
            let (mut scratch, mut out) = (DilationScratch::default(), Vec::new());
            dilate_square(&values, width, height, radius, &mut scratch, &mut out);
            prop_assert_eq!(&out, &dilated_by_definition(&values, width, height, radius));
            // Reused buffers give the same answer.
            dilate_square(&values, width, height, radius, &mut scratch, &mut out);
            prop_assert_eq!(out, dilated_by_definition(&values, width, height, radius));
        }
    }

    #[test]
    fn a_single_pixel_grows_into_a_square_clipped_at_the_border() {
        let (width, height) = (6, 5);
        let mut mask = vec![false; width * height];
        mask[width + 1] = true;
        let (mut scratch, mut out) = (DilationScratch::default(), Vec::new());
        dilate_square(&mask, width, height, 2, &mut scratch, &mut out);
        let set: Vec<(usize, usize)> = (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .filter(|&(x, y)| out[y * width + x])
            .collect();
        let expected: Vec<(usize, usize)> =
            (0..4).flat_map(|y| (0..4).map(move |x| (x, y))).collect();
        assert_eq!(set, expected);
    }

    #[test]
    fn float_logits_dilate_like_a_max_pool() {
        let logits = [-3.0f32, 1.5, -0.5, 0.25, -2.0, 4.0];
        let (mut scratch, mut out) = (DilationScratch::default(), Vec::new());
        dilate_square(&logits, 3, 2, 1, &mut scratch, &mut out);
        assert_eq!(out, vec![1.5, 4.0, 4.0, 1.5, 4.0, 4.0]);
    }
}
