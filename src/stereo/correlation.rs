//! Window correlation between a left and a right image, computed cheaply.
//!
//! Both images are normalised once (global mean 0, global standard deviation 1). The
//! window mean and variance of every pixel come from box filters of I and I², so a
//! candidate match (x, y, d) costs only the cross term Σ L·R over the window.

use rayon::prelude::*;

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
    /// Whether the window sums may take the AVX2 build (the CPU has it and
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

/// Zeros kept after the normalised right image (see `Correlator::cross3_fixed`).
const RIGHT_SLACK: usize = 4;

/// Rows of moments computed by one task: each task keeps its own running column sums.
const MOMENT_ROWS: usize = 32;

/// Window means and variances by box filtering: per task of `MOMENT_ROWS` rows, running
/// column sums of I and I² over the window's rows (one row added and one dropped per
/// step), then a sliding sum along the row. f64 sums, so nothing is lost to the running
/// updates; memory is two rows of sums per task, not two integral images.
fn moments(img: &[f32], width: usize, height: usize, half: usize, min_var: f32) -> Moments {
    let side = 2 * half + 1;
    let inv_n = 1.0 / (side * side) as f64;
    let mut mv = vec![[0.0f32; 2]; width * height];
    if width < side || height < side {
        return Moments { mv };
    }
    let pixel = |y: usize, x: usize| img[y * width + x] as f64;
    mv.par_chunks_mut(width * MOMENT_ROWS)
        .enumerate()
        .for_each(|(task, out)| {
            let first = (task * MOMENT_ROWS).max(half);
            let end = (task * MOMENT_ROWS + out.len() / width).min(height - half);
            if first >= end {
                return;
            }
            // Column sums over rows first − half ..= first + half.
            let (mut c1, mut c2) = (vec![0.0f64; width], vec![0.0f64; width]);
            for y in first - half..=first + half {
                for x in 0..width {
                    let v = pixel(y, x);
                    c1[x] += v;
                    c2[x] += v * v;
                }
            }
            for y in first..end {
                if y > first {
                    let (add, drop) = (y + half, y - half - 1);
                    for x in 0..width {
                        let (a, d) = (pixel(add, x), pixel(drop, x));
                        c1[x] += a - d;
                        c2[x] += a * a - d * d;
                    }
                }
                let row = &mut out[(y - task * MOMENT_ROWS) * width..][..width];
                let (mut s1, mut s2) = (0.0f64, 0.0f64);
                for x in 0..side - 1 {
                    s1 += c1[x];
                    s2 += c2[x];
                }
                for x in half..width - half {
                    s1 += c1[x + half];
                    s2 += c2[x + half];
                    let m = s1 * inv_n;
                    let v = (s2 * inv_n - m * m).max(0.0);
                    // Untextured windows get variance 0: they are never matched.
                    row[x] = [m as f32, if v as f32 >= min_var { v as f32 } else { 0.0 }];
                    s1 -= c1[x - half];
                    s2 -= c2[x - half];
                }
            }
        });
    Moments { mv }
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
        let il = y * self.width + x;
        let [ml, vl] = self.ml.mv[il];
        if vl == 0.0 {
            return [NO_CORRELATION; 3];
        }
        let cross = self.cross3(x, y, d);
        // cross3 returns the sums for d + 1, d, d − 1.
        let mut out = [NO_CORRELATION; 3];
        for (k, slot) in out.iter_mut().enumerate() {
            let ir = il + 1 - d - k; // right pixel at disparity d − 1 + k
            let [mr, vr] = self.mr.mv[ir];
            *slot = if vr == 0.0 {
                NO_CORRELATION
            } else {
                let cov = cross[2 - k] * self.inv_n - ml * mr;
                self.similarity_of(cov, vl, vr)
            };
        }
        out
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
        match self.similarity {
            Similarity::Mncc => 2.0 * cov / (vl + vr),
            Similarity::Ncc => cov / (vl * vr).sqrt(),
        }
    }

    /// Σ L·R over the window for disparities d + 1, d, d − 1 (needs d ≥ 1 and the
    /// right window at d + 1 inside the image).
    #[inline]
    fn cross3(&self, x: usize, y: usize, d: usize) -> [f32; 3] {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is set only when the CPU has AVX2.
            return unsafe { self.cross3_avx2(x, y, d) };
        }
        self.cross3_portable(x, y, d)
    }

    /// [`Correlator::cross3_portable`] compiled for AVX2: the broadcast and the multiply
    /// read memory directly, three instructions per window pixel instead of five. No FMA (Rust never fuses a multiply and an add on its own), so the
    /// sums are bit-identical to the portable build's.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn cross3_avx2(&self, x: usize, y: usize, d: usize) -> [f32; 3] {
        self.cross3_portable(x, y, d)
    }

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

    /// Four lanes per window pixel, one per right shift: lane k sums L·R at disparity
    /// d + 1 − k (lane 3 is a spare the vector unit computes for free), so each window
    /// pixel costs one broadcast, one unaligned load and one multiply-add of four lanes.
    /// Each row has its own accumulator (short dependency chains), and the rows are
    /// summed in order afterwards: the same additions in the same order as a scalar
    /// loop, so the result is bit-identical to it.
    #[inline(always)]
    fn cross3_fixed<const SIDE: usize>(&self, x: usize, y: usize, d: usize) -> [f32; 3] {
        let (w, h) = (self.width, self.half);
        let mut rows = [[0.0f32; 4]; SIDE];
        // Rows by index, not an inclusive range: its exhaustion flag kept the loop
        // from unrolling.
        for (j, acc) in rows.iter_mut().enumerate() {
            let start = (y - h + j) * w + x - h;
            let l: &[f32; SIDE] = self.left[start..start + SIDE].try_into().expect("SIDE");
            // `RIGHT_SLACK` zeros after the image keep the spare lane's load in bounds.
            let r = &self.right[start - d - 1..start - d + 2 + SIDE];
            for i in 0..SIDE {
                let li = l[i];
                let ri: &[f32; 4] = r[i..i + 4].try_into().expect("4 lanes");
                for k in 0..4 {
                    acc[k] += li * ri[k];
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

    /// Brute-force correlation straight from the definition.
    #[allow(clippy::too_many_arguments)]
    fn brute(
        l: &[f32],
        r: &[f32],
        w: usize,
        half: usize,
        x: usize,
        y: usize,
        d: usize,
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
                    let want = brute(&l, &r, w, half, x, y, d, sim);
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

    #[test]
    fn avx2_window_sums_are_bit_identical_to_the_portable_ones() {
        // On a CPU without AVX2 both calls take the portable build: still a valid test.
        let (w, h) = (40, 16);
        let l = noise(w * h, 8);
        let r = noise(w * h, 9);
        for half in 1..=4 {
            let c =
                Correlator::new(l.clone(), r.clone(), w, h, half, 1e-3, Similarity::Mncc).unwrap();
            for y in half..h - half {
                for x in half + 2..w - half {
                    for d in 1..x - half {
                        let (a, b) = (c.cross3(x, y, d), c.cross3_portable(x, y, d));
                        assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits), "({x},{y},{d})");
                    }
                }
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
