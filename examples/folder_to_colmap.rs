//! A folder of photos → a COLMAP 3.8 database and a match list for `colmap matches_importer`.
//!
//! ```sh
//! cargo run --release --features image,colmap --example folder_to_colmap -- photos/ out.db matches.txt
//! colmap matches_importer --database_path out.db --match_list_path matches.txt --match_type raw
//! colmap mapper --database_path out.db --image_path photos/ --output_path sparse/
//! ```
//!
//! Every image gets COLMAP's own focal-length guess (the mapper refines it); every pair is matched
//! with the ratio test and the cross-check. The `clatch colmap` command does the same with more
//! options (a known K, EXIF focal lengths, spreading keypoints over a grid, progress).

use std::error::Error;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use clatch::colmap::{Database, MatchList, PinholeCamera};
use clatch::{Backend, Extractor, ExtractorConfig, Features, GrayView, MatchConfig, Matcher};

/// The photos of `dir` (PNG, JPEG, PNM), in name order.
fn photos(dir: &Path) -> Result<Vec<PathBuf>, Box<dyn Error>> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
                ["png", "jpg", "jpeg", "pgm", "ppm"].contains(&e.to_lowercase().as_str())
            })
        })
        .collect();
    paths.sort();
    Ok(paths)
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dir, database, match_list] = args.as_slice() else {
        return Err("usage: folder_to_colmap IMAGE_DIR DATABASE MATCH_LIST".into());
    };
    let backend = Backend::auto();
    let extractor = Extractor::new(backend, ExtractorConfig::default())?;
    let matcher = Matcher::new(backend, MatchConfig::default())?;
    let mut db = Database::create(Path::new(database))?;

    let mut images: Vec<(u32, String, Features)> = Vec::new();
    for path in photos(Path::new(dir))? {
        let decoded = image::open(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let gray = clatch::decode::gray_from_dynamic(&decoded);
        let features = extractor.detect_and_describe(&GrayView::try_from(&gray)?)?;
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .ok_or_else(|| format!("{}: the name is not UTF-8", path.display()))?
            .to_string();
        let camera = db.add_camera(&PinholeCamera::guess(gray.width(), gray.height())?)?;
        let image_id = db.add_image(&name, camera)?;
        db.set_keypoints(image_id, &features.keypoints)?;
        println!("{name}: {} keypoints", features.len());
        images.push((image_id, name, features));
    }

    let mut list = MatchList::new(BufWriter::new(File::create(match_list)?));
    let mut pairs = 0;
    for (i, (id_a, name_a, a)) in images.iter().enumerate() {
        for (id_b, name_b, b) in &images[i + 1..] {
            if a.is_empty() || b.len() < 2 {
                continue;
            }
            let matches = matcher.match_descriptors(&a.descriptors, &b.descriptors)?;
            db.add_matches(*id_a, *id_b, &matches)?;
            list.add_pair(name_a, name_b, &matches)?;
            pairs += 1;
        }
    }
    list.into_inner()?;
    db.finish()?;
    println!(
        "{} images, {pairs} pairs matched on {backend}: {database}, {match_list}",
        images.len()
    );
    Ok(())
}
