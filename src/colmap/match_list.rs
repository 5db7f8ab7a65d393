//! The text file of putative matches that `colmap matches_importer --match_type raw` reads.

use std::io::Write;

use crate::colmap::error::ColmapError;
use crate::matching::Match;

/// Writes COLMAP's match list: for each pair a line `NAME1 NAME2`, one line `i1 i2` per match (keypoint
/// indices in NAME1 and NAME2, in the order the keypoints were written to the database), then an
/// empty line. Names are separated by a space, so they may hold none.
///
/// ```
/// use clatch::Match;
/// use clatch::colmap::MatchList;
///
/// let mut list = MatchList::new(Vec::new());
/// list.add_pair("a.jpg", "b.jpg", &[Match { query: 3, train: 7, distance: 40 }])?;
/// assert_eq!(String::from_utf8(list.into_inner()?).unwrap(), "a.jpg b.jpg\n3 7\n\n");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct MatchList<W: Write> {
    out: W,
}

impl<W: Write> MatchList<W> {
    /// A match list written to `out`.
    pub fn new(out: W) -> Self {
        Self { out }
    }

    /// Appends the matches of one pair; `query` indexes `name1`'s keypoints, `train` `name2`'s.
    pub fn add_pair(
        &mut self,
        name1: &str,
        name2: &str,
        matches: &[Match],
    ) -> Result<(), ColmapError> {
        for name in [name1, name2] {
            if name.is_empty() || name.chars().any(char::is_whitespace) {
                return Err(ColmapError::InvalidImageName {
                    name: name.into(),
                    reason: "a match list name must be non-empty and hold no whitespace",
                });
            }
        }
        if name1 == name2 {
            return Err(ColmapError::InvalidImageName {
                name: name1.into(),
                reason: "a pair needs two different images",
            });
        }
        let mut write = || -> std::io::Result<()> {
            writeln!(self.out, "{name1} {name2}")?;
            for m in matches {
                writeln!(self.out, "{} {}", m.query, m.train)?;
            }
            writeln!(self.out)
        };
        write().map_err(ColmapError::MatchListIo)
    }

    /// Flushes and returns the writer.
    pub fn into_inner(mut self) -> Result<W, ColmapError> {
        self.out.flush().map_err(ColmapError::MatchListIo)?;
        Ok(self.out)
    }
}
