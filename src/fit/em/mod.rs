//! Hard EM: CRF body-part labelling (E-step) alternating with Levenberg–Marquardt on the
//! labelled points (M-step).
//!
//! Energy (paper eqs. 6–9), over points i with labels V_i ∈ {0..15 segments, outlier}:
//!
//! E(Θ, V) = Σ_i U_i(V_i) + Σ_{(i,j) ∈ graph} w_ij · [V_i ≠ V_j]
//!
//! - U_i(k) = ρ(min(|d_ik|, T))/σ² with d_ik the signed distance of point i to the
//!   ellipsoid of segment k at pose Θ (ρ(r) = r²/2 by default: eq. 6), truncated at
//!   T = `truncation_factor`·τ; U_i(outlier) = ρ(τ)/σ², a constant, so leftover
//!   background, flying pixels and noise farther than τ from every part cost no more
//!   than that and do not drag the fit.
//! - w_ij = K + c·exp(−g_ij²/2σ_c²)·(d̄/d_ij) (generalised Potts, eq. 8, plus the
//!   depth-contrast term, eq. 9): g = depth difference, d_ij = 3-D edge length, d̄ the
//!   mean edge length of the frame (makes the ratio unitless). Cutting the labelling
//!   where the depth jumps is cheap; across a smooth surface it costs K + c.
//!
//! The E-step minimises over V by alpha-expansion (Potts is a metric) from the current
//! labels, so it never increases E. The M-step minimises E1 over Θ for fixed labels by
//! LM with the same truncated loss, so it never increases E either (E2 does not depend on
//! Θ). The outlier distance τ starts wide and shrinks geometrically to its final value
//! (a fixed tight cut-off strands limbs that start far away); a smaller τ lowers every
//! unary term, so the energy trace stays non-increasing across the schedule too. The
//! full energy is evaluated after every step and a step that would raise it is undone.

mod config;
mod estep;
mod labels;
mod mstep;
mod result;
mod run;
#[cfg(test)]
mod tests;
mod unary;

pub use config::{EmConfig, DEFAULT_FREE_SPACE_WEIGHT};
pub use estep::{crf_energy, edge_weights, label_points};
pub use labels::{PointLabels, NUM_LABELS, OUTLIER};
pub use result::{EmResult, EmResume, EmTermination};
pub use run::{hard_em, hard_em_from, EmOptions};
pub use unary::{settle_unary, unary_costs, unary_costs_for_labels, HeldLabels, UnaryAt};
