//! The pairs of a folder's photos: which are matched (every pair, or a given list by index or name,
//! checked before any work), and the matching of any subset of them.

use std::collections::{BTreeMap, HashMap};

use crate::colmap::error::ColmapError;
use crate::descriptor::DescriptorSet;
use crate::matcher::Matcher;
use crate::matching::Match;

/// A photo of a folder in a pair list: its index (in name order, as [`super::ImageFolder`] lists
/// them) or its name in the database (its file name).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum PhotoRef {
    /// Index in the folder's name order.
    Index(usize),
    /// File name.
    Name(String),
}

impl From<usize> for PhotoRef {
    fn from(index: usize) -> Self {
        PhotoRef::Index(index)
    }
}

impl From<&str> for PhotoRef {
    fn from(name: &str) -> Self {
        PhotoRef::Name(name.to_owned())
    }
}

impl From<String> for PhotoRef {
    fn from(name: String) -> Self {
        PhotoRef::Name(name)
    }
}

/// The pairs to match, as photo indices: with `given` `None`, every pair `(i, j)`, `i < j`, in order
/// ([`Matcher::all_pairs`]); else the given pairs in their order (`(a, b)` matches `a`'s keypoints as
/// queries against `b`'s), each photo found among `names` by index or name, each pair of two different
/// photos and each unordered pair once.
///
/// ```
/// use clatch::colmap::{PhotoRef, resolve_pairs};
///
/// let names = ["a.jpg".to_owned(), "b.jpg".to_owned(), "c.jpg".to_owned()];
/// assert_eq!(resolve_pairs(None, &names)?, [(0, 1), (0, 2), (1, 2)]);
/// let given = [(PhotoRef::from(2), PhotoRef::from("a.jpg"))];
/// assert_eq!(resolve_pairs(Some(&given), &names)?, [(2, 0)]);
/// let twice = [(PhotoRef::from(0), PhotoRef::from(1)), (PhotoRef::from(1), PhotoRef::from(0))];
/// assert!(resolve_pairs(Some(&twice), &names).is_err());
/// # Ok::<(), clatch::colmap::ColmapError>(())
/// ```
pub fn resolve_pairs(
    given: Option<&[(PhotoRef, PhotoRef)]>,
    names: &[String],
) -> Result<Vec<(usize, usize)>, ColmapError> {
    let Some(given) = given else {
        return Ok(Matcher::all_pairs(names.len()));
    };
    let index: HashMap<&str, usize> = names
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i))
        .collect();
    let photo = |position: usize, photo: &PhotoRef| match photo {
        PhotoRef::Index(i) if *i < names.len() => Ok(*i),
        PhotoRef::Index(i) => Err(ColmapError::PairOutOfRange {
            position,
            index: *i,
            photos: names.len(),
        }),
        PhotoRef::Name(name) => {
            index
                .get(name.as_str())
                .copied()
                .ok_or_else(|| ColmapError::PairNameUnknown {
                    position,
                    name: name.clone(),
                })
        }
    };
    let mut seen: HashMap<(usize, usize), usize> = HashMap::with_capacity(given.len());
    let mut pairs = Vec::with_capacity(given.len());
    for (position, (a, b)) in given.iter().enumerate() {
        let (i, j) = (photo(position, a)?, photo(position, b)?);
        if i == j {
            return Err(ColmapError::PairOfOnePhoto {
                position,
                name: names[i].clone(),
            });
        }
        if let Some(&earlier) = seen.get(&(i.min(j), i.max(j))) {
            return Err(ColmapError::DuplicatePair {
                position,
                earlier,
                first: names[i].clone(),
                second: names[j].clone(),
            });
        }
        seen.insert((i.min(j), i.max(j)), position);
        pairs.push((i, j));
    }
    Ok(pairs)
}

/// The matches of each of `pairs` (photo indices; `(i, j)` matches `i`'s descriptors as queries
/// against `j`'s), in order, with `descriptors(i)` photo `i`'s descriptors: the library's many-pairs
/// matching handed only the sets these pairs name. A pair's matches do not depend on which other
/// pairs are matched with it, so any subset of a folder's pairs, matched wherever its photos'
/// descriptors are (a worker of a cluster), gives the matches of the whole run.
pub fn match_photo_pairs<'a>(
    matcher: &Matcher,
    descriptors: impl Fn(usize) -> Option<&'a DescriptorSet>,
    pairs: &[(usize, usize)],
) -> Result<Vec<Vec<Match>>, ColmapError> {
    let mut local: BTreeMap<usize, usize> = BTreeMap::new();
    let mut sets: Vec<&DescriptorSet> = Vec::new();
    let mut local_pairs = Vec::with_capacity(pairs.len());
    for (position, &(i, j)) in pairs.iter().enumerate() {
        let mut slot = |image: usize| -> Result<usize, ColmapError> {
            if let Some(&k) = local.get(&image) {
                return Ok(k);
            }
            let set =
                descriptors(image).ok_or(ColmapError::MissingDescriptors { position, image })?;
            sets.push(set);
            local.insert(image, sets.len() - 1);
            Ok(sets.len() - 1)
        };
        local_pairs.push((slot(i)?, slot(j)?));
    }
    Ok(matcher.match_pairs(&sets, &local_pairs)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: usize) -> Vec<String> {
        (0..n).map(|i| format!("view{i}.png")).collect()
    }

    #[test]
    fn given_pairs_are_checked_with_their_position() {
        let check = |given: &[(PhotoRef, PhotoRef)]| resolve_pairs(Some(given), &names(4));
        let e = check(&[(0.into(), 1.into()), (3.into(), 4.into())]).unwrap_err();
        assert!(
            matches!(
                e,
                ColmapError::PairOutOfRange {
                    position: 1,
                    index: 4,
                    photos: 4
                }
            ),
            "{e}"
        );
        let e = check(&[("view2.png".into(), 2.into())]).unwrap_err();
        assert!(
            matches!(e, ColmapError::PairOfOnePhoto { position: 0, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("view2.png"), "{e}");
        let e = check(&[
            (1.into(), 2.into()),
            (0.into(), 3.into()),
            (2.into(), 1.into()),
        ])
        .unwrap_err();
        assert!(
            matches!(
                e,
                ColmapError::DuplicatePair {
                    position: 2,
                    earlier: 0,
                    ..
                }
            ),
            "{e}"
        );
        let e = check(&[("view0.png".into(), "nope.png".into())]).unwrap_err();
        assert!(e.to_string().contains("not an image of the folder"), "{e}");
        assert_eq!(
            check(&[(3.into(), "view0.png".into()), (1.into(), 2.into())]).unwrap(),
            [(3, 0), (1, 2)]
        );
        assert_eq!(resolve_pairs(Some(&[]), &names(3)).unwrap(), []);
    }

    #[test]
    fn a_subset_of_pairs_gives_the_matches_of_the_whole_run() {
        let width = crate::DescriptorWidth::from_bits(64).unwrap();
        let sets: Vec<DescriptorSet> = (0..4u64)
            .map(|seed| {
                let words = (0..60u64)
                    .map(|i| (i * 7 + seed % 2).wrapping_mul(0x9E37_79B9_7F4A_7C15))
                    .collect();
                DescriptorSet::from_words(width, words).unwrap()
            })
            .collect();
        let matcher = Matcher::new(crate::Backend::Cpu, crate::MatchConfig::default()).unwrap();
        let pairs = Matcher::all_pairs(4);
        let all = match_photo_pairs(&matcher, |i| sets.get(i), &pairs).unwrap();
        assert!(
            all.iter().any(|m| !m.is_empty()),
            "the sets match somewhere"
        );
        // Only photos 1 and 3 are held here.
        let held = |i: usize| [1, 3].contains(&i).then(|| &sets[i]);
        assert_eq!(match_photo_pairs(&matcher, held, &[(3, 1)]).unwrap()[0], {
            matcher.match_descriptors(&sets[3], &sets[1]).unwrap()
        });
        assert_eq!(
            match_photo_pairs(&matcher, held, &[(1, 3)]).unwrap()[0],
            all[4]
        );
        let e = match_photo_pairs(&matcher, held, &[(1, 3), (0, 1)]).unwrap_err();
        assert!(
            matches!(
                e,
                ColmapError::MissingDescriptors {
                    position: 1,
                    image: 0
                }
            ),
            "{e}"
        );
    }
}
