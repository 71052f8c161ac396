//! Model fitting (paper Section II-D): CRF body-part labelling and Levenberg–Marquardt
//! in a hard EM loop, inverse kinematics from joints, and body-shape calibration.

pub mod em;
pub mod ik;
pub mod lm;
pub mod objective;
