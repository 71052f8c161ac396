//! Headerless depth frames (`.u16`, `.raw`): little-endian 16-bit units of `scale`
//! metres, row-major, as Kinect recorders dump them. The file holds no shape, so the
//! caller gives it and the file's size must match it exactly.

use super::{check_size, existing, io_error, path_str, Image};
use crate::error::{Error, Result};
use std::path::Path;

/// The (height, width) assumed when none is given: Kinect v1's 640 × 480.
pub const KINECT_SHAPE: (usize, usize) = (480, 640);

/// Reads a raw frame of `shape` (height, width), its size checked against the limit
/// and the file before anything is read.
pub fn read(path: &Path, scale: f64, shape: (usize, usize)) -> Result<Image> {
    let (height, width) = shape;
    if height == 0 || width == 0 {
        return Err(Error::invalid(
            "shape",
            format!("must be positive (height, width), got ({height}, {width})"),
        ));
    }
    check_size(path, width as u64, height as u64)?;
    let size = existing(path, "an image file")?;
    if size != 2 * (height * width) as u64 {
        return Err(Error::file(
            path_str(path),
            format!(
                "holds {} 16-bit values, not {height}x{width}; pass shape=(height, width)",
                size / 2
            ),
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| io_error(path, "read", e))?;
    if bytes.len() != 2 * height * width {
        return Err(Error::file(path_str(path), "the file changed while read"));
    }
    let data = bytes
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]) as f32 * scale as f32)
        .collect();
    Ok(Image {
        data,
        height,
        width,
    })
}

#[cfg(test)]
mod tests {
    use super::super::tests::temp_dir;
    use super::*;

    #[test]
    fn frames_read_when_the_shape_fits() {
        let dir = temp_dir("raw");
        let p = dir.join("d.u16");
        std::fs::write(&p, [0xe8, 0x03, 0xd0, 0x07, 0, 0, 1, 0]).unwrap();
        let img = read(&p, 0.001, (2, 2)).unwrap();
        assert_eq!(img.data, [1.0, 2.0, 0.0, 0.001]);
        let e = read(&p, 0.001, (3, 2)).unwrap_err().to_string();
        assert!(
            e.contains("holds 4 16-bit values, not 3x2; pass shape"),
            "{e}"
        );
        assert!(matches!(
            read(&p, 0.001, (1 << 40, 1 << 40)),
            Err(Error::ResourceLimit { .. })
        ));
        assert!(read(&p, 0.001, (0, 4)).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
