//! Reading and writing images: 16-bit depth PNG/TIFF, float TIFF, raw `.u16`, and gray
//! images for stereo. Decoding uses the `image` crate (PNG, TIFF, JPEG only).

use crate::error::{Error, Result};
use image::{DynamicImage, ImageReader};
use std::path::Path;

/// A decoded single-channel image, row-major.
#[derive(Debug, Clone)]
pub struct Image {
    pub data: Vec<f32>,
    pub height: usize,
    pub width: usize,
}

fn path_str(path: &Path) -> String {
    path.display().to_string()
}

fn open(path: &Path) -> Result<DynamicImage> {
    if !path.exists() {
        return Err(Error::file(path_str(path), "no such file"));
    }
    let reader = ImageReader::open(path)
        .map_err(|e| Error::file(path_str(path), format!("cannot open: {e}")))?
        .with_guessed_format()
        .map_err(|e| Error::file(path_str(path), format!("cannot read: {e}")))?;
    if reader.format().is_none() {
        return Err(Error::file(
            path_str(path),
            "not a PNG, TIFF or JPEG image (unknown format)",
        ));
    }
    reader
        .decode()
        .map_err(|e| Error::file(path_str(path), format!("corrupt or truncated image: {e}")))
}

/// Reads a depth image: 16-bit gray PNG/TIFF (integer units times `scale` metres, so
/// millimetres with the default 0.001) or 32-bit float TIFF (metres, `scale` ignored).
/// An 8-bit or colour image is refused: it cannot hold depth.
pub fn read_depth(path: &Path, scale: f64) -> Result<Image> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(Error::invalid(
            "scale",
            format!("must be positive, got {scale}"),
        ));
    }
    let img = open(path)?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    let data: Vec<f32> = match img {
        DynamicImage::ImageLuma16(buf) => buf
            .into_raw()
            .into_iter()
            .map(|v| (v as f64 * scale) as f32)
            .collect(),
        DynamicImage::ImageRgb32F(_) | DynamicImage::ImageRgba32F(_) => {
            return Err(Error::file(
                path_str(path),
                "a colour float image is not a depth image",
            ))
        }
        DynamicImage::ImageLuma8(_) | DynamicImage::ImageLumaA8(_) => {
            return Err(Error::file(
                path_str(path),
                "an 8-bit image cannot hold depth; depth PNGs are 16-bit (millimetres)",
            ))
        }
        other => {
            return Err(Error::file(
                path_str(path),
                format!(
                    "a {:?} image is not a depth image (need 16-bit gray or float)",
                    other.color()
                ),
            ))
        }
    };
    Ok(Image {
        data,
        height,
        width,
    })
}

/// Reads any PNG/TIFF/JPEG as gray float32: integer images scaled to [0, 1] by their
/// type's maximum, float images as stored, colour converted by luminance.
pub fn read_gray(path: &Path) -> Result<Image> {
    let img = open(path)?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    let data: Vec<f32> = match img {
        DynamicImage::ImageLuma8(b) => b.into_raw().into_iter().map(|v| v as f32 / 255.0).collect(),
        DynamicImage::ImageLuma16(b) => b
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 65535.0)
            .collect(),
        other => {
            let rgb = other.into_rgb32f();
            rgb.pixels()
                .map(|p| 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2])
                .collect()
        }
    };
    Ok(Image {
        data,
        height,
        width,
    })
}

/// Reads a float TIFF (e.g. Middlebury ground-truth disparity) as stored.
pub fn read_float(path: &Path) -> Result<Image> {
    let img = open(path)?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    let data = match img {
        DynamicImage::ImageRgb32F(b) => b.pixels().map(|p| p[0]).collect(),
        DynamicImage::ImageRgba32F(b) => b.pixels().map(|p| p[0]).collect(),
        other => other
            .into_luma16()
            .into_raw()
            .into_iter()
            .map(|v| v as f32)
            .collect(),
    };
    Ok(Image {
        data,
        height,
        width,
    })
}

/// Writes depth (metres) as a 16-bit PNG in units of `scale` metres (0 = no reading;
/// NaN, zero and out-of-range values are written as 0).
pub fn write_depth_png(
    path: &Path,
    depth: &[f32],
    height: usize,
    width: usize,
    scale: f64,
) -> Result<()> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(Error::invalid(
            "scale",
            format!("must be positive, got {scale}"),
        ));
    }
    if depth.len() != height * width || height == 0 || width == 0 {
        return Err(Error::invalid(
            "depth",
            format!(
                "{} values do not make a {height}x{width} image",
                depth.len()
            ),
        ));
    }
    let raw: Vec<u16> = depth
        .iter()
        .map(|&z| {
            let v = (z as f64 / scale).round();
            if v.is_finite() && v > 0.0 && v <= u16::MAX as f64 {
                v as u16
            } else {
                0
            }
        })
        .collect();
    let buf = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(width as u32, height as u32, raw)
        .expect("size checked above");
    buf.save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| Error::file(path_str(path), format!("cannot write: {e}")))
}

/// Writes an 8-bit RGB picture (row-major, 3 bytes a pixel) as PNG.
pub fn write_rgb_png(path: &Path, rgb: &[u8], height: usize, width: usize) -> Result<()> {
    if rgb.len() != height * width * 3 || height == 0 || width == 0 {
        return Err(Error::invalid(
            "image",
            format!(
                "{} bytes do not make a {height}x{width} RGB image",
                rgb.len()
            ),
        ));
    }
    image::save_buffer_with_format(
        path,
        rgb,
        width as u32,
        height as u32,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .map_err(|e| Error::file(path_str(path), format!("cannot write: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_png_round_trip() {
        let dir = std::env::temp_dir().join(format!("depthpose-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("d.png");
        let depth = vec![0.0, 1.234, 2.5, f32::NAN, 65.535, 3.0];
        write_depth_png(&p, &depth, 2, 3, 0.001).unwrap();
        let back = read_depth(&p, 0.001).unwrap();
        assert_eq!((back.height, back.width), (2, 3));
        let want = [0.0, 1.234, 2.5, 0.0, 65.535, 3.0];
        for (a, b) in back.data.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
        // An 8-bit picture is refused as depth but reads as gray.
        let q = dir.join("g.png");
        write_rgb_png(&q, &[255u8; 18], 2, 3).unwrap();
        assert!(read_depth(&q, 0.001)
            .unwrap_err()
            .to_string()
            .contains("not a depth image"));
        let g = read_gray(&q).unwrap();
        assert!(g.data.iter().all(|&v| (v - 1.0).abs() < 1e-5));
        // Truncated file.
        let bytes = std::fs::read(&p).unwrap();
        let t = dir.join("t.png");
        std::fs::write(&t, &bytes[..bytes.len() / 2]).unwrap();
        assert!(read_depth(&t, 0.001)
            .unwrap_err()
            .to_string()
            .contains("corrupt"));
        assert!(read_depth(&dir.join("missing.png"), 0.001)
            .unwrap_err()
            .to_string()
            .contains("no such file"));
        std::fs::remove_dir_all(&dir).ok();
    }
}
