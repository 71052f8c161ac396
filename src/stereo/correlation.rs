//! Window correlation between a left and a right image, computed cheaply.
//!
//! Both images are normalised once (global mean 0, global standard deviation 1). The
//! window mean and variance of every pixel come from box filters of I and I², so a
//! candidate match (x, y, d) costs only the cross term Σ L·R over the window.

use rayon::prelude::*;
use std::ops::Range;

/// Correlation reported for a candidate that cannot be scored (untextured window or
/// window outside an image). Lower than any real correlation.
pub const NO_CORRELATION: f32 = -2.0;

/// The similarity of two windows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Similarity {
    /// Moravec's normalised cross-correlation, 2·cov / (var_L + var_R), the measure of
    /// Čech and Šára: it also penalises a difference in contrast between the windows.
    Mncc,
    /// Plain normalised cross-correlation, cov / sqrt(var_L · var_R).
    Ncc,
}

/// Window moments of one image: [mean, variance] per pixel (variance 0 where the
/// window leaves the image or has too little texture to be matched). Interleaved, so a
/// candidate reads both from one cache line.
struct Moments {
    mv: Vec<[f32; 2]>,
}

/// Moment images and normalised pixels of a rectified pair; scores candidates.
pub struct Correlator {
    left: Vec<f32>,
    right: Vec<f32>,
    ml: Moments,
    mr: Moments,
    width: usize,
    height: usize,
    half: usize,
    inv_n: f32,
    similarity: Similarity,
    /// Whether `score3` and `score_line` may take their AVX2 builds (the CPU has it and
    /// `DEPTHPOSE_NO_AVX2` is not set).
    avx2: bool,
}

/// Shifts and scales `img` in place to mean 0 and standard deviation 1; false (and `img`
/// unspecified) when the image is uniform (no texture anywhere).
fn normalise(img: &mut [f32]) -> bool {
    let n = img.len() as f64;
    let mean = img.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = img.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n;
    if var.is_nan() || var <= 0.0 {
        return false;
    }
    let inv_sd = 1.0 / var.sqrt();
    for v in img.iter_mut() {
        *v = ((*v as f64 - mean) * inv_sd) as f32;
    }
    true
}

/// Zeros kept after the normalised right image (the spare lane of [`window_sums`] reads past the last window).
const RIGHT_SLACK: usize = 4;

/// Rows of moments computed by one task: each task keeps its own running column sums.
const MOMENT_ROWS: usize = 32;

/// Window means and variances by box filtering, per task of `MOMENT_ROWS` rows: running
/// column sums of I and I² over the window's rows (one row added and one dropped per
/// step), then window sums along each row (see [`moment_rows`]). f64 sums, so nothing is
/// lost to the running updates; memory is four rows of sums per task, not two integral
/// images.
fn moments(img: &[f32], width: usize, height: usize, half: usize, min_var: f32) -> Moments {
    let side = 2 * half + 1;
    let mut mv = vec![[0.0f32; 2]; width * height];
    if width < side || height < side {
        return Moments { mv };
    }
    mv.par_chunks_mut(width * MOMENT_ROWS)
        .enumerate()
        .for_each(|(task, out)| {
            let rows = task * MOMENT_ROWS..task * MOMENT_ROWS + out.len() / width;
            moment_rows(img, width, height, half, min_var, rows, out);
        });
    Moments { mv }
}

avx2_dispatch! {
    /// The moments of image rows `rows` (those whose window lies inside the image) into
    /// `out`, which holds exactly those rows. Along each row, the window sums add `side`
    /// shifted copies of the column sums: independent additions that vectorise, where a
    /// sliding sum (add one column, drop one) would be a chain of dependent ones.
    fn moment_rows(
        img: &[f32],
        width: usize,
        height: usize,
        half: usize,
        min_var: f32,
        rows: Range<usize>,
        out: &mut [[f32; 2]],
    ) {
        let side = 2 * half + 1;
        let inv_n = 1.0 / (side * side) as f64;
        let (first, end) = (rows.start.max(half), rows.end.min(height - half));
        if first >= end {
            return;
        }
        let row_of = |y: usize| &img[y * width..][..width];
        // Column sums over rows first − half ..= first + half.
        let (mut c1, mut c2) = (vec![0.0f64; width], vec![0.0f64; width]);
        for y in first - half..=first + half {
            for ((a, b), &v) in c1.iter_mut().zip(c2.iter_mut()).zip(row_of(y)) {
                let v = v as f64;
                *a += v;
                *b += v * v;
            }
        }
        // Window sums of the pixels half..width − half of a row.
        let inner = width - 2 * half;
        let (mut s1, mut s2) = (vec![0.0f64; inner], vec![0.0f64; inner]);
        for y in first..end {
            if y > first {
                let (add, drop) = (row_of(y + half), row_of(y - half - 1));
                for (((a, b), &p), &q) in c1.iter_mut().zip(c2.iter_mut()).zip(add).zip(drop) {
                    let (p, q) = (p as f64, q as f64);
                    *a += p - q;
                    *b += p * p - q * q;
                }
            }
            s1.copy_from_slice(&c1[..inner]);
            s2.copy_from_slice(&c2[..inner]);
            for k in 1..side {
                for (s, &c) in s1.iter_mut().zip(&c1[k..k + inner]) {
                    *s += c;
                }
                for (s, &c) in s2.iter_mut().zip(&c2[k..k + inner]) {
                    *s += c;
                }
            }
            let row = &mut out[(y - rows.start) * width + half..][..inner];
            for ((o, &a), &b) in row.iter_mut().zip(&s1).zip(&s2) {
                let m = a * inv_n;
                let v = ((b * inv_n - m * m).max(0.0)) as f32;
                // Untextured windows get variance 0: they are never matched.
                *o = [m as f32, if v >= min_var { v } else { 0.0 }];
            }
        }
    }
}

impl Correlator {
    /// Prepares a pair of `height`×`width` images (taken by value: they are normalised
    /// in place) for windows of `2·half + 1` pixels. Windows whose standard deviation is
    /// below `min_texture` (in units of the image's global standard deviation) are never
    /// matched. `None` when either image is uniform.
    pub fn new(
        mut left: Vec<f32>,
        mut right: Vec<f32>,
        width: usize,
        height: usize,
        half: usize,
        min_texture: f32,
        similarity: Similarity,
    ) -> Option<Self> {
        let (l_ok, r_ok) = rayon::join(|| normalise(&mut left), || normalise(&mut right));
        if !(l_ok && r_ok) {
            return None;
        }
        // Zeros after the right image: the four-lane window sums read one pixel past
        // the last window's reach.
        right.resize(width * height + RIGHT_SLACK, 0.0);
        let min_var = (min_texture * min_texture).max(f32::MIN_POSITIVE);
        let (ml, mr) = rayon::join(
            || moments(&left, width, height, half, min_var),
            || moments(&right, width, height, half, min_var),
        );
        let side = 2 * half + 1;
        Some(Correlator {
            left,
            right,
            ml,
            mr,
            width,
            height,
            half,
            inv_n: 1.0 / (side * side) as f32,
            similarity,
            avx2: crate::cpu::avx2(),
        })
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn half(&self) -> usize {
        self.half
    }

    /// Whether the left window at (x, y) has texture (and lies inside the image).
    #[inline]
    pub fn left_textured(&self, x: usize, y: usize) -> bool {
        self.ml.mv[y * self.width + x][1] > 0.0
    }

    /// Correlation of the left window at (x, y) with the right window at (x − d, y).
    /// The caller guarantees x − d ≥ half and x < width − half, half ≤ y < height − half
    /// (outside that, one of the variances is 0 and `NO_CORRELATION` is returned only
    /// if the indices are valid; callers check the range first).
    #[inline]
    pub fn score(&self, x: usize, y: usize, d: usize) -> f32 {
        let il = y * self.width + x;
        let ir = il - d;
        let ([ml, vl], [mr, vr]) = (self.ml.mv[il], self.mr.mv[ir]);
        if vl == 0.0 || vr == 0.0 {
            return NO_CORRELATION;
        }
        let cov = self.cross(x, y, d) * self.inv_n - ml * mr;
        self.similarity_of(cov, vl, vr)
    }

    /// Correlations at disparities d − 1, d, d + 1 (in that order); a disparity outside
    /// 0..=top gets `NO_CORRELATION`. The three share one pass over the left window.
    #[inline]
    pub fn score3(&self, x: usize, y: usize, d: usize, top: usize) -> [f32; 3] {
        if d == 0 || d + 1 > top {
            let at = |dd: Option<usize>| match dd {
                Some(v) if v <= top => self.score(x, y, v),
                _ => NO_CORRELATION,
            };
            return [at(d.checked_sub(1)), at(Some(d)), at(Some(d + 1))];
        }
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is set only when the CPU has AVX2.
            return unsafe { self.score3_inner_avx2(x, y, d) };
        }
        self.score3_inner(x, y, d)
    }

    /// [`Correlator::score3_inner`] compiled for AVX2: the window sums' loads fold into
    /// their multiplications (three instructions per window pixel instead of five). No
    /// FMA, so the correlations are bit-identical to the portable build's.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn score3_inner_avx2(&self, x: usize, y: usize, d: usize) -> [f32; 3] {
        self.score3_inner(x, y, d)
    }

    /// [`Correlator::score3`] for 1 ≤ d and d + 1 ≤ the top disparity at x.
    #[inline(always)]
    fn score3_inner(&self, x: usize, y: usize, d: usize) -> [f32; 3] {
        let il = y * self.width + x;
        let [ml, vl] = self.ml.mv[il];
        if vl == 0.0 {
            return [NO_CORRELATION; 3];
        }
        // Sums for d + 1, d, d − 1: right pixels il − d − 1, il − d, il − d + 1.
        let cross = self.cross3_portable(x, y, d);
        let right = &self.mr.mv[il - d - 1..il - d + 2];
        let [c1, c0, cm] = similarity3(self.similarity, cross, self.inv_n, ml, vl, right);
        [cm, c0, c1]
    }

    /// Correlations of the left window at (x, y) with the right windows at every
    /// disparity 0..=top, into `out` (resized to top + 1): the exhaustive search of a
    /// seed. Needs (x, y) inside and top ≤ [`Correlator::max_disparity_at`]`(x)`.
    pub fn score_line(&self, x: usize, y: usize, top: usize, out: &mut Vec<f32>) {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is set only when the CPU has AVX2.
            return unsafe { self.score_line_avx2(x, y, top, out) };
        }
        self.score_line_portable(x, y, top, out)
    }

    /// [`Correlator::score_line_portable`] compiled for AVX2 (eight lanes instead of
    /// four; each disparity's sum is formed in the same order, so bit-identical).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn score_line_avx2(&self, x: usize, y: usize, top: usize, out: &mut Vec<f32>) {
        self.score_line_portable(x, y, top, out)
    }

    #[inline(always)]
    fn score_line_portable(&self, x: usize, y: usize, top: usize, out: &mut Vec<f32>) {
        let (w, h) = (self.width, self.half);
        let side = 2 * h + 1;
        out.clear();
        out.resize(top + 1, 0.0);
        let il = y * w + x;
        let [ml, vl] = self.ml.mv[il];
        if vl == 0.0 {
            out.fill(NO_CORRELATION);
            return;
        }
        // out[e] sums L·R for disparity top − e: the right windows of consecutive e are
        // consecutive, so each left pixel of the window adds one contiguous
        // multiply-add over the whole line, which vectorises.
        for row in y - h..=y + h {
            let left = &self.left[row * w + x - h..][..side];
            let right = row * w + x - h - top;
            for (i, &l) in left.iter().enumerate() {
                let r = &self.right[right + i..][..top + 1];
                for (acc, &rv) in out.iter_mut().zip(r) {
                    *acc += l * rv;
                }
            }
        }
        out.reverse();
        for (d, slot) in out.iter_mut().enumerate() {
            let [mr, vr] = self.mr.mv[il - d];
            *slot = if vr == 0.0 {
                NO_CORRELATION
            } else {
                self.similarity_of(*slot * self.inv_n - ml * mr, vl, vr)
            };
        }
    }

    #[inline]
    fn similarity_of(&self, cov: f32, vl: f32, vr: f32) -> f32 {
        similarity_value(self.similarity, cov, vl, vr)
    }

    /// Σ L·R over the window for disparities d + 1, d, d − 1 (needs d ≥ 1 and the
    /// right window at d + 1 inside the image).
    #[inline(always)]
    fn cross3_portable(&self, x: usize, y: usize, d: usize) -> [f32; 3] {
        // Common window sides get fixed-size loops the compiler unrolls and vectorises.
        match self.half {
            1 => self.cross3_fixed::<3>(x, y, d),
            2 => self.cross3_fixed::<5>(x, y, d),
            3 => self.cross3_fixed::<7>(x, y, d),
            _ => self.cross3_any(x, y, d),
        }
    }

    /// The window sums of a fixed window side by [`window_sums`] (lane k: disparity
    /// d + 1 − k), after one range test for the whole window.
    #[inline(always)]
    fn cross3_fixed<const SIDE: usize>(&self, x: usize, y: usize, d: usize) -> [f32; 3] {
        let w = self.width;
        // The window's first pixel in the left image, and that of the right span it
        // reads (disparity d + 1, so one pixel further left).
        let left_first = (y - self.half) * w + x - self.half;
        let left_last = left_first + (SIDE - 1) * w;
        // One range test for the whole window rather than two per row: per-row slicing
        // cost ≈ 80 of the ≈ 215 instructions of a 5 × 5 window. Written so that no
        // sum can wrap. `RIGHT_SLACK` zeros after the right image keep the spare lane's
        // reads in bounds.
        let (left_len, right_len) = (self.left.len(), self.right.len());
        assert!(
            left_first < left_len
                && d < left_first
                && left_last < left_len
                && left_len - left_last >= SIDE
                && left_last - (d + 1) < right_len
                && right_len - (left_last - (d + 1)) >= SIDE + 3,
            "window out of the image"
        );
        let right_first = left_first - (d + 1);
        // SAFETY: row j's left pixels end at left_first + j·w + SIDE ≤ left_last + SIDE,
        // and its right pixels (SIDE + 3 of them) at right_first + j·w + SIDE + 3 ≤
        // left_last − (d + 1) + SIDE + 3: both within the lengths tested above.
        unsafe {
            window_sums::<SIDE>(
                self.left.as_ptr().add(left_first),
                self.right.as_ptr().add(right_first),
                w,
            )
        }
    }

    fn cross3_any(&self, x: usize, y: usize, d: usize) -> [f32; 3] {
        let (w, h) = (self.width, self.half);
        let side = 2 * h + 1;
        let mut sums = [0.0f32; 3];
        for row in y - h..=y + h {
            let start = row * w + x - h;
            let l = &self.left[start..start + side];
            let r = &self.right[start - d - 1..start - d + 1 + side];
            for (k, sum) in sums.iter_mut().enumerate() {
                *sum += l
                    .iter()
                    .zip(&r[k..k + side])
                    .map(|(a, b)| a * b)
                    .sum::<f32>();
            }
        }
        sums
    }

    /// Σ L·R over the window pair (the only per-candidate work).
    #[inline]
    fn cross(&self, x: usize, y: usize, d: usize) -> f32 {
        let (w, h) = (self.width, self.half);
        let side = 2 * h + 1;
        let mut sum = 0.0f32;
        for row in y - h..=y + h {
            let start = row * w + x - h;
            let l = &self.left[start..start + side];
            let r = &self.right[start - d..start - d + side];
            sum += l.iter().zip(r).map(|(a, b)| a * b).sum::<f32>();
        }
        sum
    }

    /// The disparities d with a scorable window pair at left column x:
    /// right column x − d must keep its window inside the image.
    #[inline]
    pub fn max_disparity_at(&self, x: usize) -> usize {
        x.saturating_sub(self.half)
    }

    /// Whether (x, y) has its window fully inside the image.
    #[inline]
    pub fn inside(&self, x: usize, y: usize) -> bool {
        x >= self.half
            && y >= self.half
            && x + self.half < self.width
            && y + self.half < self.height
    }
}

/// The similarities of one left window (mean `ml`, variance `vl` > 0) with three right
/// windows, from their sums Σ L·R (`cross`) and their moments (`right`, same order):
/// `NO_CORRELATION` where a right window has no texture. Four lanes on x86-64 (the x86-64
/// baseline, SSE); the same operations in the same order as [`Correlator::score`]'s
/// scalar ones (no FMA), so the values are bit-identical to a scalar loop.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn similarity3(
    similarity: Similarity,
    cross: [f32; 3],
    inv_n: f32,
    ml: f32,
    vl: f32,
    right: &[[f32; 2]],
) -> [f32; 3] {
    use std::arch::x86_64::*;
    let right: &[[f32; 2]; 3] = right.try_into().expect("three right windows");
    // SAFETY: SSE is part of the x86-64 baseline; the loads read right[0..2] (four
    // floats) and right[2] (two floats), all inside `right`.
    unsafe {
        let first = _mm_loadu_ps(right.as_ptr().cast::<f32>()); // m0 v0 m1 v1
        let last = _mm_castpd_ps(_mm_load_sd(right.as_ptr().add(2).cast::<f64>())); // m2 v2 0 0
        let mr = _mm_shuffle_ps::<0b10_00_10_00>(first, last); // m0 m1 m2 0
        let vr = _mm_shuffle_ps::<0b10_01_11_01>(first, last); // v0 v1 v2 0
        let sums = _mm_setr_ps(cross[0], cross[1], cross[2], 0.0);
        let cov = _mm_sub_ps(
            _mm_mul_ps(sums, _mm_set1_ps(inv_n)),
            _mm_mul_ps(_mm_set1_ps(ml), mr),
        );
        let sim = match similarity {
            Similarity::Mncc => _mm_div_ps(
                _mm_mul_ps(_mm_set1_ps(2.0), cov),
                _mm_add_ps(_mm_set1_ps(vl), vr),
            ),
            Similarity::Ncc => _mm_div_ps(cov, _mm_sqrt_ps(_mm_mul_ps(_mm_set1_ps(vl), vr))),
        };
        let flat = _mm_cmpeq_ps(vr, _mm_setzero_ps());
        let out = _mm_or_ps(
            _mm_and_ps(flat, _mm_set1_ps(NO_CORRELATION)),
            _mm_andnot_ps(flat, sim),
        );
        let mut lanes = [0.0f32; 4];
        _mm_storeu_ps(lanes.as_mut_ptr(), out);
        [lanes[0], lanes[1], lanes[2]]
    }
}

/// The portable form of the x86-64 [`similarity3`].
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn similarity3(
    similarity: Similarity,
    cross: [f32; 3],
    inv_n: f32,
    ml: f32,
    vl: f32,
    right: &[[f32; 2]],
) -> [f32; 3] {
    std::array::from_fn(|k| {
        let [mr, vr] = right[k];
        if vr == 0.0 {
            return NO_CORRELATION;
        }
        similarity_value(similarity, cross[k] * inv_n - ml * mr, vl, vr)
    })
}

/// The similarity of two windows from their covariance and variances.
#[inline]
fn similarity_value(similarity: Similarity, cov: f32, vl: f32, vr: f32) -> f32 {
    match similarity {
        Similarity::Mncc => 2.0 * cov / (vl + vr),
        Similarity::Ncc => cov / (vl * vr).sqrt(),
    }
}

/// Σ L·R over a SIDE × SIDE window for three right shifts: lane k of the result sums
/// left[j·w + i] · right[j·w + i + k] (k = 0, 1, 2; lane 3 is a spare computed for free).
/// Each row has its own four-lane accumulator, and the rows are summed in order
/// afterwards: the same multiplications and additions in the same order as a scalar loop,
/// so the result is bit-identical to it. Explicit SSE (the x86-64 baseline) because the
/// compiler, seeing lane 3 unused, splits the lanes into a pair and a scalar and more
/// than doubles the instructions.
///
/// # Safety
/// `left` must be readable for rows j < SIDE of SIDE pixels at `left + j·w`, and `right`
/// for SIDE + 3 pixels at `right + j·w`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn window_sums<const SIDE: usize>(
    left: *const f32,
    right: *const f32,
    w: usize,
) -> [f32; 3] {
    use std::arch::x86_64::{
        _mm_add_ps, _mm_loadu_ps, _mm_mul_ps, _mm_set1_ps, _mm_setzero_ps, _mm_storeu_ps,
    };
    let mut rows = [_mm_setzero_ps(); SIDE];
    for (j, acc) in rows.iter_mut().enumerate() {
        let (l, r) = (left.add(j * w), right.add(j * w));
        for i in 0..SIDE {
            *acc = _mm_add_ps(
                *acc,
                _mm_mul_ps(_mm_set1_ps(*l.add(i)), _mm_loadu_ps(r.add(i))),
            );
        }
    }
    let mut sums = _mm_setzero_ps();
    for acc in rows {
        sums = _mm_add_ps(sums, acc);
    }
    let mut out = [0.0f32; 4];
    _mm_storeu_ps(out.as_mut_ptr(), sums);
    [out[0], out[1], out[2]]
}

/// The portable form of the x86-64 [`window_sums`]: the same sums in the same order.
///
/// # Safety
/// As for the x86-64 form.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
unsafe fn window_sums<const SIDE: usize>(
    left: *const f32,
    right: *const f32,
    w: usize,
) -> [f32; 3] {
    let mut rows = [[0.0f32; 3]; SIDE];
    for (j, acc) in rows.iter_mut().enumerate() {
        let (l, r) = (left.add(j * w), right.add(j * w));
        for i in 0..SIDE {
            for k in 0..3 {
                acc[k] += *l.add(i) * *r.add(i + k);
            }
        }
    }
    let mut sums = [0.0f32; 3];
    for acc in &rows {
        for k in 0..3 {
            sums[k] += acc[k];
        }
    }
    sums
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize, seed: u64) -> Vec<f32> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect()
    }

    /// Brute-force correlation straight from the definition, of the window of
    /// half-size `half` at (x, y) in `l` (`w` pixels wide) with the one at (x − d, y)
    /// in `r`.
    fn brute(
        (l, r, w): (&[f32], &[f32], usize),
        half: usize,
        (x, y, d): (usize, usize, usize),
        sim: Similarity,
    ) -> f64 {
        let (mut nl, mut nr) = (l.to_vec(), r.to_vec());
        assert!(normalise(&mut nl) && normalise(&mut nr));
        let mut a = Vec::new();
        let mut b = Vec::new();
        for yy in y - half..=y + half {
            for xx in x - half..=x + half {
                a.push(nl[yy * w + xx] as f64);
                b.push(nr[yy * w + xx - d] as f64);
            }
        }
        let n = a.len() as f64;
        let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
        let va = a.iter().map(|v| (v - ma).powi(2)).sum::<f64>() / n;
        let vb = b.iter().map(|v| (v - mb).powi(2)).sum::<f64>() / n;
        let cov = a
            .iter()
            .zip(&b)
            .map(|(p, q)| (p - ma) * (q - mb))
            .sum::<f64>()
            / n;
        match sim {
            Similarity::Mncc => 2.0 * cov / (va + vb),
            Similarity::Ncc => cov / (va * vb).sqrt(),
        }
    }

    #[test]
    fn score_matches_the_definition() {
        let (w, h) = (23, 17);
        let l = noise(w * h, 1);
        let r = noise(w * h, 2);
        for sim in [Similarity::Mncc, Similarity::Ncc] {
            for half in [1, 2, 3] {
                let c = Correlator::new(l.clone(), r.clone(), w, h, half, 1e-3, sim).unwrap();
                for (x, y, d) in [(10, 8, 0), (15, 5, 7), (19, 13, 3), (half + 4, half, 4)] {
                    let got = c.score(x, y, d) as f64;
                    let want = brute((&l, &r, w), half, (x, y, d), sim);
                    assert!(
                        (got - want).abs() < 1e-4,
                        "{sim:?} h={half} ({x},{y},{d}): {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn box_filter_moments_match_the_definition_across_task_borders() {
        // Taller than two tasks of MOMENT_ROWS rows, so running sums restart twice.
        let (w, h) = (19, 2 * MOMENT_ROWS + 11);
        let img = noise(w * h, 6);
        for half in [1, 2, 3] {
            let m = moments(&img, w, h, half, 1e-6);
            for y in 0..h {
                for x in 0..w {
                    let [mean, var] = m.mv[y * w + x];
                    if x < half || y < half || x + half >= w || y + half >= h {
                        assert_eq!([mean, var], [0.0, 0.0], "border ({x},{y})");
                        continue;
                    }
                    let window: Vec<f64> = (y - half..=y + half)
                        .flat_map(|yy| (x - half..=x + half).map(move |xx| (yy, xx)))
                        .map(|(yy, xx)| img[yy * w + xx] as f64)
                        .collect();
                    let n = window.len() as f64;
                    let want_mean = window.iter().sum::<f64>() / n;
                    let want_var = window.iter().map(|v| (v - want_mean).powi(2)).sum::<f64>() / n;
                    assert!((mean as f64 - want_mean).abs() < 1e-6, "mean ({x},{y})");
                    assert!((var as f64 - want_var).abs() < 1e-6, "var ({x},{y})");
                }
            }
        }
    }

    #[test]
    fn score3_agrees_with_score() {
        let (w, h) = (30, 12);
        let l = noise(w * h, 4);
        let r = noise(w * h, 5);
        for half in 1..=4 {
            let c =
                Correlator::new(l.clone(), r.clone(), w, h, half, 1e-3, Similarity::Mncc).unwrap();
            for (x, y) in [(20, 5), (25, 7), (half, half), (10, 6)] {
                let top = c.max_disparity_at(x).min(12);
                for d in 0..=top {
                    let got = c.score3(x, y, d, top);
                    for (k, &g) in got.iter().enumerate() {
                        let want = match (d + k).checked_sub(1) {
                            Some(dd) if dd <= top => c.score(x, y, dd),
                            _ => NO_CORRELATION,
                        };
                        assert!(
                            (g - want).abs() < 1e-5,
                            "({x},{y}) d={d} k={k}: {g} vs {want}"
                        );
                    }
                }
            }
        }
    }

    /// Noise with flat patches in it, so that some windows have no texture.
    fn patchy_noise(w: usize, h: usize, seed: u64) -> Vec<f32> {
        let mut img = noise(w * h, seed);
        for y in 0..h {
            for x in 0..w {
                if (x / 12 + y / 11 + seed as usize).is_multiple_of(3) {
                    img[y * w + x] = 0.25;
                }
            }
        }
        img
    }

    #[test]
    fn vector_correlations_are_bit_identical_to_a_scalar_loop() {
        // score3 takes the AVX2 build where the CPU has it, and four-lane sums and
        // similarities in either build: all must equal a plain scalar loop bit for bit
        // (rows summed one by one, then the rows in order; no FMA).
        let (w, h) = (40, 24);
        let (l, r) = (patchy_noise(w, h, 8), patchy_noise(w, h, 9));
        for similarity in [Similarity::Mncc, Similarity::Ncc] {
            for half in 1..=4 {
                let c =
                    Correlator::new(l.clone(), r.clone(), w, h, half, 0.05, similarity).unwrap();
                let side = 2 * half + 1;
                let mut flat = 0;
                for y in half..h - half {
                    for x in half + 2..w - half {
                        for d in 1..x - half - 1 {
                            let il = y * w + x;
                            let [ml, vl] = c.ml.mv[il];
                            let want: [f32; 3] = std::array::from_fn(|k| {
                                // k = 0, 1, 2: disparity d − 1 + k.
                                let dk = d - 1 + k;
                                let [mr, vr] = c.mr.mv[il - dk];
                                if vl == 0.0 || vr == 0.0 {
                                    return NO_CORRELATION;
                                }
                                let mut sum = 0.0f32;
                                for j in 0..side {
                                    let mut row = 0.0f32;
                                    for i in 0..side {
                                        let p = (y - half + j) * w + x - half + i;
                                        row += c.left[p] * c.right[p - dk];
                                    }
                                    sum += row;
                                }
                                c.similarity_of(sum * c.inv_n - ml * mr, vl, vr)
                            });
                            flat += want.iter().filter(|&&v| v == NO_CORRELATION).count();
                            let top = c.max_disparity_at(x);
                            let (got, portable) = (c.score3(x, y, d, top), c.score3_inner(x, y, d));
                            assert_eq!(
                                got.map(f32::to_bits),
                                want.map(f32::to_bits),
                                "({x},{y},{d})"
                            );
                            assert_eq!(portable.map(f32::to_bits), want.map(f32::to_bits));
                        }
                    }
                }
                assert!(flat > 0, "the test images must have untextured windows");
            }
        }
    }

    #[test]
    fn avx2_line_scores_are_bit_identical_to_the_portable_ones() {
        let (w, h) = (90, 9);
        let c = Correlator::new(
            noise(w * h, 10),
            noise(w * h, 11),
            w,
            h,
            2,
            1e-3,
            Similarity::Mncc,
        )
        .unwrap();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for x in [2, 3, 17, 40, 87] {
            for top in [0, 1, 5, 9, 16, 33] {
                let top = top.min(c.max_disparity_at(x));
                c.score_line(x, 4, top, &mut a);
                c.score_line_portable(x, 4, top, &mut b);
                assert_eq!(a.len(), top + 1);
                assert!(
                    a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()),
                    "x {x} top {top}"
                );
            }
        }
    }

    #[test]
    fn identical_windows_correlate_perfectly_and_flat_ones_not_at_all() {
        let (w, h) = (20, 10);
        let mut l = noise(w * h, 3);
        for x in 0..8 {
            for y in 0..h {
                l[y * w + x] = 0.5; // flat block on the left
            }
        }
        let c = Correlator::new(l.clone(), l.clone(), w, h, 2, 1e-3, Similarity::Mncc).unwrap();
        assert!((c.score(12, 5, 0) - 1.0).abs() < 1e-5);
        assert!(!c.left_textured(3, 5));
        assert_eq!(c.score(3, 5, 0), NO_CORRELATION);
        assert!(
            Correlator::new(vec![1.0; w * h], l.clone(), w, h, 2, 1e-3, Similarity::Mncc).is_none()
        );
    }
}
