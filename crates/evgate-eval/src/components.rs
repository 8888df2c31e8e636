//! Connected components of a binary mask with 8-connectivity: pixels that touch by an edge or a
//! corner belong to the same object, so a thin diagonal object is not split into pieces.

use evgate_core::SensorSize;

/// One connected component.
#[derive(Clone, Debug, PartialEq)]
pub struct Component {
    /// Number of pixels.
    pub area: u64,
    /// Mean column and row of its pixels.
    pub centroid: (f64, f64),
}

/// Component labels of every pixel (0 = not in the mask, k ≥ 1 = component k − 1).
#[derive(Clone, Debug, PartialEq)]
pub struct Components {
    pub labels: Vec<u32>,
    pub components: Vec<Component>,
}

impl Components {
    /// Labels `mask` (row-major, `size.pixels()` long) by flood fill.
    ///
    /// # Panics
    /// When `mask.len() != size.pixels()`; callers check sizes where data enter the harness.
    pub fn label(mask: &[bool], size: SensorSize) -> Self {
        assert_eq!(
            mask.len(),
            size.pixels(),
            "mask does not match the frame size"
        );
        let (width, height) = (size.width as i64, size.height as i64);
        let mut labels = vec![0u32; mask.len()];
        let mut components = Vec::new();
        let mut stack = Vec::new();
        for start in 0..mask.len() {
            if !mask[start] || labels[start] != 0 {
                continue;
            }
            let label = components.len() as u32 + 1;
            labels[start] = label;
            stack.push(start);
            let (mut area, mut sum_x, mut sum_y) = (0u64, 0f64, 0f64);
            while let Some(pixel) = stack.pop() {
                let (x, y) = ((pixel as i64) % width, (pixel as i64) / width);
                area += 1;
                sum_x += x as f64;
                sum_y += y as f64;
                for (dx, dy) in NEIGHBOURS {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= width || ny >= height {
                        continue;
                    }
                    let neighbour = (ny * width + nx) as usize;
                    if mask[neighbour] && labels[neighbour] == 0 {
                        labels[neighbour] = label;
                        stack.push(neighbour);
                    }
                }
            }
            components.push(Component {
                area,
                centroid: (sum_x / area as f64, sum_y / area as f64),
            });
        }
        Self { labels, components }
    }

    pub fn len(&self) -> usize {
        self.components.len()
    }

    pub fn is_empty(&self) -> bool {
        self.components.is_empty()
    }
}

const NEIGHBOURS: [(i64, i64); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(rows: &[&str]) -> (Vec<bool>, SensorSize) {
        let size = SensorSize::new(rows[0].len() as u16, rows.len() as u16);
        let pixels = rows
            .iter()
            .flat_map(|r| r.chars().map(|c| c == '#'))
            .collect();
        (pixels, size)
    }

    #[test]
    fn diagonal_neighbours_join_and_gaps_split() {
        let (pixels, size) = mask(&["#...#", ".#..#", "....."]);
        let found = Components::label(&pixels, size);
        assert_eq!(found.len(), 2);
        assert_eq!(found.components[0].area, 2);
        assert_eq!(found.components[0].centroid, (0.5, 0.5));
        assert_eq!(found.components[1].area, 2);
        assert_eq!(found.components[1].centroid, (4.0, 0.5));
        assert_eq!(found.labels[5 + 1], 1);
        assert_eq!(found.labels[4], 2);
    }

    #[test]
    fn empty_mask_has_no_components() {
        let (pixels, size) = mask(&["...", "..."]);
        let found = Components::label(&pixels, size);
        assert!(found.is_empty());
        assert!(found.labels.iter().all(|&l| l == 0));
    }

    #[test]
    fn u_shape_is_one_component() {
        let (pixels, size) = mask(&["#.#", "#.#", "###"]);
        assert_eq!(Components::label(&pixels, size).len(), 1);
    }
}
