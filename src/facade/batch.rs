//! Many images in one call.

use super::Extractor;
use super::in_flight::{Queued, STREAMS, run_in_order, streams};
use crate::backend::Backend;
use crate::cuda;
use crate::error::Result;
use crate::features::Features;
use crate::gray_view::GrayView;
use crate::parallel::*;

impl Extractor {
    /// [`Extractor::detect_and_describe`] of every image, in input order (each result equal to its
    /// own call). Every image is checked before any work. `done(i)` is called as image `i` finishes
    /// (in any order on the CPU, in input order on the GPU), e.g. for progress.
    ///
    /// The CPU backend spreads the images over its threads (each image's own work is parallel too);
    /// the CUDA backend keeps several streams busy, each image's upload and kernels queued while
    /// earlier images finish.
    ///
    /// ```
    /// use clatch::{Backend, Extractor, ExtractorConfig, GrayView};
    ///
    /// let a = clatch::synthetic::rectangles(320, 240, 1)?;
    /// let b = clatch::synthetic::rectangles(200, 300, 2)?;
    /// let images = [GrayView::new(&a, 320, 240, 320)?, GrayView::new(&b, 200, 300, 200)?];
    /// let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
    /// let all = extractor.detect_and_describe_batch(&images, &|_| {})?;
    /// assert_eq!(all[1], extractor.detect_and_describe(&images[1])?);
    /// # Ok::<(), clatch::Error>(())
    /// ```
    pub fn detect_and_describe_batch(
        &self,
        images: &[GrayView],
        done: &(dyn Fn(usize) + Sync),
    ) -> Result<Vec<Features>> {
        for image in images {
            Self::check_image(image)?;
        }
        match self.backend() {
            Backend::Cpu => images
                .par_iter()
                .enumerate()
                .map(|(i, image)| {
                    let features = self.detect_and_describe(image);
                    done(i);
                    features
                })
                .collect(),
            Backend::Cuda { device } => {
                let streams = streams(device)?;
                run_in_order(
                    images.len(),
                    |i| {
                        self.detect_and_describe_async(&streams[i % STREAMS], &images[i])
                            .map(Queued::Pending)
                    },
                    cuda::PendingFeatures::wait,
                    done,
                )
            }
        }
    }
}
