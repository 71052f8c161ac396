//! `Candidate`: a template matched to a depth image, placed at the observed body.

use super::super::convert::to_numpy;
use crate::body::{NUM_JOINTS, NUM_PARAMS};
use crate::templates::{template_code, Candidate, ARM_POSE_NAMES, LEG_POSE_NAMES, VIEW_NAMES};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

/// A template matched to a depth image, placed at the observed body.
#[pyclass(name = "Candidate", module = "depthpose._core", frozen)]
pub struct PyCandidate {
    pub(super) inner: Candidate,
}

#[pymethods]
impl PyCandidate {
    #[getter]
    fn index(&self) -> usize {
        self.inner.index
    }

    #[getter]
    fn view(&self) -> usize {
        self.inner.view
    }

    #[getter]
    fn pose<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        to_numpy(py, self.inner.pose.to_vec(), &[NUM_PARAMS])
    }

    #[getter]
    fn joints<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let v = self.inner.joints.iter().flatten().copied().collect();
        to_numpy(py, v, &[NUM_JOINTS, 3])
    }

    #[getter]
    fn cost(&self) -> f64 {
        self.inner.cost
    }

    #[getter]
    fn prune_cost(&self) -> f64 {
        self.inner.prune_cost
    }

    #[getter]
    fn scale(&self) -> f64 {
        self.inner.scale
    }

    /// (right arm, left arm, right leg, left leg, view) names of the template.
    #[getter]
    fn code(
        &self,
    ) -> (
        &'static str,
        &'static str,
        &'static str,
        &'static str,
        &'static str,
    ) {
        let ([ra, la, rl, ll], view) = template_code(self.inner.index);
        (
            ARM_POSE_NAMES[ra],
            ARM_POSE_NAMES[la],
            LEG_POSE_NAMES[rl],
            LEG_POSE_NAMES[ll],
            VIEW_NAMES[view],
        )
    }

    fn __repr__(&self) -> String {
        let c = &self.inner;
        format!(
            "Candidate(index={}, view={}, cost={:.4}, prune_cost={:.4}, scale={:.3})",
            c.index, c.view, c.cost, c.prune_cost, c.scale
        )
    }
}
