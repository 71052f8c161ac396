//! A borrowed depth image and its checks.

use crate::error::{ensure, Error, Result};

/// A borrowed depth image: row-major `height`×`width`, metres, 0 or NaN = no reading.
#[derive(Debug, Clone, Copy)]
pub struct DepthView<'a> {
    pub data: &'a [f32],
    pub width: usize,
    pub height: usize,
}

/// Index of the first negative or infinite value. Serial on purpose (a frame takes tens
/// of microseconds, less than waking the thread pool) and in branch-free chunks, so
/// that the scan vectorises; only a chunk with a bad value is searched.
pub(super) fn first_bad_depth(data: &[f32]) -> Option<usize> {
    const CHUNK: usize = 512;
    let bad = |z: f32| z.is_infinite() | (z < 0.0);
    data.chunks(CHUNK).enumerate().find_map(|(c, chunk)| {
        if chunk.iter().fold(false, |acc, &z| acc | bad(z)) {
            chunk.iter().position(|&z| bad(z)).map(|k| c * CHUNK + k)
        } else {
            None
        }
    })
}

impl<'a> DepthView<'a> {
    /// Wraps a slice after checking its size and values: negative or infinite depth is
    /// an error (NaN and 0 mean "no reading").
    pub fn new(data: &'a [f32], height: usize, width: usize, name: &str) -> Result<Self> {
        ensure(height > 0 && width > 0, name, || {
            format!("depth image is empty ({height}x{width})")
        })?;
        ensure(data.len() == height * width, name, || {
            format!(
                "has {} values but {height}x{width} needs {}",
                data.len(),
                height * width
            )
        })?;
        if let Some(bad) = first_bad_depth(data) {
            return Err(Error::invalid(
                name,
                format!(
                    "depth must be >= 0 (0 or NaN = no reading); pixel (row {}, col {}) holds {}",
                    bad / width,
                    bad % width,
                    data[bad]
                ),
            ));
        }
        Ok(DepthView {
            data,
            width,
            height,
        })
    }

    /// The depth at (row, col) if it is a reading, else None.
    #[inline]
    pub fn at(&self, row: usize, col: usize) -> Option<f32> {
        let z = self.data[row * self.width + col];
        (z > 0.0).then_some(z) // NaN > 0 is false
    }

    /// Number of pixels with a reading.
    pub fn count_valid(&self) -> usize {
        self.data.iter().filter(|&&z| z > 0.0).count()
    }
}
