//! Converting and checking every argument that crosses from Python into Rust.
//!
//! Every error names the argument. Wrong Python types raise `InvalidTypeError` (a
//! `TypeError` and an `InvalidInputError`), wrong values `InvalidInputError`, and
//! inputs beyond a size limit `ResourceLimitError` naming the limit, checked before
//! anything is allocated or copied.
//!
//! The readers live in one file per kind: [`scalars`] (numbers, flags, strings,
//! paths and short sequences of them), [`arrays`] and [`objects`] (the native classes
//! and the settings built from them); this file holds the size limits and the errors.
//!
//! # Numbers, flags, strings, paths
//!
//! [`Int`], [`Real`], [`Flag`], [`Text`] and [`PathArg`] take any Python object and
//! check it when asked for the value ([`Int::count`], [`Real::get`], ...), so that
//! the error names the argument. Integers are Python `int`s or numpy integers (any
//! size: one beyond the range asked for is a clear error, not an `OverflowError`);
//! real numbers are those or Python/numpy floats. `bool` is not a number here.
//!
//! # Arrays
//!
//! | kind | dtypes | read as | layout |
//! |---|---|---|---|
//! | numbers (points, poses, costs, seeds, ...) | floating, signed or unsigned integer | f64 or f32 | any |
//! | indices (edges, labels, node ids) | signed or unsigned integer | i64 | any |
//! | depth images | float32/float64 metres, uint16 millimetres | f32 metres | C-contiguous |
//! | masks | bool, or an integer type holding only 0 and 1 | bool | C-contiguous |
//!
//! "Any" layout: C or Fortran order, negative strides, strided or broadcast views are
//! read in logical (row-major) order. Depth images and masks are the pixel arrays of
//! a live loop and must be C-contiguous (`numpy.ascontiguousarray`); others are
//! refused with a clear error. Non-native byte order, unaligned data, float16 and
//! long double are converted by numpy (after the size check). Bool, complex, object,
//! string, datetime and structured arrays are refused where numbers are expected.

mod arrays;
mod objects;
mod scalars;

pub use arrays::*;
pub use objects::*;
pub use scalars::*;

use super::{InvalidInputError, InvalidTypeError, ResourceLimitError};
use crate::error::brief_numbers;
use pyo3::prelude::*;

/// Largest depth image, mask or picture (height × width): 2^23 pixels, e.g.
/// 4096 × 2048. Also the largest image a camera may render.
pub const MAX_IMAGE_PIXELS: usize = crate::io::MAX_IMAGE_PIXELS;
/// Most depth readings (in the mask) one body fit or template match takes: 2^20. A fit
/// holds some 900 bytes per point (costs per segment, the neighbour graph, labels).
pub const MAX_FIT_POINTS: usize = 1 << 20;
/// Largest number of elements of any other array argument: 2^26 (512 MiB as float64).
pub const MAX_ARRAY_ELEMENTS: usize = 1 << 26;
/// Largest result one call may allocate (an output array, a rendered image, a graph
/// built for it): 2^30 bytes.
pub const MAX_RESULT_BYTES: usize = 1 << 30;

/// An argument as an error shows it: the name of its type.
pub fn type_name(obj: &Bound<PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

/// `InvalidInputError` naming `name`.
pub fn invalid(name: &str, msg: impl std::fmt::Display) -> PyErr {
    InvalidInputError::new_err(format!("{name}: {}", brief_numbers(&msg.to_string())))
}

/// `InvalidTypeError` (a `TypeError`) naming `name`: expected `what`, got `obj`'s type.
pub fn wrong_type(name: &str, what: &str, got: &str) -> PyErr {
    PyErr::new::<InvalidTypeError, _>(format!("{name}: expected {what}, got {got}"))
}

/// `ResourceLimitError` naming `name` and the limit.
pub fn too_large(name: &str, msg: impl std::fmt::Display) -> PyErr {
    ResourceLimitError::new_err(format!("{name}: {msg}"))
}

/// Fails unless a result of `bytes` bytes (computed without overflow by the caller,
/// `None` when it overflowed) fits [`MAX_RESULT_BYTES`].
pub fn check_result_bytes(bytes: Option<usize>, name: &str, what: &str) -> PyResult<()> {
    match bytes {
        Some(b) if b <= MAX_RESULT_BYTES => Ok(()),
        _ => Err(too_large(
            name,
            format!(
                "{what} would need {} bytes, more than the limit MAX_RESULT_BYTES = {MAX_RESULT_BYTES}",
                bytes.map_or_else(|| "over 2**64".to_string(), |b| b.to_string())
            ),
        )),
    }
}

/// Fails unless an image of `height` × `width` pixels fits [`MAX_IMAGE_PIXELS`].
pub fn check_image_pixels(height: usize, width: usize, name: &str) -> PyResult<()> {
    match height.checked_mul(width) {
        Some(p) if p <= MAX_IMAGE_PIXELS => Ok(()),
        _ => Err(too_large(
            name,
            format!(
                "an image of {height}x{width} pixels exceeds the limit MAX_IMAGE_PIXELS = \
                 {MAX_IMAGE_PIXELS}"
            ),
        )),
    }
}

/// Fails unless the depth readings of `depth` (positive, finite, in `mask`) number at
/// most [`MAX_FIT_POINTS`] (`already`: readings counted in other frames).
pub fn check_fit_points(
    depth: &[f32],
    mask: Option<&[bool]>,
    already: usize,
    name: &str,
) -> PyResult<usize> {
    let valid = |z: f32| z.is_finite() && z > 0.0;
    let n = already
        + match mask {
            Some(m) => depth
                .iter()
                .zip(m)
                .filter(|(&z, &on)| on && valid(z))
                .count(),
            None => depth.iter().filter(|&&z| valid(z)).count(),
        };
    if n > MAX_FIT_POINTS {
        return Err(too_large(
            name,
            format!(
                "{n} depth readings to fit exceed the limit MAX_FIT_POINTS = {MAX_FIT_POINTS}; \
                 pass a mask of the person or a smaller image"
            ),
        ));
    }
    Ok(n)
}
