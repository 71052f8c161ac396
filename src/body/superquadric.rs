//! Super-quadric segment surfaces for rendering templates (paper, eq. 1):
//!
//! (x/x0)² + (y/y0)² = (1 + s·z/z0) · (1 − |1 − 2z/z0|^d),   0 ≤ z ≤ z0,
//!
//! a solid of revolution-like shape along z: `s` tapers it (s < 0 narrows the far end)
//! and `d` squares it off (d = 2 with s = 0 is the ellipsoid of half-axes x0, y0,
//! z0/2; larger d approaches a capsule/cylinder). We write |1 − 2z/z0|^d, which equals
//! the paper's (1 − 2z/z0)^d for its even d and stays defined for any d > 1. Each
//! segment's super-quadric spans the same extent along the long axis as its fitting
//! ellipsoid and has the same largest cross-section.

use super::{BodyModel, Pose, NUM_SEGMENTS};
use crate::error::{Error, Result};
use nalgebra::Vector3;

/// Taper `s` and exponent `d` of one segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SuperquadricShape {
    pub taper: f64,
    pub exponent: f64,
}

const fn sq(taper: f64, exponent: f64) -> SuperquadricShape {
    SuperquadricShape { taper, exponent }
}

/// Per segment (label order): limbs taper toward the distal end and are squared off
/// (d = 4), the torso narrows toward the waist, head/hands/feet stay ellipsoidal-ish.
pub const SEGMENT_SUPERQUADRICS: [SuperquadricShape; NUM_SEGMENTS] = [
    sq(0.0, 2.0),   // head
    sq(0.0, 4.0),   // neck
    sq(-0.25, 4.0), // torso (top → waist)
    sq(0.0, 3.0),   // pelvis
    sq(-0.25, 4.0), // r upper arm
    sq(-0.35, 4.0), // r forearm
    sq(0.0, 2.0),   // r hand
    sq(-0.25, 4.0), // l upper arm
    sq(-0.35, 4.0), // l forearm
    sq(0.0, 2.0),   // l hand
    sq(-0.4, 4.0),  // r thigh
    sq(-0.4, 4.0),  // r shin
    sq(0.3, 2.0),   // r foot (heel → toe)
    sq(-0.4, 4.0),  // l thigh
    sq(-0.4, 4.0),  // l shin
    sq(0.3, 2.0),   // l foot
];

/// Tessellation of the meshes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshConfig {
    /// Rings along the long axis (≥ 3).
    pub rings: usize,
    /// Vertices around each ring (≥ 3).
    pub sectors: usize,
}

impl Default for MeshConfig {
    fn default() -> Self {
        MeshConfig {
            rings: 20,
            sectors: 24,
        }
    }
}

/// A triangle mesh: vertices and counter-clockwise (outward) faces.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<[f64; 3]>,
    pub faces: Vec<[u32; 3]>,
}

/// Squared cross-section scale of eq. 1 at w = z/z0.
fn profile(shape: &SuperquadricShape, w: f64) -> f64 {
    ((1.0 + shape.taper * w) * (1.0 - (1.0 - 2.0 * w).abs().powf(shape.exponent))).max(0.0)
}

/// The most rings or sectors a mesh may have (a million vertices per segment; more
/// would be a memory error, not a finer picture).
pub const MAX_MESH_DIVISIONS: usize = 1000;

/// Mesh of eq. 1 in its own frame (z from 0 to z0), scaled so the widest cross-section
/// has half-axes x0, y0. Faces point outward.
pub fn superquadric_mesh(
    x0: f64,
    y0: f64,
    z0: f64,
    shape: &SuperquadricShape,
    cfg: &MeshConfig,
) -> Result<Mesh> {
    for (v, n) in [(x0, "x0"), (y0, "y0"), (z0, "z0")] {
        crate::error::ensure_positive(v, n)?;
    }
    if !(shape.exponent > 1.0 && shape.exponent.is_finite()) {
        return Err(Error::invalid(
            "exponent",
            format!("must be > 1, got {}", shape.exponent),
        ));
    }
    if !(shape.taper > -1.0 && shape.taper < 1.0) {
        return Err(Error::invalid(
            "taper",
            format!("must be in (-1, 1), got {}", shape.taper),
        ));
    }
    if !(3..=MAX_MESH_DIVISIONS).contains(&cfg.rings)
        || !(3..=MAX_MESH_DIVISIONS).contains(&cfg.sectors)
    {
        return Err(Error::invalid(
            "rings/sectors",
            format!(
                "must be within 3..={MAX_MESH_DIVISIONS}, got {} and {}",
                cfg.rings, cfg.sectors
            ),
        ));
    }
    // Rings clustered toward the ends, where the profile changes fastest.
    let ws: Vec<f64> = (1..cfg.rings)
        .map(|i| 0.5 * (1.0 - (std::f64::consts::PI * i as f64 / cfg.rings as f64).cos()))
        .collect();
    let peak = (0..=1000)
        .map(|i| profile(shape, i as f64 / 1000.0))
        .fold(0.0, f64::max)
        .sqrt();
    let mut mesh = Mesh::default();
    mesh.vertices.push([0.0, 0.0, 0.0]);
    for &w in &ws {
        let rho = profile(shape, w).sqrt() / peak;
        for j in 0..cfg.sectors {
            let phi = 2.0 * std::f64::consts::PI * j as f64 / cfg.sectors as f64;
            mesh.vertices
                .push([x0 * rho * phi.cos(), y0 * rho * phi.sin(), w * z0]);
        }
    }
    mesh.vertices.push([0.0, 0.0, z0]);
    let m = cfg.sectors as u32;
    let ring = |i: usize, j: u32| 1 + i as u32 * m + (j % m);
    let top = mesh.vertices.len() as u32 - 1;
    for j in 0..m {
        mesh.faces.push([0, ring(0, j + 1), ring(0, j)]);
        mesh.faces
            .push([top, ring(ws.len() - 1, j), ring(ws.len() - 1, j + 1)]);
    }
    for i in 0..ws.len() - 1 {
        for j in 0..m {
            mesh.faces
                .push([ring(i, j), ring(i, j + 1), ring(i + 1, j + 1)]);
            mesh.faces
                .push([ring(i, j), ring(i + 1, j + 1), ring(i + 1, j)]);
        }
    }
    Ok(mesh)
}

/// Long axis of each segment's super-quadric in the segment frame, as (a, b, c) with
/// a × b = c: eq. 1's x and y map to a and b, its z to c. Limbs, trunk and head run
/// along +y (proximal → distal, i.e. downward at rest); the foot runs heel → toe (−z).
fn segment_axes(segment: usize) -> [Vector3<f64>; 3] {
    if segment == super::seg::R_FOOT || segment == super::seg::L_FOOT {
        [Vector3::y(), Vector3::x(), -Vector3::z()]
    } else {
        [Vector3::z(), Vector3::x(), Vector3::y()]
    }
}

impl BodyModel {
    /// Super-quadric surface mesh of every segment, posed, in the camera frame.
    pub fn superquadric_meshes(&self, pose: &Pose, cfg: &MeshConfig) -> Result<Vec<Mesh>> {
        let frames = self.segment_transforms(pose);
        let ell = self.shape.ellipsoids();
        (0..NUM_SEGMENTS)
            .map(|k| {
                let [a, b, c] = segment_axes(k);
                let r = ell[k].radii;
                let (ra, rb, rc) = (a.abs().dot(&r), b.abs().dot(&r), c.abs().dot(&r));
                let mut mesh = superquadric_mesh(ra, rb, 2.0 * rc, &SEGMENT_SUPERQUADRICS[k], cfg)?;
                let start = ell[k].centre - c * rc;
                for v in mesh.vertices.iter_mut() {
                    let local = start + a * v[0] + b * v[1] + c * v[2];
                    let p = frames[k].transform_point(&local.into());
                    *v = [p.x, p.y, p.z];
                }
                Ok(mesh)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Signed volume by the divergence theorem (positive for outward faces).
    fn volume(mesh: &Mesh) -> f64 {
        mesh.faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| Vector3::from(mesh.vertices[i as usize]));
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    #[test]
    fn plain_superquadric_is_the_ellipsoid() {
        let cfg = MeshConfig {
            rings: 120,
            sectors: 160,
        };
        let m = superquadric_mesh(0.1, 0.2, 0.6, &sq(0.0, 2.0), &cfg).unwrap();
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 0.1 * 0.2 * 0.3;
        assert!((volume(&m) - exact).abs() / exact < 2e-3, "{}", volume(&m));
        for v in &m.vertices {
            let l = (v[0] / 0.1).powi(2) + (v[1] / 0.2).powi(2) + ((v[2] - 0.3) / 0.3).powi(2);
            assert!((l - 1.0).abs() < 1e-9);
        }
        // Closed: every edge shared by exactly two faces, in opposite directions.
        let mut edges = std::collections::HashMap::new();
        for f in &m.faces {
            for e in 0..3 {
                *edges.entry((f[e], f[(e + 1) % 3])).or_insert(0) += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1);
            assert_eq!(edges.get(&(b, a)), Some(&1));
        }
    }

    #[test]
    fn higher_exponent_fills_more_and_taper_narrows() {
        let cfg = MeshConfig::default();
        let v2 = volume(&superquadric_mesh(0.1, 0.1, 0.5, &sq(0.0, 2.0), &cfg).unwrap());
        let v6 = volume(&superquadric_mesh(0.1, 0.1, 0.5, &sq(0.0, 6.0), &cfg).unwrap());
        assert!(v6 > 1.2 * v2 && v2 > 0.0);
        let m = superquadric_mesh(0.1, 0.1, 0.5, &sq(-0.5, 4.0), &cfg).unwrap();
        let width_at = |lo: f64, hi: f64| {
            m.vertices
                .iter()
                .filter(|v| v[2] > lo && v[2] < hi)
                .map(|v| v[0].hypot(v[1]))
                .fold(0.0, f64::max)
        };
        assert!(width_at(0.05, 0.15) > width_at(0.35, 0.45));
        assert!(superquadric_mesh(0.1, 0.1, 0.5, &sq(0.0, 0.5), &cfg).is_err());
    }

    #[test]
    fn body_meshes_wrap_the_ellipsoids() {
        let model = BodyModel::default();
        let pose = BodyModel::neutral_pose();
        let meshes = model
            .superquadric_meshes(&pose, &MeshConfig::default())
            .unwrap();
        assert_eq!(meshes.len(), NUM_SEGMENTS);
        let placed = model.placed_ellipsoids(&super::super::Kinematics::new(&model, &pose));
        for (k, m) in meshes.iter().enumerate() {
            assert!(volume(m) > 0.0, "segment {k} faces inward");
            // Every vertex lies near its ellipsoid (within a fraction of its size).
            let size = model.shape.ellipsoids()[k].radii.max();
            for v in &m.vertices {
                let d = placed[k].signed_distance(&Vector3::from(*v));
                assert!(d.abs() < 0.5 * size, "segment {k}: vertex {d} m off");
            }
        }
    }
}
