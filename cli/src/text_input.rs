//! Reading the small text inputs (homography, camera matrix): regular files only, with a size limit,
//! a UTF-8 byte-order mark skipped.

use std::io::Read;
use std::path::Path;

use clatch::homography::Homography;

use crate::error::CliError;

/// Largest text input: a 3x3 matrix, even as OpenCV XML with comments, is far smaller.
pub const MAX_TEXT_BYTES: u64 = 64 * 1024;

/// The UTF-8 byte-order mark some editors write at the start of a file.
const BOM: char = '\u{feff}';

/// The content of the text file `path` (a `what` file, for the message), without a leading BOM.
pub fn read_text(path: &Path, what: &'static str) -> Result<String, CliError> {
    let read_err = |source| CliError::Read {
        path: path.to_path_buf(),
        source,
    };
    let meta = std::fs::metadata(path).map_err(read_err)?;
    if !meta.is_file() {
        return Err(CliError::NotAFile {
            path: path.to_path_buf(),
            kind: clatch::decode::file_kind(&meta),
        });
    }
    let file = std::fs::File::open(path).map_err(read_err)?;
    let mut bytes = Vec::new();
    file.take(MAX_TEXT_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(read_err)?;
    if bytes.len() as u64 > MAX_TEXT_BYTES {
        return Err(CliError::TextTooLarge {
            path: path.to_path_buf(),
            max: MAX_TEXT_BYTES,
            what,
        });
    }
    let text = String::from_utf8(bytes)
        .map_err(|e| read_err(std::io::Error::new(std::io::ErrorKind::InvalidData, e)))?;
    Ok(text.strip_prefix(BOM).map(str::to_owned).unwrap_or(text))
}

/// A homography file: nine numbers (the Oxford format) or OpenCV FileStorage XML, read as
/// [`read_text`] reads and parsed by the library.
pub fn read_homography(path: &Path) -> Result<Homography, CliError> {
    read_text(path, "homography")?
        .parse()
        .map_err(
            |e: clatch::homography::ParseHomographyError| CliError::Homography {
                path: path.to_path_buf(),
                reason: e.to_string(),
            },
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(dir: &crate::test_dir::TestDir, name: &str) -> std::path::PathBuf {
        dir.join(name)
    }

    #[test]
    fn homography_files_of_both_formats_are_read_and_bad_ones_named() {
        let dir = crate::test_dir::TestDir::new("text-homography");
        let (xml, txt, bad) = (dir.join("h.xml"), dir.join("H1to3p"), dir.join("bad"));
        std::fs::write(
            &xml,
            "<?xml version=\"1.0\"?>\n<opencv_storage><H13 type_id=\"opencv-matrix\">\
             <rows>3</rows><cols>3</cols><dt>d</dt><data>2. 0. 15. 0. 2. -4. 0. 0. 1.</data>\
             </H13></opencv_storage>\n",
        )
        .unwrap();
        std::fs::write(&txt, "2 0 15\n0 2 -4\n0 0 1\n").unwrap();
        std::fs::write(&bad, "<opencv_storage><rows>3</rows></opencv_storage>").unwrap();
        let from_xml = read_homography(&xml).unwrap();
        assert_eq!(from_xml, read_homography(&txt).unwrap());
        assert_eq!(from_xml.apply(1.0, 3.0), Some((17.0, 2.0)));
        let e = read_homography(&bad).unwrap_err();
        assert!(matches!(e, CliError::Homography { .. }), "{e}");
        assert!(e.to_string().contains("bad"), "{e}");
        let e = read_homography(&dir.join("missing")).unwrap_err();
        assert!(matches!(e, CliError::Read { .. }), "{e}");
    }

    #[test]
    fn a_bom_is_skipped() {
        let dir = crate::test_dir::TestDir::new("text-bom");
        let path = temp(&dir, "bom.txt");
        std::fs::write(&path, "\u{feff}1 0 0").unwrap();
        assert_eq!(read_text(&path, "homography").unwrap(), "1 0 0");
    }

    #[test]
    fn oversized_and_special_files_are_refused_without_reading_them_whole() {
        let dir = crate::test_dir::TestDir::new("text-big");
        let path = temp(&dir, "big.txt");
        std::fs::write(&path, vec![b' '; MAX_TEXT_BYTES as usize + 1]).unwrap();
        assert!(matches!(
            read_text(&path, "homography"),
            Err(CliError::TextTooLarge { .. })
        ));
        std::fs::write(&path, vec![b' '; MAX_TEXT_BYTES as usize]).unwrap();
        assert!(read_text(&path, "homography").is_ok());
        #[cfg(unix)]
        {
            let e = read_text(Path::new("/dev/zero"), "homography").unwrap_err();
            assert!(
                matches!(
                    e,
                    CliError::NotAFile {
                        kind: "a device",
                        ..
                    }
                ),
                "{e}"
            );
            let fifo = temp(&dir, "pipe");
            std::fs::remove_file(&fifo).ok();
            assert!(
                std::process::Command::new("mkfifo")
                    .arg(&fifo)
                    .status()
                    .unwrap()
                    .success()
            );
            let e = read_text(&fifo, "camera matrix").unwrap_err();
            assert!(
                matches!(e, CliError::NotAFile { kind: "a FIFO", .. }),
                "{e}"
            );
        }
    }
}
