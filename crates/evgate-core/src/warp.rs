//! Backward warping of a logit map by a flow field: out(p) = in(p − ψ(p)), the paper's way of
//! moving the current mask to a future time.

use crate::geometry::SensorSize;

/// Why a warp could not run.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum WarpError {
    #[error("warp input has {actual} values, a {size} map needs {expected}")]
    InputLength {
        actual: usize,
        expected: usize,
        size: SensorSize,
    },
    #[error("flow has {actual} values, a [2, {height}, {width}] field needs {expected}")]
    FlowLength {
        actual: usize,
        expected: usize,
        width: u16,
        height: u16,
    },
    #[error("warp output has {actual} values, a {size} map needs {expected}")]
    OutputLength {
        actual: usize,
        expected: usize,
        size: SensorSize,
    },
}

/// Warps `input` (`[H, W]` row-major, H × W = `size`) by `flow` (`[2, H, W]`: the x
/// displacement plane, then the y plane, in pixels) into `output`:
/// output(x, y) = input(x − dx(x, y), y − dy(x, y)), sampled bilinearly; taps outside the map
/// read 0 and a non-finite sample position gives 0. This equals PyTorch's
/// `grid_sample(mode="bilinear", padding_mode="zeros", align_corners=True)` expressed in
/// pixels.
pub fn warp_backward(
    input: &[f32],
    flow: &[f32],
    size: SensorSize,
    output: &mut [f32],
) -> Result<(), WarpError> {
    let pixels = size.pixels();
    if input.len() != pixels {
        return Err(WarpError::InputLength {
            actual: input.len(),
            expected: pixels,
            size,
        });
    }
    if flow.len() != 2 * pixels {
        return Err(WarpError::FlowLength {
            actual: flow.len(),
            expected: 2 * pixels,
            width: size.width,
            height: size.height,
        });
    }
    if output.len() != pixels {
        return Err(WarpError::OutputLength {
            actual: output.len(),
            expected: pixels,
            size,
        });
    }
    let width = usize::from(size.width);
    let (flow_x, flow_y) = flow.split_at(pixels);
    let tap = |column: isize, row: isize| -> f32 {
        if column < 0 || row < 0 || column >= width as isize || row >= size.height as isize {
            0.0
        } else {
            input[row as usize * width + column as usize]
        }
    };
    for (index, out) in output.iter_mut().enumerate() {
        let sample_x = (index % width) as f32 - flow_x[index];
        let sample_y = (index / width) as f32 - flow_y[index];
        if !(sample_x.is_finite() && sample_y.is_finite()) {
            *out = 0.0;
            continue;
        }
        let (left, top) = (sample_x.floor(), sample_y.floor());
        let (right_weight, bottom_weight) = (sample_x - left, sample_y - top);
        // Saturating float→int casts keep far-away samples far away (and out of the map).
        let (column, row) = (left as isize, top as isize);
        let top_row = tap(column, row) * (1.0 - right_weight)
            + tap(column.saturating_add(1), row) * right_weight;
        let bottom_row = tap(column, row.saturating_add(1)) * (1.0 - right_weight)
            + tap(column.saturating_add(1), row.saturating_add(1)) * right_weight;
        *out = top_row * (1.0 - bottom_weight) + bottom_row * bottom_weight;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn half_pixel_shift_averages_neighbours() {
        let size = SensorSize::new(3, 1);
        let input = [2.0, 4.0, 8.0];
        // dx = 0.5 everywhere: out(x) = in(x − 0.5).
        let flow = [0.5, 0.5, 0.5, 0.0, 0.0, 0.0];
        let mut output = [0.0; 3];
        warp_backward(&input, &flow, size, &mut output).unwrap();
        assert_eq!(output, [1.0, 3.0, 6.0]);
    }

    #[test]
    fn non_finite_flow_reads_zero() {
        let size = SensorSize::new(2, 1);
        let mut output = [9.0; 2];
        let flow = [f32::NAN, f32::INFINITY, 0.0, 0.0];
        warp_backward(&[1.0, 1.0], &flow, size, &mut output).unwrap();
        assert_eq!(output, [0.0, 0.0]);
    }

    #[test]
    fn wrong_lengths_are_rejected() {
        let size = SensorSize::new(2, 2);
        let mut output = [0.0; 4];
        assert!(matches!(
            warp_backward(&[0.0; 4], &[0.0; 7], size, &mut output),
            Err(WarpError::FlowLength {
                actual: 7,
                expected: 8,
                ..
            })
        ));
        assert!(matches!(
            warp_backward(&[0.0; 3], &[0.0; 8], size, &mut output),
            Err(WarpError::InputLength { actual: 3, .. })
        ));
        assert!(matches!(
            warp_backward(&[0.0; 4], &[0.0; 8], size, &mut output[..3]),
            Err(WarpError::OutputLength { actual: 3, .. })
        ));
    }

    fn map() -> impl Strategy<Value = (SensorSize, Vec<f32>)> {
        (1u16..12, 1u16..12).prop_flat_map(|(width, height)| {
            let size = SensorSize::new(width, height);
            (
                Just(size),
                prop::collection::vec(-50.0f32..50.0, size.pixels()),
            )
        })
    }

    proptest! {
        #[test]
        fn zero_flow_is_identity((size, input) in map()) {
            let flow = vec![0.0; 2 * size.pixels()];
            let mut output = vec![f32::NAN; size.pixels()];
            warp_backward(&input, &flow, size, &mut output).unwrap();
            prop_assert_eq!(output, input);
        }

        #[test]
        fn integer_flow_is_exact_shift((size, input) in map(), dx in -13i32..13, dy in -13i32..13) {
            let pixels = size.pixels();
            let mut flow = vec![dx as f32; pixels];
            flow.extend(std::iter::repeat_n(dy as f32, pixels));
            let mut output = vec![f32::NAN; pixels];
            warp_backward(&input, &flow, size, &mut output).unwrap();
            let (width, height) = (i32::from(size.width), i32::from(size.height));
            for y in 0..height {
                for x in 0..width {
                    let (source_x, source_y) = (x - dx, y - dy);
                    let expected = if (0..width).contains(&source_x) && (0..height).contains(&source_y) {
                        input[(source_y * width + source_x) as usize]
                    } else {
                        0.0
                    };
                    prop_assert_eq!(output[(y * width + x) as usize], expected);
                }
            }
        }
    }
}
