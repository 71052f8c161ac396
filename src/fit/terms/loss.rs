//! The loss of a point's residual and the per-point cost shared by the E-step's unary
//! terms and the M-step.

/// Robust loss of the residuals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Loss {
    /// ρ(r) = r²/2.
    Squared,
    /// Quadratic up to `delta` (m), linear beyond.
    Huber(f64),
    /// ρ(r) = δ²/2 · ln(1 + r²/δ²).
    Cauchy(f64),
}

impl Loss {
    /// ρ(r).
    #[inline]
    pub fn rho(self, r: f64) -> f64 {
        match self {
            Loss::Squared => 0.5 * r * r,
            Loss::Huber(d) => {
                let a = r.abs();
                if a <= d {
                    0.5 * r * r
                } else {
                    d * (a - 0.5 * d)
                }
            }
            Loss::Cauchy(d) => 0.5 * d * d * (r * r / (d * d)).ln_1p(),
        }
    }

    /// The residual r ≥ 0 with ρ(r) = `v` (≥ 0): ρ's inverse on r ≥ 0, where it
    /// increases.
    #[inline]
    pub fn rho_inverse(self, v: f64) -> f64 {
        match self {
            Loss::Squared => (2.0 * v).sqrt(),
            Loss::Huber(d) => {
                if v <= 0.5 * d * d {
                    (2.0 * v).sqrt()
                } else {
                    v / d + 0.5 * d
                }
            }
            Loss::Cauchy(d) => d * (2.0 * v / (d * d)).exp_m1().sqrt(),
        }
    }

    /// IRLS weight ρ'(r)/r.
    #[inline]
    pub fn weight(self, r: f64) -> f64 {
        match self {
            Loss::Squared => 1.0,
            Loss::Huber(d) => {
                let a = r.abs();
                if a <= d {
                    1.0
                } else {
                    d / a
                }
            }
            Loss::Cauchy(d) => 1.0 / (1.0 + r * r / (d * d)),
        }
    }
}

/// Per-point cost settings shared by the E-step unary and the M-step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointCost {
    /// Residual scale σ (m): cost = ρ(r)/σ².
    pub sigma: f64,
    pub loss: Loss,
    /// Residuals beyond this (m) cost the constant ρ(T)/σ².
    pub truncation: f64,
}

impl PointCost {
    /// Cost of residual `r`.
    #[inline]
    pub fn cost(&self, r: f64) -> f64 {
        self.loss.rho(r.abs().min(self.truncation)) / (self.sigma * self.sigma)
    }

    /// The largest residual whose cost is at most `c` (from ρ's inverse, so within a
    /// rounding): infinite when even the cap is at most `c`.
    #[inline]
    pub fn residual_within(&self, c: f64) -> f64 {
        if c >= self.cap() {
            f64::INFINITY
        } else {
            self.loss.rho_inverse(c.max(0.0) * self.sigma * self.sigma)
        }
    }

    /// The constant cost of a truncated residual.
    #[inline]
    pub fn cap(&self) -> f64 {
        self.loss.rho(self.truncation) / (self.sigma * self.sigma)
    }

    /// (cost, IRLS weight / σ²) of residual `r`; the weight is 0 beyond the truncation.
    #[inline]
    pub(super) fn cost_and_weight(&self, r: f64) -> (f64, f64) {
        let s2 = self.sigma * self.sigma;
        if r.abs() > self.truncation {
            (self.cap(), 0.0)
        } else {
            (self.loss.rho(r) / s2, self.loss.weight(r) / s2)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ρ's inverse on r ≥ 0 for every loss, and the largest residual within a cost:
    /// its cost is the given one (below the cap), infinite at and above the cap.
    #[test]
    fn rho_inverse_and_residual_within() {
        for loss in [Loss::Squared, Loss::Huber(0.03), Loss::Cauchy(0.05)] {
            for k in 0..200 {
                let r = 0.002 * k as f64;
                let back = loss.rho_inverse(loss.rho(r));
                assert!(
                    (back - r).abs() <= 1e-12 * (1.0 + r),
                    "{loss:?}: {r} -> {back}"
                );
            }
            let pc = PointCost {
                sigma: 0.02,
                loss,
                truncation: 0.2,
            };
            for k in 0..100 {
                let c = pc.cap() * k as f64 / 100.0;
                let r = pc.residual_within(c);
                assert!(r < pc.truncation);
                assert!((pc.cost(r) - c).abs() <= 1e-12 * (1.0 + c), "{loss:?}: {c}");
            }
            assert_eq!(pc.residual_within(pc.cap()), f64::INFINITY);
            assert_eq!(pc.residual_within(f64::INFINITY), f64::INFINITY);
        }
    }
}
