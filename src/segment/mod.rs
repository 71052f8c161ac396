//! Person segmentation: which pixels of a depth image are the person, with or without a
//! frame of the empty scene.
//!
//! With a background frame, the person is what lies clearly in front of it
//! ([`crate::cloud::foreground_mask`]). Without one — the usual case — the scene's
//! support planes (floor, walls) are found and removed ([`planes`]), what remains is
//! split into depth-continuous clusters, and the person is the cluster that looks most
//! like one in metric terms ([`clusters`]); in a video the previous frame's planes are
//! reused and the previous person is followed. A video may also learn its static
//! background over its frames ([`background_model`]); once it has, the person is what
//! lies clearly in front of the learned background, with the support-plane test kept for
//! the pixels not yet learned. The result says which method found the person, which
//! planes were removed and which other person-like clusters were seen.

pub mod background_model;
pub mod clusters;
pub mod planes;

#[cfg(test)]
mod tests;

use crate::camera::Camera;
use crate::cloud::foreground::{fill_silhouette, in_front_of_background, Components, MAX_GAP};
use crate::cloud::{foreground_mask, DepthView, ForegroundConfig};
use crate::error::{ensure, Error, Result};
pub use background_model::{BackgroundModel, BackgroundModelConfig};
pub use clusters::{Cluster, PersonPrior};
use nalgebra::Vector3;
use planes::Rays;
pub use planes::{Plane, PlaneConfig};
use std::sync::Arc;

/// Settings of [`segment_person`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SegmentConfig {
    /// Depth range, background tolerance, depth continuity, speckle size and attachment
    /// of pieces (shared with background subtraction).
    pub foreground: ForegroundConfig,
    /// Support-plane detection.
    pub planes: PlaneConfig,
    /// What a person looks like.
    pub person: PersonPrior,
}

impl SegmentConfig {
    pub fn validate(&self) -> Result<()> {
        self.foreground.validate()?;
        let p = &self.planes;
        ensure(p.samples >= 3, "planes.samples", || {
            format!("must be >= 3, got {}", p.samples)
        })?;
        ensure(p.iterations <= 100_000, "planes.iterations", || {
            format!("must be <= 100000, got {}", p.iterations)
        })?;
        for (v, n) in [
            (p.local_radius, "planes.local_radius"),
            (p.min_area, "planes.min_area"),
            (p.tolerance, "planes.tolerance"),
            (p.tolerance_quadratic, "planes.tolerance_quadratic"),
        ] {
            ensure(v.is_finite() && v >= 0.0, n, || {
                format!("must be >= 0, got {v}")
            })?;
        }
        let q = &self.person;
        for (v, n) in [
            (q.min_area, "person.min_area"),
            (q.max_area, "person.max_area"),
            (q.min_extent, "person.min_extent"),
            (q.max_extent, "person.max_extent"),
            (q.min_height, "person.min_height"),
            (q.full_extent, "person.full_extent"),
            (q.comparable, "person.comparable"),
            (q.continuity, "person.continuity"),
            (q.piece_share, "person.piece_share"),
        ] {
            ensure(v.is_finite() && v >= 0.0, n, || {
                format!("must be >= 0, got {v}")
            })?;
        }
        ensure(q.full_extent > 0.0, "person.full_extent", || {
            "must be > 0".into()
        })
    }
}

/// How the person's pixels were found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Subtraction of a frame of the empty scene.
    Background,
    /// Support planes removed, the most person-like cluster kept.
    Planes,
    /// As [`Method::Planes`], but where a video's learned background is known the
    /// pixels in front of it are the candidates instead of those off the planes.
    Learned,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Background => "background",
            Method::Planes => "planes",
            Method::Learned => "learned",
        }
    }
}

/// What a video's previous frame tells the next segmentation.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SegmentHint {
    /// The support planes found last (tried first).
    pub planes: Vec<Plane>,
    /// The person's centroid last (camera frame, m).
    pub centroid: Option<[f32; 3]>,
    /// The video's learned background (metres, row-major, the depth image's size; 0
    /// where unknown), once it is reliable ([`BackgroundModel::learned`]).
    pub background: Option<Arc<Vec<f32>>>,
}

/// The person's pixels and how they were found.
#[derive(Debug, Clone, PartialEq)]
pub struct Segmentation {
    /// Row-major, the depth image's size.
    pub mask: Vec<bool>,
    pub method: Method,
    /// The support planes removed (none with a background frame).
    pub planes: Vec<Plane>,
    /// The person (all of its pieces together).
    pub person: Cluster,
    /// Other person-like clusters, most person-like first.
    pub others: Vec<Cluster>,
}

impl Segmentation {
    /// What the next frame of a video should start from.
    pub fn hint(&self) -> SegmentHint {
        SegmentHint {
            planes: self.planes.clone(),
            centroid: Some(self.person.centroid),
            background: None,
        }
    }
}

/// The person's pixels in `depth`: by background subtraction when `background` is given,
/// else by support-plane removal and cluster choice (module docs). `hint` carries a
/// video's previous frame and its learned background, which decides the pixels it knows.
/// Errors with `NoBody` (saying what was found) when nothing looks like a person, and
/// `InvalidArgument` when the background's (or the learned one's) size differs.
pub fn segment_person(
    depth: &DepthView,
    camera: &Camera,
    background: Option<&DepthView>,
    config: &SegmentConfig,
    hint: Option<&SegmentHint>,
) -> Result<Segmentation> {
    config.validate()?;
    ensure(
        camera.width == depth.width && camera.height == depth.height,
        "camera",
        || {
            format!(
                "is {}x{} but the depth image is {}x{}",
                camera.width, camera.height, depth.width, depth.height
            )
        },
    )?;
    let learned = hint.and_then(|h| h.background.as_deref());
    if let Some(b) = learned {
        ensure(b.len() == depth.data.len(), "hint.background", || {
            format!("has {} values for {} pixels", b.len(), depth.data.len())
        })?;
    }
    let rays = Rays::new(camera, depth.width, depth.height);
    if let Some(bg) = background {
        let mask = foreground_mask(depth, Some(bg), &config.foreground)?;
        let person = measure_mask(depth, &rays, &mask, Vector3::new(0.0, -1.0, 0.0));
        return Ok(Segmentation {
            mask,
            method: Method::Background,
            planes: Vec::new(),
            person,
            others: Vec::new(),
        });
    }
    let fg = &config.foreground;
    let usable: Vec<bool> = depth
        .data
        .iter()
        .map(|&z| z > fg.min_depth && z < fg.max_depth)
        .collect();
    let valid = usable.iter().filter(|&&u| u).count();
    if valid == 0 {
        return Err(Error::NoBody(if depth.count_valid() == 0 {
            "depth: the image has no valid reading (all zero or NaN)".into()
        } else {
            format!(
                "depth: no reading between {} and {} m",
                fg.min_depth, fg.max_depth
            )
        }));
    }
    let previous = hint.map(|h| h.planes.as_slice()).unwrap_or(&[]);
    let (planes, on_plane) = planes::detect_planes(depth, &rays, &usable, &config.planes, previous);
    let candidate: Vec<bool> = match learned {
        // Known pixels: in front of the learned background; unknown ones: off the planes.
        Some(bg) => usable
            .iter()
            .zip(&on_plane)
            .zip(depth.data.iter().zip(bg))
            .map(|((&u, &p), (&z, &b))| {
                let known = b > 0.0;
                u & ((known & in_front_of_background(z, b, fg)) | (!known & !p))
            })
            .collect(),
        None => usable
            .iter()
            .zip(&on_plane)
            .map(|(&u, &p)| u & !p)
            .collect(),
    };
    // Medians are taken per group below, not per component.
    let components = Components::label(depth, &candidate, fg.max_step, usize::MAX);
    let up = clusters::up_direction(&planes);
    let groups = components.bridge_gaps(depth, MAX_GAP, fg.attach_depth);
    let (found, cluster_of_group) = clusters::measure(
        depth,
        &rays,
        &components,
        (&groups.0, groups.1),
        up,
        fg.min_component,
        &config.person,
    );
    let centroid = hint.and_then(|h| h.centroid);
    let Some(chosen) = clusters::choose_person(&found, centroid, &config.person) else {
        return Err(Error::NoBody(nobody_message(&planes, &found)));
    };
    let keep = clusters::pieces_of(&found, chosen, fg.attach_depth, &config.person);
    let mut keep_cluster = vec![false; found.len()];
    for &k in &keep {
        keep_cluster[k] = true;
    }
    let keep_component: Vec<bool> = groups
        .0
        .iter()
        .map(|&g| cluster_of_group[g] != usize::MAX && keep_cluster[cluster_of_group[g]])
        .collect();
    let mut mask = vec![false; depth.data.len()];
    for &i in &components.pixels {
        mask[i as usize] = keep_component[components.label[i as usize] as usize];
    }
    let bbox = clusters::bbox_of(&found, &keep);
    fill_silhouette(depth, &mut mask, bbox);
    let person = if keep.len() == 1 {
        found[chosen]
    } else {
        measure_mask(depth, &rays, &mask, up)
    };
    let mut others: Vec<Cluster> = (0..found.len())
        .filter(|&k| found[k].person_like && !keep.contains(&k))
        .map(|k| found[k])
        .collect();
    others.sort_by(|a, b| b.score.total_cmp(&a.score));
    Ok(Segmentation {
        mask,
        method: if learned.is_some() {
            Method::Learned
        } else {
            Method::Planes
        },
        planes,
        person,
        others,
    })
}

/// "No person found", saying what was found instead.
fn nobody_message(planes: &[Plane], clusters: &[Cluster]) -> String {
    let mut msg = format!(
        "depth: no person-like object found ({} support plane{} removed, {} cluster{} left",
        planes.len(),
        if planes.len() == 1 { "" } else { "s" },
        clusters.len(),
        if clusters.len() == 1 { "" } else { "s" },
    );
    if let Some(c) = clusters.iter().max_by(|a, b| a.area.total_cmp(&b.area)) {
        msg += &format!(
            "; the largest covers {:.2} m², {:.2} m tall and {:.2} m wide, at {:.2} m",
            c.area, c.height, c.width, c.median_depth
        );
    }
    msg + ")"
}

/// The cluster measures of the pixels of `mask` that have a reading, as one cluster.
fn measure_mask(depth: &DepthView, rays: &Rays, mask: &[bool], up: Vector3<f64>) -> Cluster {
    let candidate: Vec<bool> = mask
        .iter()
        .zip(depth.data)
        .map(|(&m, &z)| m && z > 0.0)
        .collect();
    let components = Components::label(depth, &candidate, f32::INFINITY, usize::MAX);
    let one = vec![0; components.stats.len()];
    let (found, _) = clusters::measure(
        depth,
        rays,
        &components,
        (&one, 1),
        up,
        1,
        &PersonPrior::default(),
    );
    found.into_iter().next().unwrap_or(Cluster {
        pixels: 0,
        area: 0.0,
        height: 0.0,
        width: 0.0,
        centroid: [f32::NAN; 3],
        median_depth: f32::NAN,
        bbox: [0; 4],
        person_like: false,
        score: 0.0,
    })
}
