//! Seeds and growing: the two stages of Growing Correspondence Seeds (Čech and Šára,
//! "Efficient sampling of disparity space for fast and accurate matching", 2007).
//!
//! A few seeds are matched by exhaustive search along their epipolar line; then a
//! priority queue ordered by correlation grows matches from them into the 4-neighbours
//! of the left image, testing only disparities d − 1, d, d + 1 of the match they grow
//! from. A popped candidate is accepted only when its left and its right pixel are both
//! still free (uniqueness), so the disparity space is sampled only around surfaces.

use super::correlation::Correlator;
use rayon::prelude::*;
use std::hint::select_unpredictable;
use std::ops::Range;
use std::sync::Mutex;

/// Value of the integer disparity map where a pixel has no match.
pub const UNMATCHED: i32 = -1;

/// Number of correlation levels of the bucket queue between the threshold and 1.
/// Candidates within one level (≈ 0.001 of correlation for τ = 0.6) pop in last-in
/// first-out order; a binary heap would order them exactly but costs several times
/// more per candidate.
pub const QUEUE_LEVELS: usize = 512;

/// What the neighbours of one accepted match share while growing into them.
struct Step {
    /// The match's disparity.
    d: usize,
    /// The largest disparity considered.
    max_d: usize,
    /// [`order_key`] of the acceptance threshold.
    threshold_key: i32,
}

/// A candidate match: left pixel index, disparity, correlation.
#[derive(Clone, Copy)]
struct Candidate {
    idx: u32,
    d: u32,
    c: f32,
}

/// A monotone priority queue of candidates with correlation in [threshold, 1], bucketed
/// into `QUEUE_LEVELS` levels: push and pop in O(1).
struct BucketQueue {
    buckets: Vec<Vec<Candidate>>,
    top: usize,
    len: usize,
    floor: f32,
    scale: f32,
}

impl BucketQueue {
    fn new() -> Self {
        BucketQueue {
            buckets: (0..QUEUE_LEVELS).map(|_| Vec::new()).collect(),
            top: 0,
            len: 0,
            floor: 0.0,
            scale: 1.0,
        }
    }

    /// Empties the queue (keeping the storage) for correlations in [threshold, 1].
    fn reset(&mut self, threshold: f32) {
        self.buckets.iter_mut().for_each(Vec::clear);
        self.top = 0;
        self.len = 0;
        self.floor = threshold;
        self.scale = (QUEUE_LEVELS - 1) as f32 / (1.0 - threshold).max(f32::EPSILON);
    }

    #[inline]
    fn push(&mut self, cand: Candidate) {
        let level = (((cand.c - self.floor) * self.scale) as usize).min(QUEUE_LEVELS - 1);
        self.buckets[level].push(cand);
        self.top = self.top.max(level);
        self.len += 1;
    }

    #[inline]
    fn pop(&mut self) -> Option<Candidate> {
        if self.len == 0 {
            return None;
        }
        loop {
            if let Some(c) = self.buckets[self.top].pop() {
                self.len -= 1;
                return Some(c);
            }
            self.top -= 1; // len > 0: a lower bucket holds something
        }
    }
}

/// A tiny deterministic generator (SplitMix64) for drawing seed pixels.
pub struct SplitMix64(u64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in 0..n (n > 0); the modulo bias is negligible for image sizes.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// The best disparity of left pixel (x, y) by exhaustive search over 0..=max_d, with
/// its correlation, if it is distinct: the best correlation outside d ± 1 must leave at
/// least `1 / distinctness` times more dissimilarity (1 − c) than the best. `scores` is
/// scratch space (reused between calls).
pub fn search_line(
    corr: &Correlator,
    x: usize,
    y: usize,
    max_d: usize,
    distinctness: f32,
    scores: &mut Vec<f32>,
) -> Option<(usize, f32)> {
    let top = max_d.min(corr.max_disparity_at(x));
    corr.score_line(x, y, top, scores);
    let (best_d, best) =
        scores
            .iter()
            .copied()
            .enumerate()
            .fold(
                (0, f32::NEG_INFINITY),
                |a, (d, c)| if c > a.1 { (d, c) } else { a },
            );
    if !best.is_finite() {
        return None;
    }
    let runner_up = scores
        .iter()
        .enumerate()
        .filter(|&(d, _)| d + 1 < best_d || d > best_d + 1)
        .map(|(_, &c)| c)
        .fold(f32::NEG_INFINITY, f32::max);
    // Strict, so two perfect matches are ambiguous; ρ = 1 turns the test off.
    let distinct = distinctness >= 1.0 || (1.0 - best) < distinctness * (1.0 - runner_up);
    distinct.then_some((best_d, best))
}

/// Random seeds: `count` left pixels drawn with `rng` (textured, window inside), each
/// matched by [`search_line`]; returns (x, y, d, correlation) of those that pass
/// `threshold` and the distinctness test. Seeds are searched in parallel.
pub fn random_seeds(
    corr: &Correlator,
    count: usize,
    max_d: usize,
    threshold: f32,
    distinctness: f32,
    rng: &mut SplitMix64,
) -> Vec<(usize, usize, usize, f32)> {
    let (w, h, half) = (corr.width(), corr.height(), corr.half());
    if w <= 2 * half || h <= 2 * half {
        return Vec::new();
    }
    let pixels: Vec<(usize, usize)> = (0..count)
        .map(|_| {
            (
                half + rng.below(w - 2 * half),
                half + rng.below(h - 2 * half),
            )
        })
        .collect();
    pixels
        .par_iter()
        .filter(|&&(x, y)| corr.left_textured(x, y))
        .map_init(Vec::new, |scores, &(x, y)| {
            let (d, c) = search_line(corr, x, y, max_d, distinctness, scores)?;
            (c >= threshold).then_some((x, y, d, c))
        })
        .flatten()
        .collect()
}

/// Largest disparity the grower can store (its per-pixel state holds 16-bit values).
pub const DISPARITY_LIMIT: usize = i16::MAX as usize;

/// Per left pixel: a cache of the correlations at disparities `cached_d` − 1,
/// `cached_d`, `cached_d` + 1 (`cached_d` = `NOT_CACHED` when empty). Neighbours usually
/// grow into a pixel with the same d, and the subpixel step needs the same three
/// values. The match itself lives in a separate, compact array: the growing loop tests
/// it for every neighbour, and a 2-byte state keeps that test in cache where a 16-byte
/// cell would miss.
#[derive(Clone, Copy)]
struct Cache {
    cached_d: u16,
    /// The disparity of this pixel's latest candidate in the queue (`NOT_CACHED` when
    /// none was pushed). While the pixel is unmatched and that disparity is still the
    /// best free one, the candidate is still pending, so pushing it again would only
    /// add a pop that is rejected.
    pushed_d: u16,
    scores: [f32; 3],
}

const NO_MATCH: i16 = -1;
/// Padding before the band's first right pixel in `Grower::right_used`.
const RIGHT_PAD: usize = 2;

const NOT_CACHED: u16 = u16::MAX;
const EMPTY_CACHE: Cache = Cache {
    cached_d: NOT_CACHED,
    pushed_d: NOT_CACHED,
    scores: [0.0; 3],
};

/// An integer that orders correlations like the floats themselves (−0 and +0 alike):
/// the sign-magnitude bits with the magnitude of negatives flipped.
#[inline]
fn order_key(c: f32) -> i32 {
    let bits = (c + 0.0).to_bits() as i32; // + 0.0 turns −0 into +0
    bits ^ (((bits >> 31) as u32) >> 1) as i32
}

/// The best of three candidate correlations `scores` whose right pixel is not `used`:
/// its position and [`order_key`] (`i32::MIN` when all are used); ties go to the first.
/// Without branches (the queue order makes them unpredictable): in integers, where
/// selects become conditional moves (float selects became branches). The growing
/// passes the scores of d − 1, d, d + 1; out of range, score3 gave NO_CORRELATION,
/// below any threshold, so only the right pixel's flag needs testing.
#[inline(always)]
fn best_free(scores: [f32; 3], used: [bool; 3]) -> (usize, i32) {
    let key = |k: usize| select_unpredictable(used[k], i32::MIN, order_key(scores[k]));
    let (k0, k1, k2) = (key(0), key(1), key(2));
    let k = (k1 > k0) as usize;
    let best = k0.max(k1);
    (select_unpredictable(k2 > best, 2, k), best.max(k2))
}

/// Reusable state of the growing stage.
pub struct Grower {
    queue: BucketQueue,
    right_used: Vec<bool>,
    /// Disparity of each left pixel of the band, `NO_MATCH` where none.
    disp: Vec<i16>,
    /// One bit per left pixel of the band: whether it is matched. The growing tests it
    /// for every popped candidate and every neighbour; as bits the whole band's flags
    /// stay in the first-level cache, where `disp` (read only at the end) does not.
    matched: Vec<u64>,
    cache: Vec<Cache>,
    /// The rows this grower works on: matches never grow out of them. Rows are
    /// independent for uniqueness (epipolar lines), so bands can grow in parallel.
    rows: Range<usize>,
}

impl Grower {
    pub fn new() -> Self {
        Grower {
            queue: BucketQueue::new(),
            right_used: Vec::new(),
            disp: Vec::new(),
            matched: Vec::new(),
            cache: Vec::new(),
            rows: 0..0,
        }
    }

    /// Grows matches from `seeds` (x, y, d) within `rows`. Only candidates with
    /// correlation ≥ `threshold` are accepted, and no disparity above `max_d`
    /// (≤ `DISPARITY_LIMIT`). Seeds outside `rows` are ignored. Read the result with
    /// [`Grower::disparity`].
    pub fn grow(
        &mut self,
        corr: &Correlator,
        seeds: &[(usize, usize, usize)],
        max_d: usize,
        threshold: f32,
        rows: Range<usize>,
    ) {
        let w = corr.width();
        let rows = rows.start.min(corr.height())..rows.end.min(corr.height());
        let n = w * rows.len();
        // Indices below are relative to the band's first pixel.
        let first = rows.start * w;
        self.rows = rows.clone();
        let max_d = max_d.min(DISPARITY_LIMIT);
        // Right pixel r of the band is `right_used[r + RIGHT_PAD]`; the padding lets the
        // candidate choice read all three disparities without range tests.
        self.right_used.clear();
        self.right_used.resize(n + RIGHT_PAD + 1, false);
        self.disp.clear();
        self.disp.resize(n, NO_MATCH);
        self.matched.clear();
        self.matched.resize(n.div_ceil(64), 0);
        self.cache.clear();
        self.cache.resize(n, EMPTY_CACHE);
        self.queue.reset(threshold);
        let threshold_key = order_key(threshold);

        for &(x, y, d) in seeds {
            if rows.contains(&y) && corr.inside(x, y) && d <= max_d.min(corr.max_disparity_at(x)) {
                let c = corr.score(x, y, d);
                if c >= threshold {
                    self.queue.push(Candidate {
                        idx: (y * w + x - first) as u32,
                        d: d as u32,
                        c,
                    });
                }
            }
        }

        while let Some(cand) = self.queue.pop() {
            let (idx, d) = (cand.idx as usize, cand.d as usize);
            if self.is_matched(idx) || self.right_used[idx - d + RIGHT_PAD] {
                continue; // uniqueness: one of the two pixels is taken already
            }
            self.disp[idx] = d as i16;
            self.matched[idx / 64] |= 1 << (idx % 64);
            self.right_used[idx - d + RIGHT_PAD] = true;
            let (x, y) = (idx % w, rows.start + idx / w);
            // The popped pixel's window lies inside the image and its row inside the
            // band (it was queued from a seed or a neighbour that passed these tests), so
            // each neighbour needs only the one test its step can fail.
            let half = corr.half();
            let step = Step {
                d,
                max_d,
                threshold_key,
            };
            // Four calls rather than a loop over the neighbours: each call's tests get
            // their own branch history, and the loop's own exit tests go (cachegrind's
            // branch simulation put 150 k mispredictions per cones call on them).
            if x > half {
                self.visit(corr, &step, idx - 1, x - 1, y);
            }
            if x + 1 + half < w {
                self.visit(corr, &step, idx + 1, x + 1, y);
            }
            if y > half.max(rows.start) {
                self.visit(corr, &step, idx - w, x, y - 1);
            }
            if y + 1 + half < corr.height() && y + 1 < rows.end {
                self.visit(corr, &step, idx + w, x, y + 1);
            }
        }
    }

    /// Whether pixel `idx` of the band is matched.
    #[inline(always)]
    fn is_matched(&self, idx: usize) -> bool {
        (self.matched[idx / 64] >> (idx % 64)) & 1 != 0
    }

    /// Growing from a match at disparity `step.d` into its neighbour (nx, ny), pixel
    /// `nidx` of the band, whose window lies inside the image: the best free one of
    /// d − 1, d, d + 1 there is queued if it passes the threshold.
    #[inline(always)]
    fn visit(&mut self, corr: &Correlator, step: &Step, nidx: usize, nx: usize, ny: usize) {
        let d = step.d;
        if self.is_matched(nidx) {
            return;
        }
        let cell = &mut self.cache[nidx];
        let top = step.max_d.min(corr.max_disparity_at(nx));
        if d > top + 1 {
            return; // even d − 1 is out of range here
        }
        if cell.cached_d != d as u16 {
            cell.scores = corr.score3(nx, ny, d, top);
            cell.cached_d = d as u16;
        }
        // Flags of the right pixels of d + 1, d, d − 1 (`RIGHT_PAD` keeps d = 0 and the
        // band's first pixels in bounds).
        let used = &self.right_used[nidx + RIGHT_PAD - 1 - d..][..3];
        let s = cell.scores;
        let (k, best_key) = best_free(s, [used[2], used[1], used[0]]);
        let best_d = (d + k).wrapping_sub(1); // d − 1 + k; k ≥ 1 when d = 0 and it counts
        if best_key >= step.threshold_key && cell.pushed_d != best_d as u16 {
            cell.pushed_d = best_d as u16;
            self.queue.push(Candidate {
                idx: nidx as u32,
                d: best_d as u32,
                c: s[k],
            });
        }
    }

    /// The integer disparity of every left pixel of its rows after [`Grower::grow`],
    /// `UNMATCHED` where none, appended to `out`.
    pub fn disparity(&self, out: &mut Vec<i32>) {
        out.extend(
            self.disp
                .iter()
                .map(|&d| if d == NO_MATCH { UNMATCHED } else { d as i32 }),
        );
    }

    /// Correlations at d − 1, d, d + 1 of left pixel (x, y) after [`Grower::grow`]
    /// (from the cache when there), `NO_CORRELATION` outside 0..=top.
    pub fn scores_around(
        &self,
        corr: &Correlator,
        x: usize,
        y: usize,
        d: usize,
        top: usize,
    ) -> [f32; 3] {
        if !self.rows.contains(&y) {
            return corr.score3(x, y, d, top);
        }
        match self.cache.get((y - self.rows.start) * corr.width() + x) {
            Some(cell) if cell.cached_d as usize == d => cell.scores,
            _ => corr.score3(x, y, d, top),
        }
    }
}

/// Growers kept between calls, so that a stream of frames does not allocate (and fault
/// in) the per-pixel state and the queue's buckets afresh for every band of every call
/// (a few per cent of a call on the stereo benchmark's pairs).
static POOL: Mutex<Vec<Grower>> = Mutex::new(Vec::new());

/// Most bytes of grower storage kept in the pool between calls.
const POOL_BYTES: usize = 64 << 20;

impl Grower {
    /// A grower from the pool of earlier calls' growers, or a new one.
    pub fn pooled() -> Self {
        let reused = POOL.lock().ok().and_then(|mut pool| pool.pop());
        reused.unwrap_or_default()
    }

    /// Returns `growers` to the pool, as many as fit in its byte budget.
    pub fn recycle(growers: Vec<Grower>) {
        let Ok(mut pool) = POOL.lock() else {
            return; // a poisoned pool: the growers are simply dropped
        };
        let mut held: usize = pool.iter().map(Grower::heap_bytes).sum();
        for g in growers {
            let bytes = g.heap_bytes();
            if held + bytes <= POOL_BYTES {
                held += bytes;
                pool.push(g);
            }
        }
    }

    /// Heap storage held by this grower, in bytes.
    fn heap_bytes(&self) -> usize {
        use std::mem::size_of;
        self.right_used.capacity() * size_of::<bool>()
            + self.disp.capacity() * size_of::<i16>()
            + self.matched.capacity() * size_of::<u64>()
            + self.cache.capacity() * size_of::<Cache>()
            + self
                .queue
                .buckets
                .iter()
                .map(|b| b.capacity() * size_of::<Candidate>())
                .sum::<usize>()
    }
}

impl Default for Grower {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::super::correlation::Similarity;
    use super::*;

    #[test]
    fn queue_pops_by_decreasing_level() {
        let mut q = BucketQueue::new();
        q.reset(0.5);
        for (i, c) in [0.6f32, 0.99, 0.5, 1.0, 0.75, 0.8].into_iter().enumerate() {
            q.push(Candidate {
                idx: i as u32,
                d: 0,
                c,
            });
        }
        let order: Vec<f32> = std::iter::from_fn(|| q.pop()).map(|c| c.c).collect();
        assert_eq!(order, vec![1.0, 0.99, 0.8, 0.75, 0.6, 0.5]);
        assert!(q.pop().is_none());
        q.push(Candidate {
            idx: 9,
            d: 1,
            c: 0.7,
        });
        assert_eq!(q.pop().map(|c| c.idx), Some(9));
    }

    #[test]
    fn seed_search_finds_the_shift_and_refuses_repetitive_texture() {
        let (w, h, shift) = (60, 9, 7);
        let mut rng = SplitMix64::new(3);
        let right: Vec<f32> = (0..w * h).map(|_| rng.below(100) as f32).collect();
        let left: Vec<f32> = (0..w * h)
            .map(|i| {
                if i % w >= shift {
                    right[i - shift]
                } else {
                    0.0
                }
            })
            .collect();
        let corr =
            Correlator::new(left.clone(), right.clone(), w, h, 2, 0.01, Similarity::Mncc).unwrap();
        let mut scratch = Vec::new();
        let (d, c) = search_line(&corr, 40, 4, 30, 0.8, &mut scratch).unwrap();
        assert_eq!(d, shift);
        // The scratch holds the score of every disparity 0..=top, whatever top is
        // modulo the three disparities scored per pass.
        for max_d in 0..12 {
            search_line(&corr, 40, 4, max_d, 1.0, &mut scratch);
            assert_eq!(scratch.len(), max_d + 1);
            for (dd, &c) in scratch.iter().enumerate() {
                assert!(
                    (c - corr.score(40, 4, dd)).abs() < 1e-5,
                    "max_d {max_d} d {dd}"
                );
            }
        }
        assert!(c > 0.95); // not 1: the two images are normalised by different global gains
                           // A texture repeating every 6 columns (plus independent noise in each image)
                           // matches about equally well at d and d ± 6.
        let mut stripes = || -> Vec<f32> {
            (0..w * h)
                .map(|i| ((i % w) % 6) as f32 + rng.below(100) as f32 / 100.0)
                .collect()
        };
        let (a, b) = (stripes(), stripes());
        let corr = Correlator::new(a.clone(), b.clone(), w, h, 2, 0.01, Similarity::Mncc).unwrap();
        assert!(search_line(&corr, 40, 4, 30, 0.8, &mut scratch).is_none());
        assert!(search_line(&corr, 40, 4, 30, 1.0, &mut scratch).is_some());
    }

    proptest::proptest! {
        #[test]
        fn order_key_orders_like_the_floats(a in -3.0f32..3.0, b in -3.0f32..3.0) {
            proptest::prop_assert_eq!(a.partial_cmp(&b), Some(order_key(a).cmp(&order_key(b))));
        }

        #[test]
        fn best_free_matches_a_plain_search(
            scores in proptest::array::uniform3(-2.0f32..1.0),
            used in proptest::array::uniform3(proptest::bool::ANY),
            tie in 0usize..4,
        ) {
            // Ties are drawn on purpose: copy one score over another (tie < 3).
            let mut scores = scores;
            if tie < 3 {
                scores[(tie + 1) % 3] = scores[tie];
            }
            let mut want: Option<(usize, f32)> = None;
            for k in 0..3 {
                if !used[k] && want.is_none_or(|(_, b)| scores[k] > b) {
                    want = Some((k, scores[k]));
                }
            }
            let (k, key) = best_free(scores, used);
            match want {
                Some((wk, wc)) => {
                    proptest::prop_assert_eq!(k, wk);
                    proptest::prop_assert_eq!(key, order_key(wc));
                }
                None => proptest::prop_assert_eq!(key, i32::MIN),
            }
        }
    }

    #[test]
    fn order_key_treats_the_zeros_alike_and_keeps_the_no_correlation_mark() {
        assert_eq!(order_key(-0.0), order_key(0.0));
        assert!(order_key(super::super::correlation::NO_CORRELATION) > i32::MIN);
        assert!(order_key(-1.0) > order_key(super::super::correlation::NO_CORRELATION));
    }

    #[test]
    fn rng_is_deterministic_and_in_range() {
        let mut a = SplitMix64::new(7);
        let mut b = SplitMix64::new(7);
        for _ in 0..100 {
            let (p, q) = (a.below(13), b.below(13));
            assert_eq!(p, q);
            assert!(p < 13);
        }
    }
}
