//! `clatch match A B`: match two image files, optionally check against a homography, draw, export.

use std::io::Write;
use std::path::Path;

use clatch::{KeyPoint, Match};

use crate::draw::{MatchClass, check_picture_path, draw_matches, stage_picture};
use crate::error::CliError;
use crate::input::{check_detectable, load_gray};
use crate::pipeline;
use crate::progress::Progress;
use crate::report;
use crate::text_input::read_homography;
use crate::{MatchArgs, settings};
use clatch::output::{Staged, check_distinct, check_writable};

/// Writes matches as CSV: `query,train,distance,xq,yq,xt,yt`.
pub fn write_matches_csv(
    mut w: impl Write,
    matches: &[Match],
    query: &[KeyPoint],
    train: &[KeyPoint],
) -> std::io::Result<()> {
    writeln!(w, "query,train,distance,xq,yq,xt,yt")?;
    for m in matches {
        let (q, t) = (&query[m.query as usize], &train[m.train as usize]);
        writeln!(
            w,
            "{},{},{},{},{},{},{}",
            m.query, m.train, m.distance, q.x, q.y, t.x, t.y
        )?;
    }
    w.flush()
}

/// Runs `clatch match`.
pub fn main(args: &MatchArgs) -> Result<(), CliError> {
    let subpixel = args.subpixel.library();
    let settings = settings(&args.backend, &args.detect, subpixel, Some(&args.matching))?;
    check_picture_path(&args.output)?;
    check_paths(args)?;
    // Read the cheap inputs first, so a bad homography file fails before any work.
    let homography = args
        .homography
        .as_deref()
        .map(read_homography)
        .transpose()?;

    let progress = Progress::new(2 + pipeline::PAIR_STAGES + 1);
    progress.stage("reading images");
    let limits = args.input.limits();
    let img_a = load_gray(&args.image_a, &limits)?;
    check_detectable(&args.image_a, img_a.width(), img_a.height())?;
    progress.done();
    let img_b = load_gray(&args.image_b, &limits)?;
    check_detectable(&args.image_b, img_b.width(), img_b.height())?;
    progress.done();

    let run = pipeline::match_pair(
        &settings,
        (&img_a, &args.image_a),
        (&img_b, &args.image_b),
        &progress,
    )?;
    let (kps_a, kps_b) = (&run.a.features.keypoints, &run.b.features.keypoints);
    for (path, img, n) in [
        (&args.image_a, &img_a, kps_a.len()),
        (&args.image_b, &img_b, kps_b.len()),
    ] {
        crate::input::warn_if_no_keypoints(path, img.dimensions(), n, &settings.extractor);
    }
    let evaluation = homography
        .as_ref()
        .map(|h| report::evaluate(&run.matches, kps_a, kps_b, h, args.check.inlier_px));

    progress.stage("writing results");
    let classes = match &evaluation {
        Some(e) => e.classes.clone(),
        None => vec![MatchClass::Unchecked; run.matches.len()],
    };
    let picture = draw_matches(
        &img_a,
        &img_b,
        kps_a,
        kps_b,
        &run.matches,
        &classes,
        args.draw.max_lines,
    );
    // The picture and the CSV are both complete before either replaces an older file.
    let mut staged = Staged::new();
    stage_picture(&mut staged, &picture, &args.output)?;
    if let Some(path) = &args.matches_csv {
        staged.write(path, |w| write_matches_csv(w, &run.matches, kps_a, kps_b))?;
    }
    staged.commit()?;
    progress.done();
    progress.finish();

    println!("clatch match");
    println!("  image A     {}", args.image_a.display());
    println!("  image B     {}", args.image_b.display());
    if let Some(path) = &args.homography {
        println!("  homography  {} (maps A to B)", path.display());
    }
    print!(
        "{}",
        report::pair_summary(
            &run,
            [img_a.dimensions(), img_b.dimensions()],
            &settings.matching,
            evaluation.as_ref(),
        )
    );
    let legend = if evaluation.is_some() {
        "inliers green, outliers red"
    } else {
        "matches yellow"
    };
    println!(
        "{}",
        report::picture_written(
            &args.output,
            picture.dimensions(),
            run.matches.len(),
            args.draw.max_lines,
            legend,
        )
    );
    if let Some(path) = &args.matches_csv {
        println!(
            "  wrote       {} ({} matches)",
            path.display(),
            run.matches.len()
        );
    }
    Ok(())
}

/// Refuses outputs that name an input or each other, before any work.
fn check_paths(args: &MatchArgs) -> Result<(), CliError> {
    let mut inputs: Vec<(&'static str, &Path)> =
        vec![("image A", &args.image_a), ("image B", &args.image_b)];
    if let Some(h) = &args.homography {
        inputs.push(("homography", h));
    }
    let mut outputs: Vec<(&'static str, &Path)> = vec![("picture", &args.output)];
    if let Some(csv) = &args.matches_csv {
        check_writable(csv)?;
        outputs.push(("matches CSV", csv));
    }
    Ok(check_distinct(&inputs, &outputs)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_rows() {
        let q = [KeyPoint::new(1.0, 2.0), KeyPoint::new(3.0, 4.5)];
        let t = [KeyPoint::new(7.0, 8.0)];
        let m = [Match {
            query: 1,
            train: 0,
            distance: 17,
        }];
        let mut out = Vec::new();
        write_matches_csv(&mut out, &m, &q, &t).unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "query,train,distance,xq,yq,xt,yt\n1,0,17,3,4.5,7,8\n"
        );
    }
}
