//! The batched queries of [`SortedPlacement`]: many points of one ellipsoid through
//! the stream kernel, or without it through the lockstep root-finder.

use super::solve::{closest_sorted, solve_secular_lanes, LANES};
use super::sorted::SortedPlacement;
use super::stream::{self, DistancesF32, DistancesF64, Kernel, BLOCK};
use crate::simd::Arch;

impl SortedPlacement {
    /// Signed distances of camera-frame points in single precision, for callers whose
    /// points and results are f32: `out[i]` for every `i < out.len()`. Where the CPU
    /// has AVX-512 or AVX2 the stream root-finder runs in f32 (the same bits with
    /// either: within ~3e-7 × max(1 m, |d|) of [`Self::signed_distance`]); else in f64,
    /// [`LANES`] points at a time in lockstep.
    ///
    /// With a `cap`, a point whose [`Self::distance_lower_bound`] reaches `cap` gets
    /// that bound instead of its distance (so every value below `cap` is exact, and
    /// each value is the same with or without a cap).
    pub fn signed_distances_camera_soa_f32(
        &self,
        p: [&[f32]; 3],
        cap: Option<f64>,
        out: &mut [f32],
    ) {
        match stream::kernel() {
            Kernel::Stream(arch) => self.streamed_f32(arch, p, cap, out),
            Kernel::Lockstep => self.signed_distances_camera_lockstep_f32(p, cap, out),
        }
    }

    /// [`Self::signed_distances_camera_soa_f32`] through the stream with the instruction
    /// set `arch`, [`BLOCK`] points at a time.
    pub(super) fn streamed_f32(
        &self,
        arch: Arch,
        p: [&[f32]; 3],
        cap: Option<f64>,
        out: &mut [f32],
    ) {
        let cap = cap.map(|c| c as f32);
        for (b, out) in out.chunks_mut(BLOCK).enumerate() {
            let at = b * BLOCK;
            let p = [&p[0][at..], &p[1][at..], &p[2][at..]];
            arch.dispatch(DistancesF32 {
                e: self,
                p,
                cap,
                out,
            });
        }
    }

    /// [`Self::signed_distances_camera_soa_f32`] without the stream: in f64, [`LANES`]
    /// points at a time in lockstep.
    pub(super) fn signed_distances_camera_lockstep_f32(
        &self,
        p: [&[f32]; 3],
        cap: Option<f64>,
        out: &mut [f32],
    ) {
        for (b, o) in out.chunks_mut(BLOCK).enumerate() {
            let at = b * BLOCK;
            let mut near = [(0usize, [0.0f64; 3]); BLOCK];
            let mut m = 0;
            for (i, v) in o.iter_mut().enumerate() {
                let j = at + i;
                let y = self.local(&[p[0][j] as f64, p[1][j] as f64, p[2][j] as f64]);
                match cap.map(|c| (c, self.distance_lower_bound(&y))) {
                    Some((c, lower)) if lower >= c => *v = lower as f32,
                    _ => {
                        near[m] = (i, y);
                        m += 1;
                    }
                }
            }
            self.signed_distances_batched(near[..m].iter().copied(), |i, d| o[i] = d as f32);
        }
    }

    /// Signed distances of many local points (from [`Self::local`]), [`LANES`] at a time
    /// through the lockstep root-finder: `emit(i, d)` receives each `(i, y)` of `items`
    /// with the same value [`Self::signed_distance_local`] gives (points on a coordinate
    /// plane at once, the others when their group of [`LANES`] fills or at the end).
    #[inline]
    pub fn signed_distances_batched(
        &self,
        items: impl Iterator<Item = (usize, [f64; 3])>,
        mut emit: impl FnMut(usize, f64),
    ) {
        if let Kernel::Stream(arch) = stream::kernel() {
            self.streamed::<false>(arch, items, |i, d, _| emit(i, d));
            return;
        }
        self.closest_lockstep(items, |i, _, ys, x| {
            emit(i, self.signed_from_closest(ys, x))
        });
    }

    /// [`Self::signed_distances_batched`] with the normal: `emit(i, d, n)` receives the
    /// signed distance and camera-frame outward unit normal of each local point, the
    /// values [`Self::distance_and_normal`] gives for the camera-frame point.
    #[inline]
    pub fn distances_and_normals_batched(
        &self,
        items: impl Iterator<Item = (usize, [f64; 3])>,
        mut emit: impl FnMut(usize, f64, [f64; 3]),
    ) {
        if let Kernel::Stream(arch) = stream::kernel() {
            self.streamed::<true>(arch, items, emit);
            return;
        }
        self.closest_lockstep(items, |i, y, ys, x| {
            emit(i, self.signed_from_closest(ys, x), self.normal_at(y, x))
        });
    }

    /// The batched queries through the stream with the instruction set `arch`: the
    /// items buffered one coordinate per array, [`BLOCK`] at a time; `emit(i, d, n)`
    /// (`n` only with `NORMALS`, whose kernel computes them; else zeros).
    pub(super) fn streamed<const NORMALS: bool>(
        &self,
        arch: Arch,
        items: impl Iterator<Item = (usize, [f64; 3])>,
        mut emit: impl FnMut(usize, f64, [f64; 3]),
    ) {
        // Left uninitialised (zeroing ~16 KB per call would cost more than a short
        // call's solve); only the entries written are read.
        let mut index = std::mem::MaybeUninit::<[usize; BLOCK]>::uninit();
        let mut columns = std::mem::MaybeUninit::<[[f64; BLOCK]; 7]>::uninit();
        let index = index.as_mut_ptr() as *mut usize;
        let base = columns.as_mut_ptr() as *mut f64;
        // SAFETY: the pointers stay inside the two buffers; a block's first m points
        // are written before slices are made of them, and its results are read only
        // after the kernel wrote them.
        let mut flush = |m: usize| unsafe {
            let col = |k: usize| base.add(k * BLOCK);
            let y = [0, 1, 2].map(|k| std::slice::from_raw_parts(col(k), m));
            arch.dispatch(DistancesF64::<NORMALS> {
                e: self,
                y,
                d: col(3),
                normal: [col(4), col(5), col(6)],
            });
            let d = std::slice::from_raw_parts(col(3), m);
            if NORMALS {
                let n = [4, 5, 6].map(|k| std::slice::from_raw_parts(col(k), m));
                for j in 0..m {
                    emit(*index.add(j), d[j], [n[0][j], n[1][j], n[2][j]]);
                }
            } else {
                for (j, &dj) in d.iter().enumerate() {
                    emit(*index.add(j), dj, [0.0; 3]);
                }
            }
        };
        let mut m = 0;
        for (i, y) in items {
            // SAFETY: m < BLOCK.
            unsafe {
                *index.add(m) = i;
                for (k, &v) in y.iter().enumerate() {
                    *base.add(k * BLOCK + m) = v;
                }
            }
            m += 1;
            if m == BLOCK {
                flush(m);
                m = 0;
            }
        }
        if m > 0 {
            flush(m);
        }
    }

    /// The first-octant closest point `x` of each local point `y` of `items`:
    /// `emit(i, y, |y|, x)`, the values `closest_sorted` gives, through the lockstep
    /// root-finder [`LANES`] points at a time (points on a coordinate plane one by one,
    /// through the special cases). The batched queries' path without a stream kernel.
    #[inline]
    pub(super) fn closest_lockstep(
        &self,
        items: impl Iterator<Item = (usize, [f64; 3])>,
        mut emit: impl FnMut(usize, &[f64; 3], &[f64; 3], &[f64; 3]),
    ) {
        let c = &self.sorted;
        let mut idx = [0usize; LANES];
        let mut yl = [[0.0; 3]; LANES];
        let mut ys = [[0.0; 3]; LANES];
        let mut n = 0;
        for (i, y) in items {
            let a = [y[0].abs(), y[1].abs(), y[2].abs()];
            if a[2] > 0.0 {
                idx[n] = i;
                yl[n] = y;
                ys[n] = a;
                n += 1;
                if n == LANES {
                    let mut sa = [[0.0; 3]; LANES];
                    let mut lo = [0.0; LANES];
                    let mut hi = [0.0; LANES];
                    for l in 0..LANES {
                        (sa[l], lo[l], hi[l]) = c.secular_setup(&ys[l]);
                    }
                    let u = solve_secular_lanes(&sa, &c.b, lo, hi);
                    for l in 0..LANES {
                        let x = c.closest_from_root(&sa[l], u[l]);
                        emit(idx[l], &yl[l], &ys[l], &x);
                    }
                    n = 0;
                }
            } else {
                emit(i, &y, &a, &closest_sorted(c, a));
            }
        }
        for l in 0..n {
            emit(idx[l], &yl[l], &ys[l], &closest_sorted(c, ys[l]));
        }
    }
}
