//! Keypoint selection over the levels of a pyramid, the same for every backend: each level's share of
//! the budget, the grid that spreads a share over its level, then the strongest of the rest. Ranks
//! and positions are integers, so every comparison is exact ([`crate::numerics`], section 6).

use crate::detect::{DetectorConfig, LevelBudget};
use crate::keypoint::KeyPoint;

/// A keypoint found on a level, in that level's coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelKeypoint {
    /// The level (0 = full resolution).
    pub level: usize,
    /// The detector's keypoint on that level (integer position, the configured size).
    pub keypoint: KeyPoint,
    /// What orders it ([`crate::Ranking`]): the FAST score, or the Harris response.
    pub rank: i64,
    /// Its sub-pixel offset `[dx, dy]` on its level in 1/65536 pixel ([`crate::Subpixel`]): 0 until
    /// set after selection.
    pub offset: [i32; 2],
}

/// The order of selection: rank descending, then level, `y`, `x` ascending (level coordinates).
/// Ranks and positions are integers: exact comparisons.
fn selection_key(k: &LevelKeypoint) -> (i64, usize, u32, u32) {
    (
        -k.rank,
        k.level,
        k.keypoint.y as u32,
        k.keypoint.x as u32,
    )
}

/// The rank of a detected keypoint under [`crate::Ranking::Fast`]: its FAST score.
pub fn fast_rank(_level: usize, k: &KeyPoint) -> i64 {
    k.response as i64
}

/// Each level's share of `budget` under [`LevelBudget::Geometric`] for `levels` levels of
/// `scale_factor`: `budget · (1 - f) / (1 - f^levels) · f^l` rounded, `f = 1 / scale_factor`, the
/// last level taking what is left (ORB's rule). Host `f64` arithmetic, the same for every backend.
pub fn level_shares(budget: usize, levels: usize, scale_factor: f64) -> Vec<usize> {
    if levels <= 1 {
        return vec![budget];
    }
    let f = 1.0 / scale_factor;
    let first = budget as f64 * (1.0 - f) / (1.0 - f.powi(levels as i32));
    let mut shares = Vec::with_capacity(levels);
    let mut given = 0usize;
    for l in 0..levels - 1 {
        let share = ((first * f.powi(l as i32)).round() as usize).min(budget - given);
        shares.push(share);
        given += share;
    }
    shares.push(budget - given);
    shares
}

/// Each level's share of `budget` under [`LevelBudget::Area`]: in proportion to the level's pixels
/// `w_l · h_l` of `sizes`, level `l` getting `floor(budget · A_l / A) - floor(budget · A_{l-1} / A)`
/// with `A_l` the pixels of levels `0..=l` and `A` all of them, so the shares add up to `budget`.
/// Integer arithmetic, the same for every backend.
pub fn area_shares(budget: usize, sizes: &[(usize, usize)]) -> Vec<usize> {
    let pixels: Vec<u128> = sizes.iter().map(|&(w, h)| w as u128 * h as u128).collect();
    let all: u128 = pixels.iter().sum::<u128>().max(1);
    let mut shares = Vec::with_capacity(sizes.len());
    let (mut up_to, mut given) = (0u128, 0usize);
    for p in pixels {
        up_to += p;
        let cumulative = (budget as u128 * up_to / all) as usize;
        shares.push(cumulative - given);
        given = cumulative;
    }
    if let (Some(last), true) = (shares.last_mut(), given < budget) {
        *last += budget - given; // only when every level is empty
    }
    shares
}

/// Keeps at most `budget` of `candidates` (in selection order) spread over a `grid` x `grid`
/// division of the image (a keypoint's cell is found on its own level, `sizes[level]`, so a cell is
/// the same part of the scene on every level): each cell first keeps its strongest
/// `ceil(budget / grid²)`, then the strongest of the rest fill what sparse cells left. Marks the kept
/// ones in `keep`. With `grid = 1` this is the plain strongest `budget`.
fn spread(
    candidates: &[LevelKeypoint],
    sizes: &[(usize, usize)],
    grid: usize,
    budget: usize,
    keep: &mut [bool],
) {
    let per_cell = budget.div_ceil(grid * grid);
    let cell_of = |k: &LevelKeypoint| {
        let (w, h) = sizes[k.level];
        let cx = (k.keypoint.x as usize * grid / w.max(1)).min(grid - 1);
        let cy = (k.keypoint.y as usize * grid / h.max(1)).min(grid - 1);
        cy * grid + cx
    };
    let mut taken = vec![0usize; grid * grid];
    let mut kept = 0;
    for (i, k) in candidates.iter().enumerate() {
        if kept == budget {
            return;
        }
        let in_cell = &mut taken[cell_of(k)];
        if *in_cell < per_cell {
            *in_cell += 1;
            keep[i] = true;
            kept += 1;
        }
    }
    for flag in keep.iter_mut() {
        if kept == budget {
            return;
        }
        if !*flag {
            *flag = true;
            kept += 1;
        }
    }
}

/// The keypoints kept over all levels, in selection order (score descending, level, y, x
/// ascending). `per_level[l]` is level `l`'s detection with [`DetectorConfig::candidates`];
/// `sizes[l]` its size. With the default settings this is the strongest `max_keypoints` of all levels;
/// [`LevelBudget::Geometric`] gives each level its share first, [`DetectorConfig::grid`] spreads each
/// share over the level, and what is left of the budget goes to the strongest keypoints not yet kept.
pub fn select(
    per_level: &[Vec<KeyPoint>],
    sizes: &[(usize, usize)],
    scale_factor: f64,
    config: &DetectorConfig,
    rank: &(dyn Fn(usize, &KeyPoint) -> i64 + Sync),
) -> Vec<LevelKeypoint> {
    let mut all: Vec<LevelKeypoint> = per_level
        .iter()
        .enumerate()
        .flat_map(|(level, kps)| {
            kps.iter().map(move |&keypoint| LevelKeypoint {
                level,
                keypoint,
                rank: rank(level, &keypoint),
                offset: [0, 0],
            })
        })
        .collect();
    all.sort_by_key(selection_key);
    let budget = config.max_keypoints;
    let mut keep = vec![false; all.len()];
    match config.level_budget {
        LevelBudget::Global => spread(&all, sizes, config.grid, budget, &mut keep),
        LevelBudget::Geometric | LevelBudget::Area => {
            let shares = match config.level_budget {
                LevelBudget::Area => area_shares(budget, &sizes[..per_level.len()]),
                _ => level_shares(budget, per_level.len(), scale_factor),
            };
            for (level, &share) in shares.iter().enumerate() {
                let (index, of_level): (Vec<usize>, Vec<LevelKeypoint>) = all
                    .iter()
                    .enumerate()
                    .filter(|(_, k)| k.level == level)
                    .map(|(i, k)| (i, *k))
                    .unzip();
                let mut level_keep = vec![false; of_level.len()];
                spread(&of_level, sizes, config.grid, share, &mut level_keep);
                for (i, kept) in index.into_iter().zip(level_keep) {
                    keep[i] |= kept;
                }
            }
        }
    }
    // What levels short of keypoints left goes to the strongest not yet kept.
    let mut kept = keep.iter().filter(|&&k| k).count();
    for flag in keep.iter_mut() {
        if kept >= budget {
            break;
        }
        if !*flag {
            *flag = true;
            kept += 1;
        }
    }
    all.into_iter()
        .zip(keep)
        .filter_map(|(k, kept)| kept.then_some(k))
        .collect()
}

/// The selected keypoints of one level, in selection order.
pub fn of_level(selected: &[LevelKeypoint], level: usize) -> Vec<KeyPoint> {
    selected
        .iter()
        .filter(|k| k.level == level)
        .map(|k| k.keypoint)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn budget(max_keypoints: usize) -> DetectorConfig {
        DetectorConfig {
            max_keypoints,
            ..DetectorConfig::default()
        }
    }

    fn scored(x: f32, y: f32, score: f32) -> KeyPoint {
        KeyPoint {
            response: score,
            ..KeyPoint::new(x, y)
        }
    }

    #[test]
    fn geometric_shares_follow_orb_and_add_up() {
        assert_eq!(level_shares(5000, 1, 1.2), vec![5000]);
        let shares = level_shares(5000, 8, 1.2);
        assert_eq!(shares.iter().sum::<usize>(), 5000);
        // ORB's first share: 5000 · (1 - 1/1.2) / (1 - 1.2^-8) = 833.3 / 0.76743 = 1085.9 -> 1086.
        assert_eq!(shares[0], 1086);
        assert!(shares.windows(2).take(6).all(|w| w[0] > w[1]));
        // Factor 2 halves each share: 4000 · 0.5 / (1 - 1/8) = 2285.7.
        assert_eq!(level_shares(4000, 3, 2.0), vec![2286, 1143, 571]);
        // Tiny budgets never hand out more than there is.
        for n in 0..20 {
            assert_eq!(level_shares(n, 8, 1.2).iter().sum::<usize>(), n);
        }
    }

    #[test]
    fn area_shares_follow_the_pixels_and_add_up() {
        // 10000, 2500 and 625 pixels of 13125: floor(100 · 10000 / 13125) = floor(76.2) = 76, then
        // floor(100 · 12500 / 13125) = floor(95.2) = 95 gives 19, and the last 5.
        assert_eq!(area_shares(100, &[(100, 100), (50, 50), (25, 25)]), vec![76, 19, 5]);
        assert_eq!(area_shares(5000, &[(800, 640)]), vec![5000]);
        // Tiny budgets and empty levels never hand out more (or less) than there is.
        for n in 0..20 {
            assert_eq!(area_shares(n, &[(9, 7), (7, 6), (6, 5)]).iter().sum::<usize>(), n);
        }
        assert_eq!(area_shares(7, &[(0, 0), (0, 0)]), vec![0, 7]);
    }

    #[test]
    fn a_crowded_cell_gives_way_to_the_rest_of_the_level() {
        // 10 strong keypoints in the top-left cell of a 2x2 grid, 2 weaker ones in each other cell.
        let mut level: Vec<KeyPoint> = (0..10).map(|i| scored(i as f32, 1.0, 90.0)).collect();
        for (x, y) in [(60.0, 1.0), (61.0, 1.0), (1.0, 60.0), (2.0, 60.0), (60.0, 60.0), (61.0, 61.0)] {
            level.push(scored(x, y, 30.0));
        }
        let spread_config = |max| DetectorConfig {
            grid: 2,
            ..budget(max)
        };
        let kept = select(&[level.clone()], &[(100, 100)], 2.0, &spread_config(8), &fast_rank);
        // 2 per cell: 2 from the crowded cell, 2 from each other one.
        assert_eq!(kept.len(), 8);
        let top_left = |s: &[LevelKeypoint]| {
            s.iter()
                .filter(|k| k.keypoint.x < 50.0 && k.keypoint.y < 50.0)
                .count()
        };
        assert_eq!(top_left(&kept), 2);
        // Sparse cells leave room that the strongest of the rest fill.
        let kept = select(&[level.clone()], &[(100, 100)], 2.0, &spread_config(12), &fast_rank);
        assert_eq!(top_left(&kept), 6);
        // Selection order stays score, then raster.
        assert!(kept.windows(2).all(|w| selection_key(&w[0]) < selection_key(&w[1])));
        // Without a grid: the plain strongest.
        let kept = select(&[level], &[(100, 100)], 2.0, &budget(8), &fast_rank);
        assert_eq!(top_left(&kept), 8);
    }

    #[test]
    fn geometric_budget_keeps_each_levels_share() {
        // Level 0 has 100 strong keypoints, level 1 has 100 weak ones: the global cut takes level 0
        // only, the geometric one gives level 1 its third (factor 2, 2 levels: 67 and 33).
        let level0: Vec<KeyPoint> = (0..100).map(|i| scored((i % 10) as f32, (i / 10) as f32, 90.0)).collect();
        let level1: Vec<KeyPoint> = (0..100).map(|i| scored((i % 10) as f32, (i / 10) as f32, 10.0)).collect();
        let per_level = [level0, level1];
        let sizes = [(100, 100), (50, 50)];
        let count = |s: &[LevelKeypoint], l| s.iter().filter(|k| k.level == l).count();
        let global = DetectorConfig {
            level_budget: LevelBudget::Global,
            ..budget(100)
        };
        let global = select(&per_level, &sizes, 2.0, &global, &fast_rank);
        assert_eq!((count(&global, 0), count(&global, 1)), (100, 0));
        let geometric = DetectorConfig {
            level_budget: LevelBudget::Geometric,
            ..budget(100)
        };
        let kept = select(&per_level, &sizes, 2.0, &geometric, &fast_rank);
        assert_eq!((count(&kept, 0), count(&kept, 1)), (67, 33));
        // A level short of keypoints leaves its share to the strongest of the others.
        let short = [per_level[0].clone(), per_level[1][..10].to_vec()];
        let kept = select(&short, &sizes, 2.0, &geometric, &fast_rank);
        assert_eq!((count(&kept, 0), count(&kept, 1)), (90, 10));
    }

    #[test]
    fn selection_is_by_score_then_level_then_raster_order() {
        let kp = |x: f32, y: f32, score: f32| KeyPoint {
            response: score,
            ..KeyPoint::new(x, y)
        };
        let per_level = vec![
            vec![kp(50.0, 60.0, 90.0), kp(70.0, 50.0, 40.0)],
            vec![kp(60.0, 60.0, 90.0), kp(55.0, 55.0, 40.0)],
            vec![kp(50.0, 50.0, 95.0)],
        ];
        let selected = select(&per_level, &[(100, 100); 3], 2.0, &budget(4), &fast_rank);
        let got: Vec<(usize, f32, f32)> = selected
            .iter()
            .map(|k| (k.level, k.keypoint.x, k.keypoint.y))
            .collect();
        assert_eq!(
            got,
            vec![
                (2, 50.0, 50.0),
                (0, 50.0, 60.0),
                (1, 60.0, 60.0),
                (0, 70.0, 50.0)
            ]
        );
        assert_eq!(of_level(&selected, 1), vec![kp(60.0, 60.0, 90.0)]);
    }

    #[test]
    fn each_level_keeps_a_prefix_of_its_own_list() {
        // The global cut keeps, on every level, the first k of that level's list (what a device-side
        // merge could rely on: count per level, no reordering within a level).
        let mut rng = crate::synthetic::SplitMix64::new(3);
        for round in 0..200 {
            let per_level: Vec<Vec<KeyPoint>> = (0..1 + rng.below(5))
                .map(|_| {
                    let mut kps: Vec<KeyPoint> = (0..rng.below(40))
                        .map(|_| KeyPoint {
                            response: (1 + rng.below(4)) as f32,
                            ..KeyPoint::new(rng.below(50) as f32, rng.below(50) as f32)
                        })
                        .collect();
                    kps.sort_by_key(|k| (-(k.response as i32), k.y as u32, k.x as u32));
                    kps
                })
                .collect();
            let max = 1 + rng.below(60) as usize;
            let selected = select(&per_level, &[(50, 50); 5], 2.0, &budget(max), &fast_rank);
            let total: usize = per_level.iter().map(Vec::len).sum();
            assert_eq!(selected.len(), max.min(total));
            for (l, list) in per_level.iter().enumerate() {
                let kept = of_level(&selected, l);
                assert_eq!(kept[..], list[..kept.len()], "round {round}, level {l}");
            }
        }
    }
}
