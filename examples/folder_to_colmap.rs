//! A folder of photos → a COLMAP 3.8 database and a match list for `colmap matches_importer`.
//!
//! ```sh
//! cargo run --release --features image,colmap --example folder_to_colmap -- photos/ out.db matches.txt
//! colmap matches_importer --database_path out.db --match_list_path matches.txt --match_type raw
//! colmap mapper --database_path out.db --image_path photos/ --output_path sparse/
//! ```
//!
//! One call of the library's folder run, [`FolderJob::run`], the one `clatch colmap` and the Python
//! package run: every photo checked before any work, extracted with the settings for structure from
//! motion (8192 keypoints spread over an 8 x 8 grid, sub-pixel positions), every pair matched with
//! the ratio test and the cross-check, one camera per image size and EXIF focal length, both files
//! written under temporary names and put in place once complete. The pairs are left for COLMAP to
//! verify ([`FolderJob::without_verification`]); by default the library verifies them itself and
//! writes no match list (`clatch colmap`, then `colmap mapper` alone).

use std::error::Error;
use std::ops::ControlFlow;

use clatch::Backend;
use clatch::colmap::{FolderJob, FolderProgress};

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dir, database, match_list] = args.as_slice() else {
        return Err("usage: folder_to_colmap IMAGE_DIR DATABASE MATCH_LIST".into());
    };
    let backend = Backend::auto();
    let job = FolderJob::new(dir, database)
        .without_verification()
        .with_match_list(match_list)
        .with_backend(backend);
    let mut progress = |p: FolderProgress| {
        if p.done == p.total {
            println!("{}: {} done", p.stage, p.total);
        }
        ControlFlow::Continue(())
    };
    let report = job.run(Some(&mut progress))?;
    println!(
        "{} images, {} keypoints, {} matches over {} pairs on {backend}: {}, {}",
        report.counts.photos,
        report.counts.keypoints,
        report.counts.matches,
        report.counts.pairs,
        report.database.display(),
        match_list
    );
    Ok(())
}
