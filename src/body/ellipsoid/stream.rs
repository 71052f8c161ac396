//! The stream root-finder: signed distances (and normals) of a block of points to one
//! ellipsoid, the points streaming through vector registers. Written once over the
//! instruction set ([`crate::simd`]: AVX-512 or AVX2) and the precision (`f64`, or
//! `f32` for callers whose points and results are single precision).
//!
//! The lockstep root-finder ([`super::solve::solve_secular_lanes`]) has two costs
//! beyond its arithmetic: a group of lanes iterates as long as its slowest lane, and
//! one pass is a long chain of latency (two divisions and a square root in a row) that
//! one register cannot fill. Here every lane takes the next queued point as soon as its
//! own has converged (an expanding load puts consecutive queued values into exactly the
//! free lanes), and [`STREAMS`] independent registers are in flight at once, so the
//! divider and the square-root unit stay busy.
//!
//! The set-up (numerators and bracket) and the finish (closest point, signed distance
//! and normal from the root) are the scalar code's expressions evaluated a register of
//! points at a time. Every operation is the scalar code's IEEE operation in the scalar
//! code's order (no fused multiply-add, no reassociation), and each lane runs the
//! scalar stopping rule, so the `f64` distances and normals are bit-identical to the
//! scalar code's, whatever the instruction set; a test checks it.
//!
//! In `f32` a register holds twice the lanes and a division or square root issues as
//! fast, so a distance costs about half as much. The arithmetic is the same with two
//! single-precision tolerances: a root is accepted when |H| ≤ 4 ε₃₂, and Newton stops
//! after a step below 1e-4 relative (the iterate is then off by about (1e-4)², under
//! ε₃₂). The results stay within about 3e-7 × max(1 m, |d|) of the `f64` solve's (a
//! test bounds the difference by 2e-6 m on clouds up to 6 m from the camera), and are
//! the same bits on every instruction set.

use super::solve::{closest_sorted, H_TOLERANCE, MAX_ITERATIONS, ROOT_TOLERANCE};
use super::sorted::SortedPlacement;
use crate::simd::{Arch, Lanes, Real, Simd, WithSimd};
use std::mem::MaybeUninit;

/// Points per call of the kernel (its queue lives on the stack).
pub const BLOCK: usize = 256;

/// Independent registers iterated together (enough to cover one pass's latency with
/// the others' work).
const STREAMS: usize = 4;

/// Queue rows: a block and one register of slack, for whole-register loads and stores
/// past the queue's end.
const ROW: usize = BLOCK + 16;

/// The kernel behind the batched exact distances, decided once per process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// The stream, with this instruction set.
    Stream(Arch),
    /// No stream: the lockstep root-finder.
    Lockstep,
}

/// The best kernel this CPU runs: the stream with AVX-512 unless the environment
/// variable `DEPTHPOSE_NO_AVX512` is set, else with AVX2 unless `DEPTHPOSE_NO_STREAM`
/// is set (both for comparisons, and for testing the other paths), else the lockstep.
#[inline]
pub fn kernel() -> Kernel {
    static DECIDED: std::sync::OnceLock<Kernel> = std::sync::OnceLock::new();
    *DECIDED.get_or_init(|| match Arch::new() {
        #[cfg(target_arch = "x86_64")]
        Some(avx512 @ Arch::Avx512(_)) => Kernel::Stream(avx512),
        Some(arch) if std::env::var_os("DEPTHPOSE_NO_STREAM").is_none() => Kernel::Stream(arch),
        _ => Kernel::Lockstep,
    })
}

/// A precision of the stream: its stopping tolerances.
trait Precision: Real {
    /// |H| below this is a root to rounding precision.
    const H_TOLERANCE: Self;
    /// Newton/bisection stops when the step is below this relative size.
    const ROOT_TOLERANCE: Self;
}

impl Precision for f64 {
    const H_TOLERANCE: f64 = H_TOLERANCE;
    const ROOT_TOLERANCE: f64 = ROOT_TOLERANCE;
}

impl Precision for f32 {
    const H_TOLERANCE: f32 = 4.0 * f32::EPSILON;
    const ROOT_TOLERANCE: f32 = 1e-4;
}

/// The constants of the sorted ellipsoid the kernel reads, in its precision.
#[derive(Clone, Copy)]
struct Shape<E> {
    /// Half-axes, descending.
    e: [E; 3],
    /// 1 / e_k.
    inv_e: [E; 3],
    /// r_k = (e_k / e2)².
    r: [E; 3],
    /// b_k = r_k − 1.
    b: [E; 3],
    /// 1 / e_k².
    inv_e2: [E; 3],
}

impl<E: Real> Shape<E> {
    fn new(p: &SortedPlacement) -> Self {
        let narrow = |v: [f64; 3]| v.map(E::from_f64);
        let c = &p.sorted;
        Shape {
            e: narrow(c.e),
            inv_e: narrow(c.inv_e),
            r: narrow(c.r),
            b: narrow(c.b),
            inv_e2: narrow(p.inv_e2),
        }
    }
}

/// The queue of one block, in point order (or, where points leave it, in the order of
/// those kept): the numerators and bracket of each queued point's secular equation and
/// its first-octant coordinates, then the roots by queue position. Rows of the scratch
/// storage, which is left uninitialised (zeroing it costs more than a tenth of a call):
/// every entry is written before it is read.
struct Queue<E> {
    a: [*mut E; 3],
    lo: *mut E,
    hi: *mut E,
    ys: [*mut E; 3],
    roots: *mut E,
    /// Each queued point's index in the block (written where points leave the queue).
    index: *mut u32,
    /// Queued points on the plane y2 = 0 (bit j of word j / 64 for queue position j):
    /// they take the scalar special cases.
    planar: [u64; BLOCK / 64],
    len: usize,
}

/// The scratch storage of a [`Queue`].
struct QueueStorage<E> {
    rows: MaybeUninit<[[E; ROW]; 9]>,
    index: MaybeUninit<[u32; ROW]>,
}

impl<E: Real> QueueStorage<E> {
    fn new() -> Self {
        QueueStorage {
            rows: MaybeUninit::uninit(),
            index: MaybeUninit::uninit(),
        }
    }

    fn queue(&mut self) -> Queue<E> {
        let base = self.rows.as_mut_ptr() as *mut E;
        // SAFETY: row k < 9 starts inside the storage.
        let row = |k: usize| unsafe { base.add(k * ROW) };
        Queue {
            a: [row(0), row(1), row(2)],
            lo: row(3),
            hi: row(4),
            ys: [row(5), row(6), row(7)],
            roots: row(8),
            index: self.index.as_mut_ptr() as *mut u32,
            planar: [0; BLOCK / 64],
            len: 0,
        }
    }
}

/// The lanes below `n`, as bits.
#[inline(always)]
fn first_lanes(n: usize) -> u32 {
    (1u32 << n) - 1
}

/// `v²`, lane by lane.
#[inline(always)]
fn sq<S: Lanes<E>, E: Real>(s: S, v: S::V) -> S::V {
    s.mul(v, v)
}

/// One value per register of the stream: `$e` for `$g` = 0, 1, …, [`STREAMS`] − 1
/// (written out, not a closure, so that it is compiled with the kernel's instruction
/// set).
macro_rules! each {
    (|$g:ident| $e:expr) => {
        [
            {
                let $g = 0;
                $e
            },
            {
                let $g = 1;
                $e
            },
            {
                let $g = 2;
                $e
            },
            {
                let $g = 3;
                $e
            },
        ]
    };
}
const _: () = assert!(STREAMS == 4, "`each!` writes out four registers");

/// Where a block's points come from: their first-octant local coordinates, a register
/// at a time. (A trait, not a closure: a closure would be compiled without the kernel's
/// instruction set.)
trait Points<E: Real> {
    /// |local coordinates| of the points `base + l` for the lanes l of `m`.
    ///
    /// # Safety
    /// The points `base + l` exist for the lanes l of `m`.
    unsafe fn first_octant<S: Lanes<E>>(&self, s: S, base: usize, m: S::M) -> [S::V; 3];
}

/// Local points (from [`SortedPlacement::local`]), one coordinate per slice.
struct LocalPoints<'a> {
    y: [&'a [f64]; 3],
}

impl Points<f64> for LocalPoints<'_> {
    #[inline(always)]
    unsafe fn first_octant<S: Lanes<f64>>(&self, s: S, base: usize, m: S::M) -> [S::V; 3] {
        let y = &self.y;
        [
            s.abs(s.load_where(y[0].as_ptr().add(base), m)),
            s.abs(s.load_where(y[1].as_ptr().add(base), m)),
            s.abs(s.load_where(y[2].as_ptr().add(base), m)),
        ]
    }
}

/// Camera-frame points in single precision, one coordinate per slice, with the
/// ellipsoid's centre and sorted axes narrowed to single precision.
struct CameraPoints<'a> {
    p: [&'a [f32]; 3],
    axes: [[f32; 3]; 3],
    centre: [f32; 3],
}

impl Points<f32> for CameraPoints<'_> {
    /// The scalar expressions of [`SortedPlacement::local`] in single precision.
    #[inline(always)]
    unsafe fn first_octant<S: Lanes<f32>>(&self, s: S, base: usize, m: S::M) -> [S::V; 3] {
        let (p, c) = (&self.p, &self.centre);
        let d = [
            s.sub(s.load_where(p[0].as_ptr().add(base), m), s.splat(c[0])),
            s.sub(s.load_where(p[1].as_ptr().add(base), m), s.splat(c[1])),
            s.sub(s.load_where(p[2].as_ptr().add(base), m), s.splat(c[2])),
        ];
        let a = &self.axes;
        [
            abs_dot(s, &a[0], &d),
            abs_dot(s, &a[1], &d),
            abs_dot(s, &a[2], &d),
        ]
    }
}

/// |a · d| with the products summed in order.
#[inline(always)]
fn abs_dot<S: Lanes<f32>>(s: S, a: &[f32; 3], d: &[S::V; 3]) -> S::V {
    s.abs(s.add(
        s.add(s.mul(s.splat(a[0]), d[0]), s.mul(s.splat(a[1]), d[1])),
        s.mul(s.splat(a[2]), d[2]),
    ))
}

/// Queues the block's `n` points: for each, the numerators a_k = r_k z_k of its
/// normalised secular equation and its bracket [lo, hi] (`Sorted::secular_setup`, lane
/// by lane). A planar point gets a trivial problem (a = (0, 0, 1), lo = hi = 1: S(1) =
/// 1, done on the first pass) and is marked for the scalar special cases. With a `cap`
/// (and the outputs `out`), a point whose distance lower bound reaches it gets that
/// bound (outside the ellipsoid, the larger of e_min (√level − 1) and |y| − e_max) and
/// leaves the queue.
///
/// # Safety
/// `points` holds `n` (≤ [`BLOCK`]) points; `out` is valid for writing `n` values.
#[inline(always)]
unsafe fn set_up<S: Lanes<E>, E: Precision>(
    s: S,
    c: &Shape<E>,
    (points, n): (&impl Points<E>, usize),
    cap: Option<(E, *mut E)>,
    q: &mut Queue<E>,
) {
    let (one, zero) = (s.splat(E::ONE), s.splat(E::ZERO));
    for base in (0..n).step_by(S::LANES) {
        let count = (n - base).min(S::LANES);
        let m = first_lanes(count);
        let lanes = s.mask(m);
        let [ys0, ys1, ys2] = points.first_octant(s, base, lanes);
        let z0 = s.mul(ys0, s.splat(c.inv_e[0]));
        let z1 = s.mul(ys1, s.splat(c.inv_e[1]));
        let z2 = s.mul(ys2, s.splat(c.inv_e[2]));
        let a0 = s.mul(s.splat(c.r[0]), z0);
        let a1 = s.mul(s.splat(c.r[1]), z1);
        let a2 = z2;
        let mut lo = z2;
        // lo = lo.max(r_k (z_k − 1) + 1) where z_k > 0.
        for (z, r) in [(z0, c.r[0]), (z1, c.r[1])] {
            let single = s.add(s.mul(s.splat(r), s.sub(z, one)), one);
            lo = s.select(s.gt(z, zero), s.max(lo, single), lo);
        }
        let hi = s.sqrt(s.add(s.add(sq(s, a0), sq(s, a1)), sq(s, a2)));
        let pair = s.sub(s.sqrt(s.add(sq(s, a1), sq(s, a2))), s.splat(c.b[1]));
        lo = s.max(s.max(lo, pair), s.sub(hi, s.splat(c.b[0])));
        let hi = s.max(hi, lo);
        let mut keep = m;
        if let Some((cap, out)) = cap {
            let level = s.add(
                s.add(
                    s.mul(sq(s, ys0), s.splat(c.inv_e2[0])),
                    s.mul(sq(s, ys1), s.splat(c.inv_e2[1])),
                ),
                s.mul(sq(s, ys2), s.splat(c.inv_e2[2])),
            );
            let norm = s.sqrt(s.add(s.add(sq(s, ys0), sq(s, ys1)), sq(s, ys2)));
            let bound = s.max(
                s.mul(s.splat(c.e[2]), s.sub(s.sqrt(level), one)),
                s.sub(norm, s.splat(c.e[0])),
            );
            let far = s.and(s.and(lanes, s.gt(level, one)), s.ge(bound, s.splat(cap)));
            s.store_where(out.add(base), far, bound);
            keep &= !s.bits(far);
        }
        let flat = s.and(s.eq(ys2, zero), s.mask(keep));
        let flat_lanes = s.bits(flat);
        let queued = [
            s.select(flat, zero, a0),
            s.select(flat, zero, a1),
            s.select(flat, one, a2),
            s.select(flat, one, lo),
            s.select(flat, one, hi),
            ys0,
            ys1,
            ys2,
        ];
        let rows = [
            q.a[0], q.a[1], q.a[2], q.lo, q.hi, q.ys[0], q.ys[1], q.ys[2],
        ];
        let at = q.len;
        if cap.is_none() {
            // Every point queued: queue position = point index = base + lane.
            for (row, v) in rows.into_iter().zip(queued) {
                s.store(row.add(at), v);
            }
            q.planar[at / 64] |= (flat_lanes as u64) << (at % 64);
        } else {
            let kept = s.compress(keep);
            for (row, v) in rows.into_iter().zip(queued) {
                s.compress_store(row.add(at), kept, v);
            }
            s.compress_store_lanes(q.index.add(at), kept, base);
            let bits = s.compress_bits(flat_lanes, keep) as u64;
            q.planar[at / 64] |= bits << (at % 64);
            if at % 64 + S::LANES > 64 && at / 64 + 1 < q.planar.len() {
                q.planar[at / 64 + 1] |= bits >> (64 - at % 64);
            }
        }
        q.len += keep.count_ones() as usize;
    }
    // One register of harmless values past the queue's end, where the refill's loads
    // may reach.
    for row in [q.a[0], q.a[1], q.a[2], q.lo, q.hi] {
        s.store(row.add(q.len), one);
    }
}

/// The stream: `solve_secular` on every queued point, its root into `q.roots`.
///
/// Each operation of a pass is written for all registers before the next one, so the
/// instruction stream itself interleaves the registers' independent chains (with one
/// register's whole pass after another's, the scheduler fills up with one chain's
/// waiting operations).
///
/// # Safety
/// The queue's rows hold `q.len` queued points and a register of slack.
#[inline(always)]
unsafe fn stream<S: Lanes<E>, E: Precision>(s: S, c: &Shape<E>, q: &Queue<E>) {
    let (one, zero) = (s.splat(E::ONE), s.splat(E::ZERO));
    let (b0, b1, b2) = (s.splat(c.b[0]), s.splat(c.b[1]), s.splat(c.b[2]));
    let half = s.splat(E::from_f64(0.5));
    let (h_tol, root_tol) = (s.splat(E::H_TOLERANCE), s.splat(E::ROOT_TOLERANCE));
    let all = first_lanes(S::LANES);
    let mut u = [zero; STREAMS];
    let mut lo = [zero; STREAMS];
    let mut hi = [zero; STREAMS];
    let mut a0 = [zero; STREAMS];
    let mut a1 = [zero; STREAMS];
    let mut a2 = [zero; STREAMS];
    // Queue position of each lane's point, and the passes it has had.
    let mut at = [s.positions(); STREAMS];
    let mut passes = [s.count_zero(); STREAMS];
    let mut going = [0u32; STREAMS];
    let mut next = 0usize;
    loop {
        // Refill the free lanes from the queue.
        for g in 0..STREAMS {
            let free = !going[g] & all;
            if next < q.len && free != 0 {
                let take = (free.count_ones() as usize).min(q.len - next);
                let load;
                (load, at[g]) = s.refill(at[g], free, take, next);
                let into = s.expand(load);
                a0[g] = s.expand_load(a0[g], into, q.a[0].add(next));
                a1[g] = s.expand_load(a1[g], into, q.a[1].add(next));
                a2[g] = s.expand_load(a2[g], into, q.a[2].add(next));
                lo[g] = s.expand_load(lo[g], into, q.lo.add(next));
                hi[g] = s.expand_load(hi[g], into, q.hi.add(next));
                let fill = s.expand_mask(into);
                u[g] = s.select(fill, lo[g], u[g]);
                passes[g] = s.count_restart(passes[g], into);
                going[g] |= load;
                next += take;
            }
        }
        if going.iter().all(|&g| g == 0) {
            break;
        }
        // One pass of `solve_secular` on every register (see the scalar code for the
        // why); lanes not going compute too and are ignored. `reciprocals` first: the
        // prefix products in the scalar code's order.
        let t0 = each!(|g| s.add(u[g], b0));
        let t1 = each!(|g| s.add(u[g], b1));
        let t2 = each!(|g| s.add(u[g], b2));
        let p01 = each!(|g| s.mul(t0[g], t1[g]));
        let inv = each!(|g| s.div(one, s.mul(p01[g], t2[g])));
        let r2 = each!(|g| s.mul(inv[g], p01[g]));
        let inv = each!(|g| s.mul(inv[g], t2[g]));
        let r1 = each!(|g| s.mul(inv[g], t0[g]));
        let r0 = each!(|g| s.mul(inv[g], t1[g]));
        let q0 = each!(|g| sq(s, s.mul(a0[g], r0[g])));
        let q1 = each!(|g| sq(s, s.mul(a1[g], r1[g])));
        let q2 = each!(|g| sq(s, s.mul(a2[g], r2[g])));
        let sum = each!(|g| s.add(s.add(q0[g], q1[g]), q2[g]));
        let ds = each!(|g| {
            s.add(
                s.add(s.mul(q0[g], r0[g]), s.mul(q1[g], r1[g])),
                s.mul(q2[g], r2[g]),
            )
        });
        let root = each!(|g| s.sqrt(sum[g]));
        let root_m1 = each!(|g| s.sub(root[g], one));
        let newton = each!(|g| s.add(u[g], s.div(s.mul(sum[g], root_m1[g]), ds[g])));
        for g in 0..STREAMS {
            let at_root = s.le(s.abs(root_m1[g]), h_tol);
            let above = s.gt(root[g], one);
            let lo_n = s.select(above, u[g], lo[g]);
            let hi_n = s.select(above, hi[g], u[g]);
            let inside = s.and(s.gt(newton[g], lo_n), s.lt(newton[g], hi_n));
            let bisect = s.mul(half, s.add(lo_n, hi_n));
            let step_to = s.select(inside, newton[g], bisect);
            let small = s.or(
                s.le(s.abs(s.sub(step_to, u[g])), s.mul(root_tol, s.abs(u[g]))),
                s.le(s.sub(hi_n, lo_n), s.mul(h_tol, hi_n)),
            );
            passes[g] = s.count_step(passes[g]);
            // After the last allowed pass the scalar loop returns its last iterate.
            let capped = s.count_is(passes[g], MAX_ITERATIONS);
            let done = going[g] & s.bits(s.or(s.or(at_root, small), capped));
            if done != 0 {
                // A lane at the root returns u; one with a small step (or capped), next.
                s.scatter(q.roots, at[g], done, s.select(at_root, u[g], step_to));
            }
            let go = going[g] & !done;
            let keep = s.mask(go);
            u[g] = s.select(keep, step_to, u[g]);
            lo[g] = s.select(keep, lo_n, lo[g]);
            hi[g] = s.select(keep, hi_n, hi[g]);
            going[g] = go;
        }
    }
}

/// The finish of the queued points at positions `base + l` for the lanes l of `m`:
/// `Sorted::closest_from_root` and `SortedPlacement::signed_from_closest` a register at
/// a time. Returns the signed distances and the first-octant closest points.
///
/// # Safety
/// The queue holds the points' roots and coordinates.
#[inline(always)]
unsafe fn finish<S: Lanes<E>, E: Precision>(
    s: S,
    c: &Shape<E>,
    q: &Queue<E>,
    base: usize,
    m: S::M,
) -> (S::V, [S::V; 3]) {
    let one = s.splat(E::ONE);
    let u = s.load_where(q.roots.add(base), m);
    let (t0, t1, t2) = (
        s.add(u, s.splat(c.b[0])),
        s.add(u, s.splat(c.b[1])),
        s.add(u, s.splat(c.b[2])),
    );
    let p01 = s.mul(t0, t1);
    let inv = s.div(one, s.mul(p01, t2));
    let r2 = s.mul(inv, p01);
    let inv = s.mul(inv, t2);
    let r1 = s.mul(inv, t0);
    let r0 = s.mul(inv, t1);
    let a = [
        s.load_where(q.a[0].add(base), m),
        s.load_where(q.a[1].add(base), m),
        s.load_where(q.a[2].add(base), m),
    ];
    let x = [
        s.mul(s.mul(s.splat(c.e[0]), a[0]), r0),
        s.mul(s.mul(s.splat(c.e[1]), a[1]), r1),
        s.mul(s.mul(s.splat(c.e[2]), a[2]), r2),
    ];
    let ys = [
        s.load_where(q.ys[0].add(base), m),
        s.load_where(q.ys[1].add(base), m),
        s.load_where(q.ys[2].add(base), m),
    ];
    let dist = s.sqrt(s.add(
        s.add(sq(s, s.sub(ys[0], x[0])), sq(s, s.sub(ys[1], x[1]))),
        sq(s, s.sub(ys[2], x[2])),
    ));
    let level = s.add(
        s.add(
            s.mul(sq(s, ys[0]), s.splat(c.inv_e2[0])),
            s.mul(sq(s, ys[1]), s.splat(c.inv_e2[1])),
        ),
        s.mul(sq(s, ys[2]), s.splat(c.inv_e2[2])),
    );
    // Negative inside: the sign bit flipped (as the scalar `-d` does).
    (s.negate_where(s.lt(level, one), dist), x)
}

/// The set bits of `words`, ascending.
fn set_bits(words: &[u64]) -> impl Iterator<Item = usize> + '_ {
    words.iter().enumerate().flat_map(|(w, &bits)| {
        let mut bits = bits;
        std::iter::from_fn(move || {
            (bits != 0).then(|| {
                let i = 64 * w + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                i
            })
        })
    })
}

/// `d[i]` = the signed distance to `e` of the local point `(y0[i], y1[i], y2[i])` (from
/// [`SortedPlacement::local`]), and with `NORMALS` `normal[c][i]` = the camera-frame
/// outward unit normal at its closest point: what
/// [`SortedPlacement::signed_distance_local`] and `normal_at` give, bit for bit, for
/// every `i < y[0].len()` (≤ [`BLOCK`]; the three inputs equally long). `d` and each
/// `normal[c]` must be valid for writing that many values (they may be uninitialised:
/// they are only written).
pub struct DistancesF64<'a, const NORMALS: bool> {
    pub e: &'a SortedPlacement,
    pub y: [&'a [f64]; 3],
    pub d: *mut f64,
    pub normal: [*mut f64; 3],
}

impl<const NORMALS: bool> WithSimd for DistancesF64<'_, NORMALS> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, s: S) {
        distances_f64(s, self)
    }
}

/// [`DistancesF64`] with the instruction set `s`.
#[inline(always)]
fn distances_f64<S: Lanes<f64>, const NORMALS: bool>(s: S, job: DistancesF64<'_, NORMALS>) {
    let DistancesF64 { e, y, d, normal } = job;
    let n = y[0].len();
    assert!(n <= BLOCK && y.iter().all(|c| c.len() == n));
    let c = Shape::<f64>::new(e);
    let mut storage = QueueStorage::<f64>::new();
    let mut q = storage.queue();
    // SAFETY: every load reads the first `count` of the block's points, every store
    // writes inside the queue's rows or the outputs' first `n` values, and the queue
    // is filled before it is streamed and finished.
    unsafe {
        set_up(s, &c, (&LocalPoints { y }, n), None, &mut q);
        stream(s, &c, &q);
        for base in (0..n).step_by(S::LANES) {
            let count = (n - base).min(S::LANES);
            let m = s.mask(first_lanes(count));
            let (signed, x) = finish(s, &c, &q, base, m);
            s.store_where(d.add(base), m, signed);
            if NORMALS {
                // g_k = copysign(x_k, y_k) / e_k², normalised, turned to the
                // camera frame.
                let g = [
                    s.mul(
                        s.or_sign(x[0], s.load_where(y[0].as_ptr().add(base), m)),
                        s.splat(c.inv_e2[0]),
                    ),
                    s.mul(
                        s.or_sign(x[1], s.load_where(y[1].as_ptr().add(base), m)),
                        s.splat(c.inv_e2[1]),
                    ),
                    s.mul(
                        s.or_sign(x[2], s.load_where(y[2].as_ptr().add(base), m)),
                        s.splat(c.inv_e2[2]),
                    ),
                ];
                let inv = s.div(
                    s.splat(1.0),
                    s.sqrt(s.add(s.add(sq(s, g[0]), sq(s, g[1])), sq(s, g[2]))),
                );
                let a = &e.axes;
                for (col, out) in normal.iter().enumerate() {
                    let v = s.add(
                        s.add(
                            s.mul(g[0], s.splat(a[0][col])),
                            s.mul(g[1], s.splat(a[1][col])),
                        ),
                        s.mul(g[2], s.splat(a[2][col])),
                    );
                    s.store_where(out.add(base), m, s.mul(v, inv));
                }
            }
        }
        for i in set_bits(&q.planar) {
            let yi = [y[0][i], y[1][i], y[2][i]];
            let ys = yi.map(f64::abs);
            let x = closest_sorted(&e.sorted, ys);
            *d.add(i) = e.signed_from_closest(&ys, &x);
            if NORMALS {
                for (out, v) in normal.iter().zip(e.normal_at(&yi, &x)) {
                    *out.add(i) = v;
                }
            }
        }
    }
}

/// `out[i]` = the signed distance to `e` of the camera-frame point `(p0[i], p1[i],
/// p2[i])`, for every `i < out.len()` (≤ [`BLOCK`]; the inputs at least as long), solved
/// in single precision (see the module docs). With a `cap`, a point whose distance
/// lower bound ([`SortedPlacement::distance_lower_bound`], here in `f32`) reaches it
/// gets that bound and skips the solve; the others are queued and get the same value as
/// without a cap.
pub struct DistancesF32<'a> {
    pub e: &'a SortedPlacement,
    pub p: [&'a [f32]; 3],
    pub cap: Option<f32>,
    pub out: &'a mut [f32],
}

impl WithSimd for DistancesF32<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, s: S) {
        distances_f32(s, self)
    }
}

/// [`DistancesF32`] with the instruction set `s`.
#[inline(always)]
fn distances_f32<S: Lanes<f32>>(s: S, job: DistancesF32<'_>) {
    let DistancesF32 { e, p, cap, out } = job;
    let n = out.len();
    assert!(n <= BLOCK && p.iter().all(|c| c.len() >= n));
    let c = Shape::<f32>::new(e);
    let narrow = |v: [f64; 3]| v.map(|x| x as f32);
    let (axes, centre) = (e.axes.map(narrow), narrow(e.centre));
    let mut storage = QueueStorage::<f32>::new();
    let mut q = storage.queue();
    // SAFETY: as for `DistancesF64`; with a cap the finish writes through the
    // queued points' indices, each below `n`.
    unsafe {
        let points = CameraPoints { p, axes, centre };
        let out_ptr = out.as_mut_ptr();
        set_up(s, &c, (&points, n), cap.map(|c| (c, out_ptr)), &mut q);
        stream(s, &c, &q);
        for base in (0..q.len).step_by(S::LANES) {
            let count = (q.len - base).min(S::LANES);
            let m = s.mask(first_lanes(count));
            let (signed, _) = finish(s, &c, &q, base, m);
            if cap.is_none() {
                // Every point queued: queue position = point index.
                s.store_where(out_ptr.add(base), m, signed);
            } else {
                s.scatter_indexed(out_ptr, q.index.add(base), count, signed);
            }
        }
        for j in set_bits(&q.planar) {
            let i = if cap.is_none() {
                j
            } else {
                *q.index.add(j) as usize
            };
            let pi = [p[0][i] as f64, p[1][i] as f64, p[2][i] as f64];
            *out_ptr.add(i) = e.signed_distance(&pi) as f32;
        }
    }
}
