//! The pairs of one run: OpenCV's sample, the sequences under `--data` and the synthetic pairs, with
//! names checked unique.

use std::path::PathBuf;

use crate::EvalArgs;
use crate::error::EvalError;
use crate::pairs::{self, EvalPair, GROUP_OPENCV_SAMPLE};
use crate::sequences;

/// The pair whose figures head the report: OpenCV's graf1/graf3 if given, else Oxford graf 1-3.
pub fn headline(pairs: &[EvalPair]) -> Option<&EvalPair> {
    let by_group = pairs.iter().find(|p| p.group == GROUP_OPENCV_SAMPLE);
    by_group.or_else(|| pairs.iter().find(|p| p.name == "graf 1-3"))
}

/// Every pair this run evaluates; synthetic images are written under `out/pairs`.
pub fn collect_pairs(args: &EvalArgs) -> Result<(Vec<EvalPair>, Vec<String>), EvalError> {
    let mut pairs = Vec::new();
    let mut notes = Vec::new();
    if let Some(dir) = &args.opencv_samples {
        pairs.push(pairs::opencv_sample_pair(dir)?);
    }
    for data in &args.data {
        let (found, skipped) = sequences::sequences_under(data)?;
        pairs.extend(found);
        notes.extend(skipped.into_iter().map(|d| {
            format!(
                "skipped {}: no img1.* or 1.* (not a sequence folder)",
                d.display()
            )
        }));
    }
    if !args.no_synthetic {
        let mut sources = vec![pairs::SyntheticSource {
            name: "astronaut".into(),
            image: clatch_cli::photo::embedded_photo().map_err(EvalError::Embedded)?,
        }];
        for arg in &args.synthetic_images {
            sources.push(pairs::synthetic_source(arg)?);
        }
        for (i, s) in sources.iter().enumerate() {
            if sources[..i].iter().any(|t| t.name == s.name) {
                return Err(EvalError::Input {
                    path: PathBuf::from(&s.name),
                    reason: "two synthetic sources share this name; give one as NAME=PATH".into(),
                });
            }
        }
        let dir = args.out.join("pairs");
        for source in &sources {
            pairs.extend(pairs::write_synthetic(source, &dir)?);
        }
    }
    if let Some(twice) = repeated_name(&pairs) {
        return Err(EvalError::Input {
            path: twice.image_a.clone(),
            reason: format!(
                "two pairs are named `{}` (two sequence folders with one name?); \
                 pair names must be unique",
                twice.name
            ),
        });
    }
    if pairs.is_empty() {
        return Err(EvalError::Input {
            path: args.out.clone(),
            reason:
                "no pairs to evaluate (give --data, --opencv-samples, or allow synthetic pairs)"
                    .into(),
        });
    }
    Ok((pairs, notes))
}

/// The first pair whose name an earlier pair already has: results are told apart by pair name.
fn repeated_name(pairs: &[EvalPair]) -> Option<&EvalPair> {
    let mut seen = std::collections::HashSet::new();
    pairs.iter().find(|p| !seen.insert(p.name.as_str()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pairs::GROUP_ROTATION;

    fn pair(name: &str, group: &str) -> EvalPair {
        EvalPair {
            name: name.into(),
            group: group.into(),
            param: None,
            image_a: "a".into(),
            image_b: "b".into(),
            homography: "h".into(),
        }
    }

    #[test]
    fn headline_prefers_the_opencv_sample() {
        let oxford = pair("graf 1-3", "oxford-graf");
        let sample = pair("opencv graf1-graf3", GROUP_OPENCV_SAMPLE);
        assert_eq!(headline(std::slice::from_ref(&oxford)), Some(&oxford));
        assert_eq!(headline(&[oxford, sample.clone()]), Some(&sample));
        assert_eq!(headline(&[pair("x", GROUP_ROTATION)]), None);
    }
}
