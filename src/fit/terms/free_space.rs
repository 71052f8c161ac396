//! The free-space term of the M-step: the model's surface must not be seen in front of
//! the observed depth.
//!
//! A depth camera sees through free space: where pixel (u, v) reads depth D, nothing lies
//! on its ray nearer than D. A segment hidden by another part (an arm behind the torso)
//! gets no points of its own, and the data term alone lets it sit on the visible points
//! of the part in front, or drift there as the E-step hands it some of them. This term
//! penalises model surface in front of the observed surface: fixed samples on each
//! ellipsoid (the same body points at every pose) are projected into the depth image,
//! and a sample at depth z over a pixel reading D has the residual
//!
//! r = D − margin − z  when positive (in front of the reading by more than the margin), else 0,
//!
//! with the cost λ·min(r, T)²/(2σ²): quadratic up to the truncation T, constant beyond,
//! so that a sample far in front (over a background pixel, where the fix is to move
//! sideways into the silhouette, not backwards) adds a constant, not a pull. Pixels
//! without a reading (0 or NaN) and samples outside the image add nothing: their space
//! is unknown. (Comparing with the nearest reading within 1 or 2 pixels instead, which
//! spares a sample on a segment's outline that projects onto the part behind it, fitted
//! the shared sequences worse: docs/design.md.) The background must be in the depth image
//! for the silhouette to count (the fit's mask selects the person's points; the term
//! reads every pixel).
//!
//! The residual's gradient with respect to the sample's camera-frame position is taken
//! as (0, 0, −1): the reading D is held constant over the step (it is piecewise constant
//! in the pixel). The Gauss–Newton step is then approximate across depth edges, but the
//! LM cost test uses the exact cost, so the M-step still never increases it; the EM
//! energy counts this term, and the E-step does not change it, so the EM energy still
//! never increases either.

use crate::body::residuals::PoseGeometry;
use crate::body::{BodyModel, Pose, NUM_SEGMENTS};
use crate::camera::Camera;
use crate::fit::system::{accumulate_row, add_segment_moments, mirror_upper, N, NN, SYM6};
use std::sync::Mutex;

/// Surface samples per segment.
pub const SAMPLES_PER_SEGMENT: usize = 64;

/// Settings of the free-space term (see the module's comment).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FreeSpaceCost {
    /// λ: the weight of one sample relative to one data point (0 turns the term off).
    pub weight: f64,
    /// How far (m) a sample may lie in front of the reading before it costs (the depth
    /// noise).
    pub margin: f64,
    /// Residual scale σ (m), the data term's.
    pub sigma: f64,
    /// Truncation T (m) of the residual.
    pub truncation: f64,
}

/// Unit directions of the samples: a Fibonacci sphere (near-uniform and deterministic).
fn sample_directions() -> [[f64; 3]; SAMPLES_PER_SEGMENT] {
    let golden_angle = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    std::array::from_fn(|i| {
        let z = 1.0 - (2 * i + 1) as f64 / SAMPLES_PER_SEGMENT as f64;
        let rho = (1.0 - z * z).max(0.0).sqrt();
        let phi = golden_angle * i as f64;
        [rho * phi.cos(), rho * phi.sin(), z]
    })
}

/// The depth image a fit's free-space term reads (every pixel's reading, background
/// included; H×W metres, row-major), its camera, and the factor applied to the term's
/// weight (1 / stride² for a sub-sampled fit, whose data term has that many fewer
/// points).
#[derive(Debug, Clone, Copy)]
pub struct FreeSpaceImage<'a> {
    pub depth: &'a [f32],
    pub camera: &'a Camera,
    pub weight_scale: f64,
}

/// The free-space term over one depth image (H×W metres, row-major, the camera's size).
pub struct FreeSpaceTerm<'a> {
    model: &'a BodyModel,
    depth: &'a [f32],
    camera: Camera,
    cost: FreeSpaceCost,
    directions: [[f64; 3]; SAMPLES_PER_SEGMENT],
    /// The last pose whose cost was computed, and that cost: LM asks for the cost of a
    /// trial pose and then, if it accepts it, for the system there; the EM asks again.
    /// (A lock, not a cell, so that the term can be evaluated beside the data term.)
    last: Mutex<Option<(Pose, f64)>>,
}

/// The term's share of the Gauss–Newton system at one pose before it is added (see
/// [`FreeSpaceTerm::system`]).
pub struct FreeSpaceSystem {
    geo: PoseGeometry,
    /// Per segment with a weighted sample: the moments Σ w q qᵀ (packed) and Σ w r q.
    sums: [Option<([f64; SYM6], [f64; 6])>; NUM_SEGMENTS],
    cost: f64,
}

/// ∂r/∂p of a sample in free space is (0, 0, −1); the moment rows use n = −∂r/∂p.
const TOWARDS_CAMERA: [f64; 3] = [0.0, 0.0, 1.0];

impl<'a> FreeSpaceTerm<'a> {
    /// `depth` must hold `camera.width × camera.height` readings (checked by the fit,
    /// which builds its cloud from the same image).
    pub fn new(
        model: &'a BodyModel,
        depth: &'a [f32],
        camera: &Camera,
        cost: FreeSpaceCost,
    ) -> Self {
        debug_assert_eq!(depth.len(), camera.width * camera.height);
        FreeSpaceTerm {
            model,
            depth,
            camera: *camera,
            cost,
            directions: sample_directions(),
            last: Mutex::new(None),
        }
    }

    /// Whether the term can contribute at all.
    pub fn active(&self) -> bool {
        self.cost.weight > 0.0
    }

    /// The residual of a camera-frame point: how far it lies in front of the reading
    /// of its pixel, beyond the margin; 0 if it does not or the pixel has no reading.
    #[inline]
    pub fn residual(&self, p: &[f64; 3]) -> f64 {
        let z = p[2];
        if z <= 0.0 {
            return 0.0;
        }
        let c = &self.camera;
        let inv_z = 1.0 / z;
        // The nearest pixel: ⌊x + ½⌋, by truncation once x + ½ is known to be ≥ 0 (an
        // inline conversion, where `round` is a library call on baseline x86-64).
        let u = c.fx * p[0] * inv_z + c.cx + 0.5;
        let v = c.fy * p[1] * inv_z + c.cy + 0.5;
        // Also false for NaN.
        if !(u >= 0.0 && v >= 0.0 && u < c.width as f64 && v < c.height as f64) {
            return 0.0;
        }
        let d = self.depth[v as usize * c.width + u as usize];
        if !(d.is_finite() && d > 0.0) {
            return 0.0;
        }
        (d as f64 - self.cost.margin - z).max(0.0)
    }

    /// Cost and IRLS weight of residual `r` ≥ 0.
    #[inline]
    fn cost_and_weight(&self, r: f64) -> (f64, f64) {
        let fs = &self.cost;
        let s2 = fs.sigma * fs.sigma;
        if r <= 0.0 {
            (0.0, 0.0)
        } else if r > fs.truncation {
            (0.5 * fs.weight * fs.truncation * fs.truncation / s2, 0.0)
        } else {
            (0.5 * fs.weight * r * r / s2, fs.weight / s2)
        }
    }

    /// The term's cost at the pose of `geo`.
    pub fn cost_at(&self, geo: &PoseGeometry) -> f64 {
        if !self.active() {
            return 0.0;
        }
        let mut total = 0.0;
        for e in &geo.segments {
            for u in &self.directions {
                total += self.cost_and_weight(self.residual(&e.surface_point(u))).0;
            }
        }
        total
    }

    /// The term's cost at `pose`.
    pub fn cost(&self, pose: &Pose) -> f64 {
        if !self.active() {
            return 0.0;
        }
        if let Some((p, c)) = self.last() {
            if p == *pose {
                return c;
            }
        }
        let c = self.cost_at(&PoseGeometry::new(self.model, pose));
        self.remember(pose, c);
        c
    }

    fn last(&self) -> Option<(Pose, f64)> {
        *self.last.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn remember(&self, pose: &Pose, cost: f64) {
        *self.last.lock().unwrap_or_else(|e| e.into_inner()) = Some((*pose, cost));
    }

    /// Adds the term's Gauss–Newton system at `pose` to `h` (both triangles) and `g`;
    /// returns its cost.
    pub fn add_to(&self, pose: &Pose, h: &mut [f64; NN], g: &mut [f64; N]) -> f64 {
        if !self.active() {
            return 0.0;
        }
        let system = self.system(pose);
        self.add_system(pose, &system, h, g)
    }

    /// The part of [`Self::add_to`] that reads the depth image (the samples' residuals
    /// and moments), which the M-step runs beside the data term's normal equations.
    pub fn system(&self, pose: &Pose) -> FreeSpaceSystem {
        let geo = PoseGeometry::new(self.model, pose);
        let mut sums = [None; NUM_SEGMENTS];
        let mut cost = 0.0;
        if self.active() {
            for (e, sum) in geo.segments.iter().zip(&mut sums) {
                let (mut qq, mut qr) = ([0.0; SYM6], [0.0; 6]);
                let mut any = false;
                for u in &self.directions {
                    let p = e.surface_point(u);
                    let r = self.residual(&p);
                    let (c, w) = self.cost_and_weight(r);
                    cost += c;
                    if w > 0.0 {
                        accumulate_row(&p, &TOWARDS_CAMERA, r, w, &mut qq, &mut qr);
                        any = true;
                    }
                }
                if any {
                    *sum = Some((qq, qr));
                }
            }
        }
        FreeSpaceSystem { geo, sums, cost }
    }

    /// Adds `system` (from [`Self::system`] at `pose`) to `h` (both triangles) and `g`
    /// as [`Self::add_to`] does; returns its cost.
    pub fn add_system(
        &self,
        pose: &Pose,
        system: &FreeSpaceSystem,
        h: &mut [f64; NN],
        g: &mut [f64; N],
    ) -> f64 {
        if !self.active() {
            return 0.0;
        }
        let mut hs = [0.0; NN];
        for (k, sum) in system.sums.iter().enumerate() {
            if let Some((qq, qr)) = sum {
                add_segment_moments(&system.geo, k, qq, qr, &mut hs, g);
            }
        }
        mirror_upper(&mut hs);
        for (o, v) in h.iter_mut().zip(&hs) {
            *o += v;
        }
        self.remember(pose, system.cost);
        system.cost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::kinematics::tests::pose_for_tests;

    fn camera() -> Camera {
        Camera {
            fx: 285.7,
            fy: 285.7,
            cx: 160.0,
            cy: 120.0,
            width: 320,
            height: 240,
        }
    }

    fn term<'a>(model: &'a BodyModel, depth: &'a [f32], weight: f64) -> FreeSpaceTerm<'a> {
        FreeSpaceTerm::new(
            model,
            depth,
            &camera(),
            FreeSpaceCost {
                weight,
                margin: 0.03,
                sigma: 0.02,
                truncation: 10.0,
            },
        )
    }

    #[test]
    fn samples_lie_on_the_ellipsoids() {
        let model = BodyModel::default();
        let geo = PoseGeometry::new(&model, &pose_for_tests(3));
        for e in &geo.segments {
            for u in &sample_directions() {
                let p = e.surface_point(u);
                let l = e.local(&p);
                // On the surface: Σ (l_k / e_k)² = 1 with the sorted half-axes.
                let (hi, lo) = (e.max_radius(), e.min_radius());
                assert!(l.iter().all(|v| v.abs() <= hi * (1.0 + 1e-12)));
                assert!(l.iter().map(|v| v * v).sum::<f64>() >= lo * lo * (1.0 - 1e-12));
            }
        }
    }

    /// Behind a wall of readings nearer than the body, every sample is in free space
    /// with r = D − margin − z < T, smooth in the pose: the gradient of the normal
    /// equations must match finite differences of the cost, and H must be JᵀWJ's.
    #[test]
    fn gradient_matches_finite_differences() {
        let model = BodyModel::default();
        let cam = camera();
        let pose = pose_for_tests(5);
        let depth = vec![9.0f32; cam.width * cam.height];
        let t = term(&model, &depth, 0.7);
        let (mut h, mut g) = ([0.0; NN], [0.0; N]);
        let c = t.add_to(&pose, &mut h, &mut g);
        assert!((c - t.cost(&pose)).abs() <= 1e-9 * c.abs());
        assert!(c > 0.0);
        let step = 1e-6;
        for i in 0..N {
            let mut dp = [0.0; N];
            dp[i] = step;
            let plus = crate::fit::lm::pose_after_step(&pose, &dp);
            dp[i] = -step;
            let minus = crate::fit::lm::pose_after_step(&pose, &dp);
            let fd = (t.cost(&plus) - t.cost(&minus)) / (2.0 * step);
            assert!(
                (fd - g[i]).abs() <= 1e-4 * g[i].abs().max(1.0),
                "parameter {i}: finite difference {fd}, gradient {}",
                g[i]
            );
            // Gauss–Newton: H's diagonal is Σ w (∂r/∂θ)², positive where g moves.
            assert!(h[i * N + i] >= 0.0);
        }
        for i in 0..N {
            for j in 0..N {
                assert_eq!(h[i * N + j], h[j * N + i]);
            }
        }
    }

    /// `WithPrior` evaluates the term beside the data term and adds it after it: its
    /// cost and normal equations equal the terms added one after the other (data, prior,
    /// free space) bit for bit, at a pose where both the data and the free-space term
    /// have weighted residuals.
    #[test]
    fn the_term_beside_the_data_term_adds_up_as_one_after_the_other() {
        use crate::fit::system::PoseObjective;
        use crate::fit::terms::data::PointObjective;
        use crate::fit::terms::{Loss, PointCost};
        use crate::fit::terms::{PosePrior, WithPrior};
        let model = BodyModel::default();
        let cam = camera();
        let pose = pose_for_tests(5);
        let other = pose_for_tests(3);
        // A wall through the body: the front half of the samples in free space.
        let depth = vec![pose[2] as f32; cam.width * cam.height];
        let t = term(&model, &depth, 0.7);
        let joints = model.joints(&pose);
        let points: Vec<[f32; 3]> = (0..3000)
            .map(|i| {
                let j = joints[i % joints.len()];
                let o = 0.01 * (i % 13) as f64;
                [(j.x + o) as f32, (j.y - o) as f32, (j.z + 0.5 * o) as f32]
            })
            .collect();
        let labels: Vec<i32> = (0..points.len())
            .map(|i| (i % NUM_SEGMENTS) as i32)
            .collect();
        let pc = PointCost {
            sigma: 0.02,
            loss: Loss::Huber(0.03),
            truncation: 0.2,
        };
        let prior = PosePrior::uniform(other, 30.0, 3.0);
        let mut data = PointObjective::new(&model, &points, &labels, pc);
        let (mut h1, mut g1) = ([0.0; NN], [0.0; N]);
        let c1 = data.normal_equations(&pose, &mut h1, &mut g1)
            + prior.add_to(&pose, &mut h1, &mut g1)
            + t.add_to(&pose, &mut h1, &mut g1);
        let cost1 = data.cost(&other) + prior.cost(&other) + t.cost(&other);
        assert!(t.cost(&pose) > 0.0 && g1.iter().any(|&v| v != 0.0));

        let t2 = term(&model, &depth, 0.7);
        let mut data2 = PointObjective::new(&model, &points, &labels, pc);
        let mut both = WithPrior {
            objective: &mut data2,
            prior: Some(&prior),
            free_space: Some(&t2),
        };
        let (mut h2, mut g2) = ([0.0; NN], [0.0; N]);
        assert_eq!(both.normal_equations(&pose, &mut h2, &mut g2), c1);
        assert_eq!((h2, g2), (h1, g1));
        assert_eq!(both.cost(&other), cost1);
    }

    /// The outcome the term exists for: model surface seen in front of the observed
    /// depth, with no data points to hold it, is moved behind the readings. A wall of
    /// readings through the middle of the body (the front half in free space); LM on
    /// the free-space term alone (an objective without points) must reach zero cost,
    /// by moving the body back, never raising the cost on the way.
    #[test]
    fn surface_in_front_of_the_readings_is_pushed_behind_them() {
        use crate::fit::lm::{LevenbergMarquardt, LmConfig};
        use crate::fit::terms::data::PointObjective;
        use crate::fit::terms::WithPrior;
        use crate::fit::terms::{Loss, PointCost};
        let model = BodyModel::default();
        let cam = camera();
        let mut pose = BodyModel::neutral_pose();
        pose[2] = 2.5;
        let depth = vec![2.5f32; cam.width * cam.height];
        let mut t = term(&model, &depth, 1.0);
        t.cost.truncation = 1.0;
        let start_cost = t.cost(&pose);
        assert!(start_cost > 0.0);
        let mut no_points = PointObjective::new(
            &model,
            &[],
            &[],
            PointCost {
                sigma: 0.02,
                loss: Loss::Squared,
                truncation: 0.2,
            },
        );
        let mut objective = WithPrior {
            objective: &mut no_points,
            prior: None,
            free_space: Some(&t),
        };
        let mut lm = LevenbergMarquardt::new(LmConfig {
            max_iterations: 100,
            // Stop at zero cost, not at a step of 1e-7 (the default), which can leave
            // a sample a micrometre or two in front depending on the path.
            step_tolerance: 1e-10,
            ..LmConfig::default()
        })
        .unwrap();
        let start = pose;
        let report = lm.minimize(&mut objective, &mut pose);
        assert!(report.termination.converged(), "{report:?}");
        assert!(report.cost <= 1e-9 * report.initial_cost, "{report:?}");
        assert_eq!(report.cost, t.cost(&pose));
        // Every sample now lies behind the wall, less the margin (to a micrometre).
        let geo = PoseGeometry::new(&model, &pose);
        for e in &geo.segments {
            for u in &t.directions {
                assert!(e.surface_point(u)[2] >= 2.5 - 0.03 - 1e-6);
            }
        }
        assert!(
            pose[2] > start[2] + 0.05,
            "the body moved back: {}",
            pose[2]
        );
    }

    /// No cost when the readings are behind the body or missing, or the weight is 0; a
    /// constant per sample beyond the truncation.
    #[test]
    fn cost_is_zero_behind_readings_and_truncated_far_in_front() {
        let model = BodyModel::default();
        let cam = camera();
        let pose = pose_for_tests(2);
        let n = cam.width * cam.height;
        let far_behind = vec![0.5f32; n];
        assert_eq!(term(&model, &far_behind, 1.0).cost(&pose), 0.0);
        let missing: Vec<f32> = (0..n)
            .map(|i| if i % 2 == 0 { 0.0 } else { f32::NAN })
            .collect();
        assert_eq!(term(&model, &missing, 1.0).cost(&pose), 0.0);
        let wall = vec![50.0f32; n];
        assert_eq!(term(&model, &wall, 0.0).cost(&pose), 0.0);
        let mut t = term(&model, &wall, 2.0);
        t.cost.truncation = 0.1;
        let geo = PoseGeometry::new(&model, &pose);
        let visible = geo
            .segments
            .iter()
            .flat_map(|e| t.directions.iter().map(move |u| e.surface_point(u)))
            .filter(|p| t.residual(p) > 0.0)
            .count();
        assert!(visible > 0);
        let each = 0.5 * 2.0 * 0.1 * 0.1 / (0.02 * 0.02);
        assert!((t.cost(&pose) - visible as f64 * each).abs() <= 1e-9 * t.cost(&pose));
        let (mut h, mut g) = ([0.0; NN], [0.0; N]);
        t.add_to(&pose, &mut h, &mut g);
        assert!(g.iter().all(|&v| v == 0.0) && h.iter().all(|&v| v == 0.0));
    }
}
