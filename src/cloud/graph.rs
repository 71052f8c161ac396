//! The pixel-neighbourhood graph the CRF works on.

use super::normals::sub;
use super::points::{set_len, split_rows, Cloud, ROWS_PER_TASK};
use crate::error::{Error, Result};
use rayon::prelude::*;

/// Pixel connectivity of the neighbourhood graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Connectivity {
    Four,
    Eight,
}

impl Connectivity {
    pub fn from_int(n: u32) -> Result<Self> {
        match n {
            4 => Ok(Connectivity::Four),
            8 => Ok(Connectivity::Eight),
            _ => Err(Error::invalid(
                "connectivity",
                format!("must be 4 or 8, got {n}"),
            )),
        }
    }

    /// The number of neighbours of a pixel: 4 or 8 (the inverse of [`Connectivity::from_int`]).
    pub fn neighbours(self) -> u32 {
        match self {
            Connectivity::Four => 4,
            Connectivity::Eight => 8,
        }
    }
}

/// The undirected graph between neighbouring points of a cloud.
#[derive(Debug, Clone, Default)]
pub struct PixelGraph {
    /// Point indices (i, j), i < j in pixel order, each edge once.
    pub edges: Vec<[u32; 2]>,
    /// 3-D distance between the two points (metres).
    pub distance: Vec<f32>,
    /// Depth difference z_j − z_i (metres).
    pub depth_diff: Vec<f32>,
}

impl PixelGraph {
    pub fn len(&self) -> usize {
        self.edges.len()
    }

    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }
}

/// Number of forward edges starting in `row` (those of [`fill_row_edges`]), counted
/// over the columns from the row's first to its last point with sums the compiler
/// vectorises: two look-up entries a, b are both points exactly when `a | b >= 0`.
#[inline(always)]
pub(super) fn row_edge_count<const EIGHT: bool>(cloud: &Cloud, row: usize) -> u32 {
    let (w, h) = (cloud.width, cloud.height);
    let (first, end) = (
        cloud.row_start[row] as usize,
        cloud.row_start[row + 1] as usize,
    );
    if first == end {
        return 0;
    }
    let col_of = |k: usize| cloud.pixels[k] as usize - row * w;
    let (c0, c1) = (col_of(first), col_of(end - 1) + 1);
    let here = &cloud.point_of_pixel[row * w..(row + 1) * w];
    let pairs = |a: &[i32], b: &[i32]| -> u32 {
        a.iter().zip(b).map(|(&a, &b)| ((a | b) >= 0) as u32).sum()
    };
    let mut count = pairs(&here[c0..c1 - 1], &here[c0 + 1..c1]); // right
    if row + 1 < h {
        let below = &cloud.point_of_pixel[(row + 1) * w..(row + 2) * w];
        count += pairs(&here[c0..c1], &below[c0..c1]); // down
        if EIGHT {
            let l0 = c0.max(1);
            count += pairs(&here[l0..c1], &below[l0 - 1..c1 - 1]); // down-left
            let r1 = c1.min(w - 1);
            if c0 < r1 {
                count += pairs(&here[c0..r1], &below[c0 + 1..r1 + 1]); // down-right
            }
        }
    }
    count
}

/// Fills the edges starting in `row` (their exact number) with their attributes, in
/// pixel order: for each point of the row (a), its neighbours (b > a) right, down-left,
/// down and down-right (8-connectivity; right and down only for 4).
#[inline(always)]
pub(super) fn fill_row_edges<const EIGHT: bool>(
    cloud: &Cloud,
    row: usize,
    edges: &mut [[u32; 2]],
    distance: &mut [f32],
    depth_diff: &mut [f32],
) {
    let (w, h) = (cloud.width, cloud.height);
    let (first, end) = (
        cloud.row_start[row] as usize,
        cloud.row_start[row + 1] as usize,
    );
    let first_pixel = (row * w) as u32;
    let here = &cloud.point_of_pixel[row * w..(row + 1) * w];
    let below = if row + 1 < h {
        &cloud.point_of_pixel[(row + 1) * w..(row + 2) * w]
    } else {
        &[][..]
    };
    let point = |lookup: &[i32], col: usize| lookup.get(col).copied().unwrap_or(-1);
    let points = &cloud.points[..];
    let mut k = 0;
    // The edge a→b (b ≥ 0); the squared distance for now, the square roots are taken
    // below, all at once.
    let mut emit = |a: u32, p: [f32; 3], b: i32| {
        if b >= 0 {
            let d = sub(points[b as usize], p);
            edges[k] = [a, b as u32];
            distance[k] = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            depth_diff[k] = d[2];
            k += 1;
        }
    };
    for ((a, &pixel), &p) in (first as u32..)
        .zip(&cloud.pixels[first..end])
        .zip(&points[first..end])
    {
        let col = (pixel - first_pixel) as usize;
        emit(a, p, point(here, col + 1));
        if EIGHT {
            emit(a, p, point(below, col.wrapping_sub(1)));
        }
        emit(a, p, point(below, col));
        if EIGHT {
            emit(a, p, point(below, col + 1));
        }
    }
    for d in distance.iter_mut() {
        *d = d.sqrt();
    }
}

/// Edges between points of `cloud` whose pixels are 4- or 8-neighbours.
pub fn neighbour_graph(cloud: &Cloud, connectivity: Connectivity) -> PixelGraph {
    let mut graph = PixelGraph::default();
    neighbour_graph_into(cloud, connectivity, &mut graph);
    graph
}

/// [`neighbour_graph`] into `graph`, reusing its storage.
pub fn neighbour_graph_into(cloud: &Cloud, connectivity: Connectivity, graph: &mut PixelGraph) {
    match connectivity {
        Connectivity::Four => graph_into::<false>(cloud, graph),
        Connectivity::Eight => graph_into::<true>(cloud, graph),
    }
}

pub(super) fn graph_into<const EIGHT: bool>(cloud: &Cloud, graph: &mut PixelGraph) {
    let h = cloud.height;
    // Pass 1: edges per row and their offsets; pass 2: rows fill their own slices, so the
    // edges come out in pixel order whatever the threads do.
    let mut edge_start = vec![0u32; h + 1];
    edge_start[1..]
        .par_iter_mut()
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each(|(row, n)| *n = row_edge_count::<EIGHT>(cloud, row));
    for row in 0..h {
        edge_start[row + 1] += edge_start[row];
    }
    let m = edge_start[h] as usize;
    set_len(&mut graph.edges, m, [0, 0]);
    set_len(&mut graph.distance, m, 0.0);
    set_len(&mut graph.depth_diff, m, 0.0);
    let rows = split_rows(&mut graph.edges, &edge_start)
        .into_iter()
        .zip(split_rows(&mut graph.distance, &edge_start))
        .zip(split_rows(&mut graph.depth_diff, &edge_start))
        .collect::<Vec<_>>();
    rows.into_par_iter()
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each(|(row, ((edges, distance), depth_diff))| {
            fill_row_edges::<EIGHT>(cloud, row, edges, distance, depth_diff)
        });
}
