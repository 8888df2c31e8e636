//! PNG line plots drawn directly on an RGB canvas with an embedded 8×8 bitmap font, so plots
//! render the same on any machine (no system fonts, no font-loading library).

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use font8x8::{UnicodeFonts, BASIC_FONTS, GREEK_FONTS, LATIN_FONTS};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum PlotError {
    #[error("cannot create plot file {path}: {source}")]
    Create {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot encode plot {path} as PNG: {source}")]
    Encode {
        path: PathBuf,
        source: png::EncodingError,
    },
    #[error("plot '{title}' has no finite point to draw")]
    NoData { title: String },
    #[error(
        "plot '{title}' uses a logarithmic x axis but series '{series}' has x = {x} (must be > 0)"
    )]
    NonPositiveLogX {
        title: String,
        series: String,
        x: f64,
    },
}

/// One named line.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

/// How the x axis is scaled and labelled.
#[derive(Clone, Debug, PartialEq)]
pub enum XAxis {
    /// Linear axis with ticks every `step`.
    Linear { step: f64 },
    /// Base-10 logarithmic axis from 10^`first_decade` to 10^`last_decade`, a tick per decade.
    Log10 { first_decade: i32, last_decade: i32 },
    /// Points at x = 0, 1, 2, … labelled with these names.
    Categories(Vec<String>),
}

/// A line plot with a y axis fixed to [y_min, y_max].
#[derive(Clone, Debug, PartialEq)]
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x_axis: XAxis,
    pub y_range: (f64, f64),
    pub y_step: f64,
    pub series: Vec<Series>,
}

const WIDTH: usize = 880;
const HEIGHT: usize = 520;
const LEFT: usize = 64;
const RIGHT: usize = 240;
const TOP: usize = 44;
const BOTTOM: usize = 64;
const PALETTE: [[u8; 3]; 8] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
];

struct Canvas {
    pixels: Vec<u8>,
}

impl Canvas {
    fn new() -> Self {
        Self {
            pixels: vec![255; WIDTH * HEIGHT * 3],
        }
    }

    fn set(&mut self, x: i64, y: i64, colour: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < WIDTH && (y as usize) < HEIGHT {
            let at = (y as usize * WIDTH + x as usize) * 3;
            self.pixels[at..at + 3].copy_from_slice(&colour);
        }
    }

    fn line(&mut self, from: (i64, i64), to: (i64, i64), colour: [u8; 3], thickness: i64) {
        let (mut x, mut y) = from;
        let (dx, dy) = ((to.0 - x).abs(), -(to.1 - y).abs());
        let (sx, sy) = (if x < to.0 { 1 } else { -1 }, if y < to.1 { 1 } else { -1 });
        let mut error = dx + dy;
        loop {
            for ox in 0..thickness {
                for oy in 0..thickness {
                    self.set(x + ox - thickness / 2, y + oy - thickness / 2, colour);
                }
            }
            if x == to.0 && y == to.1 {
                break;
            }
            let doubled = 2 * error;
            if doubled >= dy {
                error += dy;
                x += sx;
            }
            if doubled <= dx {
                error += dx;
                y += sy;
            }
        }
    }

    fn square(&mut self, centre: (i64, i64), half: i64, colour: [u8; 3]) {
        for y in -half..=half {
            for x in -half..=half {
                self.set(centre.0 + x, centre.1 + y, colour);
            }
        }
    }

    /// Draws `text` with its top-left corner at (x, y); characters missing from the font show
    /// as '?'.
    fn text(&mut self, x: i64, y: i64, text: &str, scale: i64, colour: [u8; 3]) {
        for (index, character) in text.chars().enumerate() {
            let glyph = BASIC_FONTS
                .get(character)
                .or_else(|| LATIN_FONTS.get(character))
                .or_else(|| GREEK_FONTS.get(character))
                .or_else(|| BASIC_FONTS.get('?'))
                .unwrap_or([0; 8]);
            let left = x + index as i64 * 8 * scale;
            for (row, bits) in glyph.iter().enumerate() {
                for column in 0..8 {
                    if bits >> column & 1 == 1 {
                        for sy in 0..scale {
                            for sx in 0..scale {
                                self.set(
                                    left + column * scale + sx,
                                    y + row as i64 * scale + sy,
                                    colour,
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    fn text_width(text: &str, scale: i64) -> i64 {
        text.chars().count() as i64 * 8 * scale
    }
}

fn format_tick(value: f64) -> String {
    if value.fract().abs() < 1e-9 {
        format!("{value:.0}")
    } else {
        format!("{value:.1}")
    }
}

impl LinePlot {
    /// Renders the plot to a PNG file.
    pub fn write_png(&self, path: &Path) -> Result<(), PlotError> {
        let canvas = self.render()?;
        let file = File::create(path).map_err(|source| PlotError::Create {
            path: path.to_path_buf(),
            source,
        })?;
        let mut encoder = png::Encoder::new(BufWriter::new(file), WIDTH as u32, HEIGHT as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        // Flat-coloured plots compress well; the reports are committed, so keep them small.
        encoder.set_compression(png::Compression::Best);
        let encode_error = |source| PlotError::Encode {
            path: path.to_path_buf(),
            source,
        };
        let mut writer = encoder.write_header().map_err(encode_error)?;
        writer
            .write_image_data(&canvas.pixels)
            .map_err(encode_error)?;
        writer.finish().map_err(encode_error)
    }

    fn x_transform(&self, x: f64) -> f64 {
        match self.x_axis {
            XAxis::Log10 { .. } => x.log10(),
            _ => x,
        }
    }

    fn render(&self) -> Result<Canvas, PlotError> {
        if let XAxis::Log10 { .. } = self.x_axis {
            for series in &self.series {
                if let Some(&(x, _)) = series.points.iter().find(|(x, _)| *x <= 0.0) {
                    return Err(PlotError::NonPositiveLogX {
                        title: self.title.clone(),
                        series: series.name.clone(),
                        x,
                    });
                }
            }
        }
        let xs: Vec<f64> = self
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, _)| self.x_transform(*x))
            .collect();
        let (x_min, mut x_max) = match &self.x_axis {
            XAxis::Categories(names) => (-0.5, names.len() as f64 - 0.5),
            XAxis::Log10 {
                first_decade,
                last_decade,
            } => (f64::from(*first_decade), f64::from(*last_decade)),
            XAxis::Linear { .. } => xs
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                    (lo.min(x), hi.max(x))
                }),
        };
        if !x_min.is_finite() || xs.is_empty() {
            return Err(PlotError::NoData {
                title: self.title.clone(),
            });
        }
        if x_max <= x_min {
            x_max = x_min + 1.0;
        }
        let (y_min, y_max) = self.y_range;
        let plot_width = (WIDTH - LEFT - RIGHT) as f64;
        let plot_height = (HEIGHT - TOP - BOTTOM) as f64;
        let to_pixel = |x: f64, y: f64| -> (i64, i64) {
            let px = LEFT as f64 + (x - x_min) / (x_max - x_min) * plot_width;
            let clamped = y.clamp(y_min, y_max);
            let py = TOP as f64 + (1.0 - (clamped - y_min) / (y_max - y_min)) * plot_height;
            (px.round() as i64, py.round() as i64)
        };
        let mut canvas = Canvas::new();
        let (black, grid) = ([0, 0, 0], [225, 225, 225]);
        let (left, right) = (LEFT as i64, (WIDTH - RIGHT) as i64);
        let (top, bottom) = (TOP as i64, (HEIGHT - BOTTOM) as i64);

        let mut y = y_min;
        while y <= y_max + 1e-9 {
            let (_, py) = to_pixel(x_min, y);
            canvas.line((left, py), (right, py), grid, 1);
            let label = format_tick(y);
            canvas.text(
                left - 6 - Canvas::text_width(&label, 1),
                py - 4,
                &label,
                1,
                black,
            );
            y += self.y_step;
        }
        let x_ticks: Vec<(f64, String)> = match &self.x_axis {
            XAxis::Linear { step } => {
                let mut ticks = Vec::new();
                let mut x = (x_min / step).ceil() * step;
                while x <= x_max + 1e-9 {
                    ticks.push((x, format_tick(x)));
                    x += step;
                }
                ticks
            }
            XAxis::Log10 { .. } => (x_min as i64..=x_max as i64)
                .map(|decade| (decade as f64, format!("1e{decade}")))
                .collect(),
            XAxis::Categories(names) => names
                .iter()
                .enumerate()
                .map(|(i, name)| (i as f64, name.clone()))
                .collect(),
        };
        for (x, label) in &x_ticks {
            let (px, _) = to_pixel(*x, y_min);
            canvas.line((px, top), (px, bottom), grid, 1);
            canvas.line((px, bottom), (px, bottom + 4), black, 1);
            canvas.text(
                px - Canvas::text_width(label, 1) / 2,
                bottom + 8,
                label,
                1,
                black,
            );
        }
        canvas.line((left, top), (left, bottom), black, 1);
        canvas.line((left, bottom), (right, bottom), black, 1);
        canvas.line((right, top), (right, bottom), black, 1);
        canvas.line((left, top), (right, top), black, 1);

        canvas.text(
            (WIDTH as i64 - Canvas::text_width(&self.title, 2)) / 2,
            12,
            &self.title,
            2,
            black,
        );
        canvas.text(
            left + (right - left - Canvas::text_width(&self.x_label, 1)) / 2,
            bottom + 28,
            &self.x_label,
            1,
            black,
        );
        canvas.text(8, top - 14, &self.y_label, 1, black);

        for (index, series) in self.series.iter().enumerate() {
            let colour = PALETTE[index % PALETTE.len()];
            let points: Vec<(i64, i64)> = series
                .points
                .iter()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .map(|&(x, y)| to_pixel(self.x_transform(x), y))
                .collect();
            for pair in points.windows(2) {
                canvas.line(pair[0], pair[1], colour, 2);
            }
            for &point in &points {
                canvas.square(point, 2, colour);
            }
            let legend_y = top + 8 + index as i64 * 18;
            canvas.line(
                (right + 12, legend_y + 4),
                (right + 36, legend_y + 4),
                colour,
                3,
            );
            canvas.text(right + 42, legend_y, &series.name, 1, black);
        }
        Ok(canvas)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plot(x_axis: XAxis, points: Vec<(f64, f64)>) -> LinePlot {
        LinePlot {
            title: "mIoU vs horizon".into(),
            x_label: "horizon [ms]".into(),
            y_label: "mIoU [%]".into(),
            x_axis,
            y_range: (0.0, 100.0),
            y_step: 20.0,
            series: vec![Series {
                name: "model".into(),
                points,
            }],
        }
    }

    #[test]
    fn writes_a_png_with_drawn_lines() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plot.png");
        plot(
            XAxis::Linear { step: 10.0 },
            vec![(0.0, 80.0), (50.0, 70.0), (100.0, 60.0)],
        )
        .write_png(&path)
        .unwrap();
        let decoder = png::Decoder::new(File::open(&path).unwrap());
        let mut reader = decoder.read_info().unwrap();
        let mut buffer = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buffer).unwrap();
        assert_eq!((info.width, info.height), (WIDTH as u32, HEIGHT as u32));
        let series_colour = PALETTE[0];
        let coloured = buffer
            .chunks(3)
            .filter(|p| p == &series_colour.as_slice())
            .count();
        assert!(
            coloured > 100,
            "only {coloured} pixels of the series colour"
        );
    }

    #[test]
    fn log_axis_rejects_zero() {
        let axis = XAxis::Log10 {
            first_decade: 2,
            last_decade: 6,
        };
        let error = plot(axis, vec![(0.0, 1.0)]).render().err().unwrap();
        assert!(error.to_string().contains("x = 0"));
    }

    #[test]
    fn empty_plot_is_an_error() {
        let error = plot(XAxis::Linear { step: 1.0 }, vec![(1.0, f64::NAN)])
            .render()
            .err()
            .unwrap();
        assert!(matches!(error, PlotError::NoData { .. }));
    }

    #[test]
    fn categories_render() {
        let axis = XAxis::Categories(vec!["<=90".into(), "90-120".into(), ">120".into()]);
        assert!(plot(axis, vec![(0.0, 50.0), (1.0, 40.0), (2.0, 30.0)])
            .render()
            .is_ok());
    }
}
