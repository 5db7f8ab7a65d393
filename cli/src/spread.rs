//! Spreading keypoints over the image: the strongest FAST corners crowd into the most textured
//! parts of a photo, and structure from motion needs correspondences all over it.

use clatch::KeyPoint;

/// Keeps at most `max` of `keypoints` (strongest first, as the detector returns them) spread over a
/// `grid` x `grid` division of the `width` x `height` image: each cell first keeps its strongest
/// `ceil(max / grid²)`, then the strongest of the rest fill what sparse cells left. The result keeps
/// the input's order (so it stays strongest first); `grid = 1` is plain top-`max`.
pub fn spread(
    keypoints: &[KeyPoint],
    width: u32,
    height: u32,
    grid: u32,
    max: usize,
) -> Vec<KeyPoint> {
    let grid = grid.max(1) as usize;
    let cells = grid * grid;
    let quota = max.div_ceil(cells);
    let cell_of = |k: &KeyPoint| {
        let cx = (k.x as usize * grid / width.max(1) as usize).min(grid - 1);
        let cy = (k.y as usize * grid / height.max(1) as usize).min(grid - 1);
        cy * grid + cx
    };
    let mut taken_in_cell = vec![0usize; cells];
    let mut keep = vec![false; keypoints.len()];
    let mut kept = 0;
    for (i, k) in keypoints.iter().enumerate() {
        let cell = cell_of(k);
        if kept < max && taken_in_cell[cell] < quota {
            taken_in_cell[cell] += 1;
            keep[i] = true;
            kept += 1;
        }
    }
    for flag in keep.iter_mut() {
        if kept >= max {
            break;
        }
        if !*flag {
            *flag = true;
            kept += 1;
        }
    }
    keypoints
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(p, _)| *p)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_crowded_corner_gives_way_to_the_rest_of_the_image() {
        // 10 strong keypoints in the top-left cell, then 2 weaker ones in each other cell of a 2x2 grid.
        let mut kps: Vec<KeyPoint> = (0..10).map(|i| KeyPoint::new(i as f32, 1.0)).collect();
        for (x, y) in [
            (60.0, 1.0),
            (61.0, 1.0),
            (1.0, 60.0),
            (2.0, 60.0),
            (60.0, 60.0),
            (61.0, 61.0),
        ] {
            kps.push(KeyPoint::new(x, y));
        }
        let kept = spread(&kps, 100, 100, 2, 8);
        // Quota 2 per cell: 2 from the crowded cell, 2 from each other cell.
        assert_eq!(kept.len(), 8);
        assert_eq!(kept.iter().filter(|k| k.x < 50.0 && k.y < 50.0).count(), 2);
        assert_eq!(kept[0], kps[0]);
        // Sparse cells leave room that the strongest others fill, in their order.
        let kept = spread(&kps, 100, 100, 2, 12);
        assert_eq!(kept.len(), 12);
        assert_eq!(kept.iter().filter(|k| k.x < 50.0 && k.y < 50.0).count(), 6);
        assert_eq!(spread(&kps, 100, 100, 1, 5), kps[..5].to_vec());
        assert_eq!(spread(&kps, 100, 100, 4, 100).len(), kps.len());
    }
}
