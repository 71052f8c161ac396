//! The CRF's labels: the segments and the outlier, and labels as reported to callers.

use crate::body::NUM_SEGMENTS;

/// Label of the outlier class inside the CRF (exported as −1).
pub const OUTLIER: i32 = NUM_SEGMENTS as i32;
/// CRF labels: the segments plus the outlier.
pub const NUM_LABELS: usize = NUM_SEGMENTS + 1;

/// Labels as reported to callers, with what they contain.
#[derive(Debug, Clone, PartialEq)]
pub struct PointLabels {
    /// Per point: segment 0..[`NUM_SEGMENTS`], −1 = outlier.
    pub labels: Vec<i32>,
    /// Points labelled with each segment.
    pub part_counts: [usize; NUM_SEGMENTS],
    /// Points labelled outlier.
    pub outliers: usize,
}

impl PointLabels {
    /// From the solver's labels (outlier label [`OUTLIER`]).
    pub(super) fn new(solver_labels: Vec<i32>) -> Self {
        let mut part_counts = [0usize; NUM_SEGMENTS];
        let mut outliers = 0;
        let labels = solver_labels
            .into_iter()
            .map(|l| {
                if l == OUTLIER {
                    outliers += 1;
                    -1
                } else {
                    part_counts[l as usize] += 1;
                    l
                }
            })
            .collect();
        PointLabels {
            labels,
            part_counts,
            outliers,
        }
    }
}
