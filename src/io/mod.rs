//! Reading and writing files: depth images in every format depthpose takes, gray
//! images for stereo, and numpy's `.npy` arrays and `.npz` archives.
//!
//! One format per file: [`image`] (PNG, TIFF, JPEG through the `image` and `tiff`
//! crates), [`pfm`] (portable float maps), [`npy`] (numpy's array format), [`npz`]
//! (numpy's zip of `.npy` arrays) and [`raw`] (headerless little-endian `.u16`). This
//! file holds the limits, the checks every reader shares and [`read_depth`] /
//! [`write_depth`], which pick the format by the file's suffix.
//!
//! Depth in memory is `f32` metres, 0 or NaN meaning "no reading". On disk each format
//! has one unit: integer formats (16-bit PNG/TIFF, uint16 `.npy`, `.u16`) hold units of
//! `scale` metres, float formats (float TIFF, float `.npy`, `.pfm`) metres. Every
//! reader checks a file's header against [`MAX_IMAGE_PIXELS`] before it allocates the
//! pixels.

pub mod image;
pub mod npy;
pub mod npz;
pub mod pfm;
pub mod raw;

pub use image::{read_depth_image, read_float, read_gray, write_depth_png, write_rgb_png};

use crate::error::{brief, Error, Result};
use std::path::Path;

/// Largest image read, written or rendered (height × width): 2^23 pixels, e.g.
/// 4096 × 2048.
pub const MAX_IMAGE_PIXELS: usize = 1 << 23;
/// Smallest metres-per-unit scale of an integer depth file (a micrometre).
pub const MIN_DEPTH_SCALE: f64 = 1e-6;
/// Largest metres-per-unit scale of an integer depth file (a metre).
pub const MAX_DEPTH_SCALE: f64 = 1.0;

/// A decoded single-channel image, row-major.
#[derive(Debug, Clone)]
pub struct Image {
    pub data: Vec<f32>,
    pub height: usize,
    pub width: usize,
}

/// A path as messages show it.
pub(crate) fn path_str(path: &Path) -> String {
    path.display().to_string()
}

/// Refuses a depth scale (metres per integer unit) outside
/// [[`MIN_DEPTH_SCALE`], [`MAX_DEPTH_SCALE`]].
pub fn check_depth_scale(scale: f64) -> Result<()> {
    if scale.is_finite() && (MIN_DEPTH_SCALE..=MAX_DEPTH_SCALE).contains(&scale) {
        Ok(())
    } else {
        Err(Error::invalid(
            "scale",
            format!(
                "metres per unit must be in [{}, {}] (0.001 for millimetres), got {}",
                brief(MIN_DEPTH_SCALE),
                brief(MAX_DEPTH_SCALE),
                brief(scale)
            ),
        ))
    }
}

/// Refuses an image of more than [`MAX_IMAGE_PIXELS`] pixels.
pub(crate) fn check_size(path: &Path, width: u64, height: u64) -> Result<()> {
    if width.saturating_mul(height) > MAX_IMAGE_PIXELS as u64 {
        return Err(Error::resource_limit(
            path_str(path),
            format!(
                "an image of {width}x{height} pixels exceeds the limit MAX_IMAGE_PIXELS = \
                 {MAX_IMAGE_PIXELS}"
            ),
        ));
    }
    Ok(())
}

/// The size in bytes of the file at `path`: an error for a missing file or a folder
/// (`what` says what the file should have been).
pub(crate) fn existing(path: &Path, what: &str) -> Result<u64> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(Error::not_found(path_str(path))),
        Err(e) => Err(Error::file(path_str(path), format!("cannot open: {e}"))),
        Ok(m) if m.is_dir() => Err(Error::file(
            path_str(path),
            format!("is a directory, not {what}"),
        )),
        Ok(m) => Ok(m.len()),
    }
}

/// The error of a failed read or write of `path`.
pub(crate) fn io_error(path: &Path, doing: &str, e: std::io::Error) -> Error {
    if e.kind() == std::io::ErrorKind::NotFound && doing == "read" {
        return Error::not_found(path_str(path));
    }
    Error::file(path_str(path), format!("cannot {doing}: {e}"))
}

/// The suffix of `path`, lower case, with its dot ("" without one).
fn suffix(path: &Path) -> String {
    path.extension()
        .map(|e| format!(".{}", e.to_string_lossy().to_lowercase()))
        .unwrap_or_default()
}

/// Whether `path` names a headerless `.u16` (or `.raw`) depth file, whose shape is
/// not in the file.
pub fn is_raw(path: &Path) -> bool {
    matches!(suffix(path).as_str(), ".u16" | ".raw")
}

/// Reads a depth image as `f32` metres, the format by the suffix: `.png`, `.tif` /
/// `.tiff` ([`image`]), `.npy` ([`npy`]), `.pfm` ([`pfm`]), `.u16` / `.raw` ([`raw`],
/// `shape` (height, width), [`raw::KINECT_SHAPE`] when `None`). `scale` converts
/// integer units to metres.
pub fn read_depth(path: &Path, scale: f64, shape: Option<(usize, usize)>) -> Result<Image> {
    check_depth_scale(scale)?;
    existing(path, "an image file")?;
    match suffix(path).as_str() {
        ".png" | ".tif" | ".tiff" => image::read_depth_image(path, scale),
        ".npy" => npy::read_depth(path, scale),
        ".pfm" => {
            let img = pfm::read(path)?;
            check_depth(path, &img)?;
            Ok(img)
        }
        ".u16" | ".raw" => raw::read(path, scale, shape.unwrap_or(raw::KINECT_SHAPE)),
        s => Err(Error::file(
            path_str(path),
            format!("unknown depth format {s:?} (use .png, .tif, .npy, .pfm or .u16)"),
        )),
    }
}

/// Refuses a file's depth that is negative or infinite, naming the first such pixel
/// (NaN and 0 mean "no reading").
pub(crate) fn check_depth(path: &Path, img: &Image) -> Result<()> {
    match img.data.iter().position(|v| *v < 0.0 || v.is_infinite()) {
        None => Ok(()),
        Some(k) => Err(Error::file(
            path_str(path),
            format!(
                "depth holds {} at row {}, column {} (depth is >= 0 metres; NaN or 0 mean no \
                 reading)",
                img.data[k],
                k / img.width.max(1),
                k % img.width.max(1)
            ),
        )),
    }
}

/// The formats [`write_depth`] writes, by the suffix of `path` (an error naming
/// `path` for another).
pub fn check_depth_suffix(path: &Path) -> Result<()> {
    match suffix(path).as_str() {
        ".png" | ".npy" | ".pfm" => Ok(()),
        s => Err(Error::invalid(
            "path",
            format!("unknown depth format {s:?} (use .png, .npy or .pfm)"),
        )),
    }
}

/// Writes depth (`f32` metres, row-major) in the format of the suffix: a 16-bit PNG in
/// units of `scale` metres ([`write_depth_png`], which refuses what it cannot store),
/// or float32 metres in `.npy` or `.pfm` (NaN kept).
pub fn write_depth(path: &Path, depth: &Image, scale: f64) -> Result<()> {
    check_depth_suffix(path)?;
    check_depth_scale(scale)?;
    match suffix(path).as_str() {
        ".png" => write_depth_png(path, &depth.data, depth.height, depth.width, scale),
        ".npy" => npy::write(
            path,
            &npy::Array::from_f32(&depth.data, depth.height, depth.width),
        ),
        _ => pfm::write(path, depth),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Cases of the file-format fuzz tests: `DEPTHPOSE_FUZZ_CASES`, else `default`
    /// (see docs/robustness.md for a longer run).
    pub(crate) fn fuzz_cases(default: u32) -> u32 {
        std::env::var("DEPTHPOSE_FUZZ_CASES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    }

    /// A fresh folder for one test's files.
    pub(crate) fn temp_dir(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!(
            "depthpose-io-{name}-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn depth_round_trips_through_every_format() {
        let dir = temp_dir("formats");
        let depth = Image {
            data: vec![0.0, 1.25, 2.5, f32::NAN, 4.0, 0.5],
            height: 2,
            width: 3,
        };
        for name in ["d.png", "d.npy", "d.pfm", "D.PFM"] {
            let p = dir.join(name);
            write_depth(&p, &depth, 0.001).unwrap();
            let back = read_depth(&p, 0.001, None).unwrap();
            assert_eq!((back.height, back.width), (2, 3), "{name}");
            for (a, b) in back.data.iter().zip(&depth.data) {
                let b = if name == "d.png" && b.is_nan() {
                    0.0
                } else {
                    *b
                };
                assert!(a == &b || (a.is_nan() && b.is_nan()), "{name}: {a} vs {b}");
            }
        }
        let e = write_depth(&dir.join("d.bmp"), &depth, 0.001).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("path: unknown depth format \".bmp\""),
            "{e}"
        );
        std::fs::write(dir.join("d.bmp"), b"BM").unwrap();
        let e = read_depth(&dir.join("d.bmp"), 0.001, None).unwrap_err();
        assert!(e.to_string().contains("unknown depth format"), "{e}");
        assert!(matches!(
            read_depth(&dir.join("none.npy"), 0.001, None),
            Err(Error::NotFound { .. })
        ));
        let e = read_depth(&dir, 0.001, None).unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn negative_depth_in_a_float_file_is_refused() {
        let dir = temp_dir("negative");
        let p = dir.join("n.pfm");
        let img = Image {
            data: vec![1.0, -2.0],
            height: 1,
            width: 2,
        };
        pfm::write(&p, &img).unwrap();
        let e = read_depth(&p, 0.001, None).unwrap_err();
        assert!(e.to_string().contains("-2 at row 0, column 1"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
