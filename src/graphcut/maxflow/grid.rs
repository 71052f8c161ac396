//! The edges of a pixel grid.

use super::layout::MAX_NODES;
use crate::error::{Error, Result};

/// Edges of an `h`×`w` pixel grid (row-major node ids), 4- or 8-connected: right, down
/// (and the two down-diagonals for 8). Returns pairs `[i, j]`.
pub fn grid_edges(h: usize, w: usize, connectivity: u8) -> Result<Vec<[u32; 2]>> {
    if connectivity != 4 && connectivity != 8 {
        return Err(Error::invalid(
            "connectivity",
            format!("must be 4 or 8, got {connectivity}"),
        ));
    }
    if h.checked_mul(w).is_none_or(|n| n > MAX_NODES) {
        return Err(Error::invalid("h", "grid too large for u32 node indices"));
    }
    let per = if connectivity == 4 { 2 } else { 4 };
    let mut out = Vec::with_capacity(h * w * per);
    for r in 0..h {
        for c in 0..w {
            let i = (r * w + c) as u32;
            if c + 1 < w {
                out.push([i, i + 1]);
            }
            if r + 1 < h {
                out.push([i, i + w as u32]);
                if connectivity == 8 {
                    if c + 1 < w {
                        out.push([i, i + w as u32 + 1]);
                    }
                    if c > 0 {
                        out.push([i, i + w as u32 - 1]);
                    }
                }
            }
        }
    }
    Ok(out)
}
