//! The Gauss–Newton system of the pose: the objective interface the solvers use
//! ([`PoseObjective`]), and the per-segment moments the data and free-space terms
//! assemble it from.

use crate::body::residuals::{cross, PoseGeometry, MAX_SEGMENT_DOFS};
use crate::body::{Pose, NUM_PARAMS};

/// Parameters per pose.
pub const N: usize = NUM_PARAMS;
/// Entries of the N×N normal matrix (row-major).
pub const NN: usize = N * N;

/// A least-squares objective in the pose.
pub trait PoseObjective {
    /// The cost at `pose`.
    fn cost(&mut self, pose: &Pose) -> f64;
    /// The Gauss–Newton system at `pose`: `h` = JᵀWJ (N×N row-major, both triangles),
    /// `g` = JᵀWr (the cost's gradient); returns the cost. Both outputs are overwritten.
    fn normal_equations(&mut self, pose: &Pose, h: &mut [f64; NN], g: &mut [f64; N]) -> f64;
}

/// Entries of a symmetric 6×6 matrix's upper triangle.
pub(crate) const SYM6: usize = 21;

/// Position of entry (a, b) of a symmetric 6×6 matrix in its packed upper triangle
/// (row by row: (0,0) … (0,5), (1,1) … (5,5)).
#[inline]
fn sym6_index(a: usize, b: usize) -> usize {
    let (a, b) = (a.min(b), a.max(b));
    a * (11 - a) / 2 + b
}

/// Adds segment `k`'s share of the normal equations, given its weighted sums over
/// points or samples with rows q = (n, p × n) (see [`PoseGeometry::dof_basis`]): the
/// packed upper triangle `qq` of Σ w q qᵀ and `qr` = Σ w r q. With B the segment's
/// parameter basis, JᵀWJ += Bᵀ(QᵀWQ)B (into the upper triangle of `h`, in parameter
/// order; see [`mirror_upper`]) and JᵀWr += Bᵀ(QᵀWr).
pub(crate) fn add_segment_moments(
    geo: &PoseGeometry,
    k: usize,
    qq: &[f64; SYM6],
    qr: &[f64; 6],
    h: &mut [f64; NN],
    g: &mut [f64; N],
) {
    let s: [[f64; 6]; 6] = std::array::from_fn(|a| std::array::from_fn(|b| qq[sym6_index(a, b)]));
    let dofs = geo.segment_dofs(k);
    let mut basis = [[0.0; 6]; MAX_SEGMENT_DOFS];
    let mut s_basis = [[0.0; 6]; MAX_SEGMENT_DOFS];
    for (j, &dof) in dofs.iter().enumerate() {
        basis[j] = geo.dof_basis(dof);
        for a in 0..6 {
            s_basis[j][a] = (0..6).map(|b| s[a][b] * basis[j][b]).sum();
        }
    }
    for (i, &di) in dofs.iter().enumerate() {
        g[di] += (0..6).map(|a| basis[i][a] * qr[a]).sum::<f64>();
        // Upper triangle in dof order (`dofs` ascends).
        for (j, &dj) in dofs.iter().enumerate().skip(i) {
            h[di * N + dj] += (0..6).map(|a| basis[i][a] * s_basis[j][a]).sum::<f64>();
        }
    }
}

/// Copies the upper triangle of `h` into its lower one.
pub(crate) fn mirror_upper(h: &mut [f64; NN]) {
    for i in 0..N {
        for j in 0..i {
            h[i * N + j] = h[j * N + i];
        }
    }
}

/// Adds weighted row q = (n, p × n) with residual `r` and weight `w` to the packed sums
/// `qq` (upper triangle of Σ w q qᵀ) and `qr` (Σ w r q).
#[inline(always)]
pub(crate) fn accumulate_row(
    p: &[f64; 3],
    n: &[f64; 3],
    r: f64,
    w: f64,
    qq: &mut [f64; SYM6],
    qr: &mut [f64; 6],
) {
    let m = cross(p, n);
    let q = [n[0], n[1], n[2], m[0], m[1], m[2]];
    let mut e = 0;
    for a in 0..6 {
        let wq = w * q[a];
        qr[a] += wq * r;
        for &qb in &q[a..] {
            qq[e] += wq * qb;
            e += 1;
        }
    }
}
