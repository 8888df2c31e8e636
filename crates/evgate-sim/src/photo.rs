//! Photographs as textures. Suite version 5 reserves them for its out-of-domain test split:
//! training and validation see procedural textures only, so a score on photographs measures how
//! far what the network learned carries to real appearance.
//!
//! A photograph (PNG: grey, grey + alpha, RGB, RGBA or palette, 8 or 16 bits) becomes linear
//! luminance (sRGB decoded, Rec. 709 weights), its centred square is box-filtered (or bilinearly
//! enlarged) to the texture size, and reflectance is clamped to [0.01, 1] like a procedural
//! texture's. Textures wrap, so its opposite edges meet in a seam: one more straight edge.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use crate::texture::Texture;

/// Why a photograph cannot be a texture.
#[derive(Debug, thiserror::Error)]
pub enum PhotoError {
    #[error("cannot open photograph {path}: {source}")]
    Open {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("photograph {path} is not a PNG this reader decodes: {reason}")]
    Decode { path: PathBuf, reason: String },
    #[error(
        "photograph {path} is {width}x{height}; a texture needs at least 16 pixels on each side"
    )]
    TooSmall {
        path: PathBuf,
        width: u32,
        height: u32,
    },
}

/// Decodes `path` into linear luminance in [0, 1], row-major, with its width and height.
fn luminance(path: &Path) -> Result<(Vec<f32>, usize, usize), PhotoError> {
    let file = File::open(path).map_err(|source| PhotoError::Open {
        path: path.to_owned(),
        source,
    })?;
    let decode_error = |reason: String| PhotoError::Decode {
        path: path.to_owned(),
        reason,
    };
    let mut decoder = png::Decoder::new(BufReader::new(file));
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder
        .read_info()
        .map_err(|error| decode_error(error.to_string()))?;
    let mut buffer = vec![0; reader.output_buffer_size()];
    let frame = reader
        .next_frame(&mut buffer)
        .map_err(|error| decode_error(error.to_string()))?;
    let (width, height) = (frame.width as usize, frame.height as usize);
    if width < 16 || height < 16 {
        return Err(PhotoError::TooSmall {
            path: path.to_owned(),
            width: frame.width,
            height: frame.height,
        });
    }
    let channels = frame.color_type.samples();
    let linear = |byte: u8| {
        let v = byte as f32 / 255.0;
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    let pixels = buffer[..frame.buffer_size()]
        .chunks_exact(channels)
        .map(|pixel| match channels {
            1 | 2 => linear(pixel[0]),
            _ => 0.2126 * linear(pixel[0]) + 0.7152 * linear(pixel[1]) + 0.0722 * linear(pixel[2]),
        })
        .collect();
    Ok((pixels, width, height))
}

/// The photograph at `path` as a `size`×`size` texture (`size` a power of two).
pub fn photo_texture(path: &Path, size: usize) -> Result<Texture, PhotoError> {
    let (pixels, width, height) = luminance(path)?;
    let side = width.min(height);
    let (left, top) = ((width - side) / 2, (height - side) / 2);
    let scale = side as f32 / size as f32;
    let at = |x: usize, y: usize| pixels[(top + y.min(side - 1)) * width + left + x.min(side - 1)];
    let mut texels = Vec::with_capacity(size * size);
    for y in 0..size {
        for x in 0..size {
            let value = if scale >= 1.0 {
                // The mean of the source pixels this texel covers.
                let (x0, x1) = (
                    (x as f32 * scale) as usize,
                    ((x + 1) as f32 * scale) as usize,
                );
                let (y0, y1) = (
                    (y as f32 * scale) as usize,
                    ((y + 1) as f32 * scale) as usize,
                );
                let (x1, y1) = (x1.max(x0 + 1), y1.max(y0 + 1));
                let mut sum = 0.0;
                for sy in y0..y1 {
                    for sx in x0..x1 {
                        sum += at(sx, sy);
                    }
                }
                sum / ((x1 - x0) * (y1 - y0)) as f32
            } else {
                let (u, v) = (
                    ((x as f32 + 0.5) * scale - 0.5).max(0.0),
                    ((y as f32 + 0.5) * scale - 0.5).max(0.0),
                );
                let (ix, iy) = (u as usize, v as usize);
                let (fx, fy) = (u - ix as f32, v - iy as f32);
                let top_row = at(ix, iy) * (1.0 - fx) + at(ix + 1, iy) * fx;
                let bottom_row = at(ix, iy + 1) * (1.0 - fx) + at(ix + 1, iy + 1) * fx;
                top_row * (1.0 - fy) + bottom_row * fy
            };
            texels.push(value.clamp(0.01, 1.0).ln());
        }
    }
    Ok(Texture::from_texels(size, texels))
}

/// Every photograph of `paths` as a texture, in order.
pub fn load_photographs(paths: &[PathBuf], size: usize) -> Result<Vec<Texture>, PhotoError> {
    paths.iter().map(|path| photo_texture(path, size)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_png(path: &Path, width: u32, height: u32, color: png::ColorType, data: &[u8]) {
        let file = File::create(path).unwrap();
        let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
        encoder.set_color(color);
        encoder.set_depth(png::BitDepth::Eight);
        encoder
            .write_header()
            .unwrap()
            .write_image_data(data)
            .unwrap();
    }

    #[test]
    fn a_photograph_keeps_its_light_and_dark_halves() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("halves.png");
        // 64x32 RGB: left half white, right half black; the centred 32x32 square straddles both.
        let data: Vec<u8> = (0..32 * 64)
            .flat_map(|i| {
                let v = if i % 64 < 32 { 255 } else { 0 };
                [v, v, v]
            })
            .collect();
        write_png(&path, 64, 32, png::ColorType::Rgb, &data);
        let texture = photo_texture(&path, 16).unwrap();
        let texels = texture.level_texels()[0];
        assert!(
            (texels[4 * 16 + 2] - 0.0).abs() < 1e-6,
            "white is reflectance 1"
        );
        assert!(
            (texels[4 * 16 + 13] - 0.01f32.ln()).abs() < 1e-6,
            "black clamps to 0.01"
        );
    }

    #[test]
    fn grey_photographs_are_enlarged_smoothly() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ramp.png");
        let data: Vec<u8> = (0..16 * 16).map(|i| ((i % 16) * 16) as u8).collect();
        write_png(&path, 16, 16, png::ColorType::Grayscale, &data);
        let texture = photo_texture(&path, 64).unwrap();
        let row: Vec<f32> = texture.level_texels()[0][..64].to_vec();
        assert!(
            row.windows(2).all(|w| w[1] >= w[0] - 1e-6),
            "a ramp stays monotonic"
        );
    }

    #[test]
    fn bad_photographs_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.png");
        assert!(matches!(
            photo_texture(&missing, 16),
            Err(PhotoError::Open { .. })
        ));
        let text = dir.path().join("notes.png");
        std::fs::write(&text, "not a png").unwrap();
        let error = photo_texture(&text, 16).unwrap_err();
        assert!(error.to_string().contains("notes.png"), "{error}");
        let tiny = dir.path().join("tiny.png");
        write_png(&tiny, 4, 4, png::ColorType::Grayscale, &[0; 16]);
        assert!(matches!(
            photo_texture(&tiny, 16),
            Err(PhotoError::TooSmall { width: 4, .. })
        ));
    }
}
