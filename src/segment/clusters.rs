//! Depth-continuous clusters of the pixels left once the support planes are removed,
//! measured in metres, and the choice of the person among them.
//!
//! Each cluster's footprint area (Σ z²/(fx·fy)) and its extents along the scene's up
//! direction (the floor's normal, or the camera's −y without a floor) and across it
//! make a person recognisable whatever the distance and the resolution: a standing
//! adult covers 0.3–0.8 m² and spans 1.5–2 m; a chair, a box or a leftover strip of wall
//! does not look like that. The person is the most person-like cluster; when several are
//! comparable (two people), the nearest; in a video, the one nearest the previous
//! frame's person, so that the tracked person stays chosen when someone else comes
//! nearer.

use super::planes::{Plane, Rays};
use crate::cloud::foreground::{union_box, Components};
use crate::cloud::DepthView;
use nalgebra::Vector3;

/// What a person looks like, in metres: the bounds of [`Cluster::person_like`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PersonPrior {
    /// Footprint area bounds (m²): a child's side view to a person with arms spread,
    /// close to the camera.
    pub min_area: f32,
    pub max_area: f32,
    /// Bounds of the larger of the height and the width (m).
    pub min_extent: f32,
    pub max_extent: f32,
    /// A person is at least this tall along the up direction (m): lying down still
    /// leaves a body's thickness.
    pub min_height: f32,
    /// Extents up to this (m) raise a cluster's score in proportion.
    pub full_extent: f32,
    /// Clusters scoring at least this share of the best one compete on nearness.
    pub comparable: f32,
    /// In a video, the cluster whose centroid is within this many metres of the previous
    /// person's is the person, if it looks like one.
    pub continuity: f32,
    /// A piece beside the person (a hand cut off by a sensor shadow) joins it when its
    /// area is below this share of the person's, or it spans less than `min_extent`.
    pub piece_share: f32,
}

impl Default for PersonPrior {
    fn default() -> Self {
        PersonPrior {
            min_area: 0.05,
            max_area: 2.5,
            min_extent: 0.45,
            max_extent: 2.6,
            min_height: 0.25,
            full_extent: 1.2,
            comparable: 0.5,
            continuity: 0.6,
            piece_share: 0.15,
        }
    }
}

/// One depth-continuous cluster of pixels, measured in the camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cluster {
    /// Pixels in the cluster.
    pub pixels: usize,
    /// Footprint area, m² (each pixel z²/(fx·fy)).
    pub area: f32,
    /// Extent along the up direction, m.
    pub height: f32,
    /// Largest extent across the up direction, m.
    pub width: f32,
    /// Mean point, camera frame, m.
    pub centroid: [f32; 3],
    /// Median depth, m.
    pub median_depth: f32,
    /// Bounding box in pixels: row0, col0, row1, col1 (inclusive).
    pub bbox: [usize; 4],
    /// Whether its size and extents are a person's ([`PersonPrior`]).
    pub person_like: bool,
    /// Area × min(1, extent / full extent) for a person-like cluster, else 0.
    pub score: f32,
}

impl Cluster {
    fn extent(&self) -> f32 {
        self.height.max(self.width)
    }

    fn distance_to(&self, p: [f32; 3]) -> f32 {
        let c = self.centroid;
        ((c[0] - p[0]).powi(2) + (c[1] - p[1]).powi(2) + (c[2] - p[2]).powi(2)).sqrt()
    }
}

/// The scene's up direction: against the normal of the floor (the plane whose normal is
/// nearest the camera's +y, within 45°), else the camera's −y.
pub fn up_direction(planes: &[Plane]) -> Vector3<f64> {
    let down = planes
        .iter()
        .map(|p| Vector3::from(p.normal))
        .filter(|n| n.y >= std::f64::consts::FRAC_1_SQRT_2)
        .max_by(|a, b| a.y.total_cmp(&b.y));
    match down {
        Some(n) => -n,
        None => Vector3::new(0.0, -1.0, 0.0),
    }
}

/// Measures every group of components (see [`Components::bridge_gaps`]) of at least `min_size`
/// pixels; the others get no cluster. Returns the clusters and the cluster of each
/// group (`usize::MAX` for none).
pub(crate) fn measure(
    depth: &DepthView,
    rays: &Rays,
    components: &Components,
    (group, groups): (&[usize], usize),
    up: Vector3<f64>,
    min_size: usize,
    prior: &PersonPrior,
) -> (Vec<Cluster>, Vec<usize>) {
    let w = depth.width;
    let mut size = vec![0usize; groups];
    let mut bbox = vec![[usize::MAX, usize::MAX, 0, 0]; groups];
    for (k, s) in components.stats.iter().enumerate() {
        size[group[k]] += s.size;
        bbox[group[k]] = union_box(bbox[group[k]], s.bbox);
    }
    let mut index = vec![usize::MAX; groups];
    let mut clusters = Vec::new();
    for g in 0..groups {
        if size[g] >= min_size.max(1) {
            index[g] = clusters.len();
            clusters.push(Cluster {
                pixels: size[g],
                area: 0.0,
                height: 0.0,
                width: 0.0,
                centroid: [0.0; 3],
                median_depth: f32::NAN,
                bbox: bbox[g],
                person_like: false,
                score: 0.0,
            });
        }
    }
    // Axes: up, and two horizontal ones (the camera's x and z made level).
    let up = up.map(|v| v as f32);
    let level = |v: Vector3<f32>| (v - up * v.dot(&up)).normalize();
    let h1 = level(Vector3::new(1.0, 0.0, 0.0));
    let h2 = up.cross(&h1);
    let m = clusters.len();
    let (mut lo, mut hi) = (vec![[f32::INFINITY; 3]; m], vec![[f32::NEG_INFINITY; 3]; m]);
    let mut sum = vec![[0.0f64; 3]; m];
    let mut depths: Vec<Vec<f32>> = clusters
        .iter()
        .map(|c| Vec::with_capacity(c.pixels))
        .collect();
    for &i in &components.pixels {
        let i = i as usize;
        let c = index[group[components.label[i] as usize]];
        if c == usize::MAX {
            continue;
        }
        let (row, col) = (i / w, i % w);
        let z = depth.data[i];
        let p = Vector3::new(rays.x[col] * z, rays.y[row] * z, z);
        clusters[c].area += z * z * rays.pixel_area;
        for (a, axis) in [up, h1, h2].iter().enumerate() {
            let t = p.dot(axis);
            lo[c][a] = lo[c][a].min(t);
            hi[c][a] = hi[c][a].max(t);
        }
        for a in 0..3 {
            sum[c][a] += p[a] as f64;
        }
        depths[c].push(z);
    }
    for (c, cl) in clusters.iter_mut().enumerate() {
        let n = cl.pixels as f64;
        cl.centroid = sum[c].map(|s| (s / n) as f32);
        let d = &mut depths[c];
        let mid = d.len() / 2;
        cl.median_depth = *d.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1;
        cl.height = hi[c][0] - lo[c][0];
        cl.width = (hi[c][1] - lo[c][1]).max(hi[c][2] - lo[c][2]);
        let e = cl.extent();
        cl.person_like = (prior.min_area..=prior.max_area).contains(&cl.area)
            && (prior.min_extent..=prior.max_extent).contains(&e)
            && cl.height >= prior.min_height;
        if cl.person_like {
            cl.score = cl.area * (e / prior.full_extent).min(1.0);
        }
    }
    (clusters, index)
}

/// The person among `clusters`: the one nearest `previous` (the last frame's person's
/// centroid) within `continuity` when it looks like a person; else, of the person-like
/// clusters scoring at least `comparable` × the best, the nearest to the camera. None
/// when no cluster looks like a person.
pub fn choose_person(
    clusters: &[Cluster],
    previous: Option<[f32; 3]>,
    prior: &PersonPrior,
) -> Option<usize> {
    let candidates = || (0..clusters.len()).filter(|&k| clusters[k].person_like);
    if let Some(p) = previous {
        let nearest = candidates()
            .map(|k| (k, clusters[k].distance_to(p)))
            .filter(|&(_, d)| d <= prior.continuity)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((k, _)) = nearest {
            return Some(k);
        }
    }
    let best = candidates()
        .map(|k| clusters[k].score)
        .fold(0.0f32, f32::max);
    candidates()
        .filter(|&k| clusters[k].score >= prior.comparable * best)
        .min_by(|&a, &b| {
            clusters[a]
                .median_depth
                .total_cmp(&clusters[b].median_depth)
        })
}

/// The person's cluster and the pieces that belong with it: clusters whose box touches
/// the person's (grown by a tenth), whose median depth is within `attach_depth` of the
/// person's, and which are small beside it (see [`PersonPrior::piece_share`]).
pub fn pieces_of(
    clusters: &[Cluster],
    person: usize,
    attach_depth: f32,
    prior: &PersonPrior,
) -> Vec<usize> {
    let b = &clusters[person];
    let grow_r = (b.bbox[2] - b.bbox[0]) / 10 + 1;
    let grow_c = (b.bbox[3] - b.bbox[1]) / 10 + 1;
    let outer = [
        b.bbox[0].saturating_sub(grow_r),
        b.bbox[1].saturating_sub(grow_c),
        b.bbox[2] + grow_r,
        b.bbox[3] + grow_c,
    ];
    let mut keep = vec![person];
    for (k, s) in clusters.iter().enumerate() {
        if k == person {
            continue;
        }
        let touches = s.bbox[0] <= outer[2]
            && s.bbox[2] >= outer[0]
            && s.bbox[1] <= outer[3]
            && s.bbox[3] >= outer[1];
        let small = s.area < prior.piece_share * b.area || s.extent() < prior.min_extent;
        if touches && small && (s.median_depth - b.median_depth).abs() <= attach_depth {
            keep.push(k);
        }
    }
    keep
}

/// The bounding box of the given clusters.
pub fn bbox_of(clusters: &[Cluster], which: &[usize]) -> [usize; 4] {
    which
        .iter()
        .fold([usize::MAX, usize::MAX, 0, 0], |acc, &k| {
            union_box(acc, clusters[k].bbox)
        })
}
