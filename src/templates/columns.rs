//! The query's layout for the cost-matrix kernels.

use crate::descriptor::SurfaceContext;

/// A query's descriptors and positions laid out for the exact stage's cost matrices:
/// value `d` of sample `i` at `d · stride + i`, positions as two rows, every row
/// zero-padded to `stride` (the sample count rounded up to 32), so that a vector
/// holds one value of 8 (AVX2) or 16 (AVX-512) consecutive samples. Made once per
/// query.
pub struct QueryColumns {
    pub(super) values: Vec<f32>,
    pub(super) x: Vec<f32>,
    pub(super) y: Vec<f32>,
    pub(super) stride: usize,
}

impl QueryColumns {
    pub fn new(q: &SurfaceContext) -> Self {
        let (n, dim) = (q.len(), q.dim);
        // A multiple of 32: the AVX-512 kernel reads two 16-lane vectors per block.
        let stride = n.next_multiple_of(32);
        let mut values = vec![0.0f32; dim * stride];
        for i in 0..n {
            for (d, &v) in q.descriptor(i).iter().enumerate() {
                values[d * stride + i] = v;
            }
        }
        let mut x = vec![0.0f32; stride];
        let mut y = vec![0.0f32; stride];
        for (i, p) in q.positions.iter().enumerate() {
            (x[i], y[i]) = (p[0], p[1]);
        }
        QueryColumns {
            values,
            x,
            y,
            stride,
        }
    }
}
