//! The COLMAP folder run on the GPU: `FolderJob` on `Backend::Cuda` (extraction, matching, and the
//! verification and guided matching it does by default, verification on the device through
//! `Verifier`) writes the same database, byte for byte, as on the CPU.

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_folder")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![Trial::test(
        "verified_folder_equals_the_cpus",
        gpu::verified_folder,
    )]
}

#[cfg(feature = "cuda")]
mod gpu {
    use std::path::{Path, PathBuf};

    use clatch::Backend;
    use clatch::colmap::FolderJob;
    use libtest_mimic::Failed;

    use super::common::{astronaut, scale};

    /// A fresh folder with `images/` holding overlapping crops of the embedded photograph (binary
    /// PGM), shifted and of two sizes, so that pairs overlap by different amounts.
    fn folder(name: &str, photos: usize) -> Result<PathBuf, Failed> {
        let dir =
            std::env::temp_dir().join(format!("clatch-cuda-folder-{}-{name}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        let images = dir.join("images");
        std::fs::create_dir_all(&images)?;
        let photo = astronaut();
        for i in 0..photos {
            let side = if i % 2 == 0 { 360 } else { 320 };
            let (x0, y0) = (
                i * 23 % (photo.width - side),
                i * 31 % (photo.height - side),
            );
            let mut pgm = format!("P5\n{side} {side}\n255\n").into_bytes();
            for y in y0..y0 + side {
                pgm.extend_from_slice(
                    &photo.pixels[y * photo.width + x0..y * photo.width + x0 + side],
                );
            }
            std::fs::write(images.join(format!("view{i}.pgm")), pgm)?;
        }
        Ok(dir)
    }

    /// The database a default folder job writes on `backend`, and the share of pairs it verified.
    fn run(dir: &Path, backend: Backend, db: &str) -> Result<(Vec<u8>, String), Failed> {
        let report = FolderJob::new(dir.join("images"), dir.join(db))
            .with_backend(backend)
            .with_workspace(dir.join(format!("{db}-colmap")))
            .run(None)?;
        let counts = format!("{:?}", report.counts);
        Ok((std::fs::read(&report.database)?, counts))
    }

    pub fn verified_folder() -> Result<(), Failed> {
        let dir = folder("verified", scale::pick(6, 3))?;
        let job = FolderJob::new(dir.join("images"), dir.join("x.db"));
        if job.verification.is_none() || !job.guided_matching {
            return Err(
                "the default job no longer verifies and matches again under the geometry".into(),
            );
        }
        let (cpu, counts) = run(&dir, Backend::Cpu, "cpu.db")?;
        let (gpu, _) = run(&dir, Backend::Cuda { device: 0 }, "gpu.db")?;
        std::fs::remove_dir_all(&dir).ok();
        if cpu != gpu {
            return Err(format!(
                "the GPU's database ({} bytes) differs from the CPU's ({} bytes)",
                gpu.len(),
                cpu.len()
            )
            .into());
        }
        println!(
            "default folder job ({counts}): the GPU's database equals the CPU's, {} bytes",
            cpu.len()
        );
        Ok(())
    }
}
