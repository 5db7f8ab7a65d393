//! What extraction returns, from every backend and every entry point.

use crate::describe::{Described, Skipped};
use crate::descriptor::DescriptorSet;
use crate::keypoint::KeyPoint;

/// Keypoints and their descriptors: row `i` of `descriptors` describes `keypoints[i]`.
///
/// [`crate::Extractor::detect_and_describe`] describes every keypoint it detects, so there
/// `keypoint_index` is `0..n` and `skipped` is empty. [`crate::Extractor::describe`] and
/// [`crate::Extractor::describe_opencv`] describe keypoints the caller gives: those that cannot be
/// described are left out of `keypoints` and listed in `skipped`, and `keypoint_index` maps each row
/// back to its place in the caller's list. Every input keypoint appears exactly once, in
/// `keypoint_index` or in `skipped`, both in input order.
///
/// `#[non_exhaustive]`: a result, read through its fields; what extraction reports may grow.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct Features {
    /// The described keypoints, one per descriptor row (detected ones strongest first).
    pub keypoints: Vec<KeyPoint>,
    /// One descriptor per keypoint.
    pub descriptors: DescriptorSet,
    /// For each row, the index of its keypoint in the list that was described.
    pub keypoint_index: Vec<usize>,
    /// Input keypoints that got no descriptor, and why.
    pub skipped: Vec<Skipped>,
}

impl Features {
    /// Every keypoint described: row `i` is `keypoints[i]`.
    pub(crate) fn all(keypoints: Vec<KeyPoint>, descriptors: DescriptorSet) -> Self {
        Self {
            keypoint_index: (0..keypoints.len()).collect(),
            keypoints,
            descriptors,
            skipped: Vec::new(),
        }
    }

    /// A description of the caller's `input` keypoints, with the described ones picked out.
    pub(crate) fn of_input(input: &[KeyPoint], described: Described) -> Self {
        let Described {
            descriptors,
            keypoint_index,
            skipped,
        } = described;
        Self {
            keypoints: keypoint_index.iter().map(|&i| input[i]).collect(),
            descriptors,
            keypoint_index,
            skipped,
        }
    }

    /// The number of described keypoints.
    pub fn len(&self) -> usize {
        self.keypoints.len()
    }

    /// True when nothing was described.
    pub fn is_empty(&self) -> bool {
        self.keypoints.is_empty()
    }
}
