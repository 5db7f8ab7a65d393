//! Many images in one call: a slice, or a stream of images produced while earlier ones are worked on.

use std::collections::VecDeque;

use super::Extractor;
use crate::backend::Backend;
use crate::cuda::{GpuStream, ImageLife, PendingFeatures};
use crate::error::{Error, Result};
use crate::features::Features;
use crate::gray_view::{AsGrayView, GrayView};
use crate::in_flight::{IN_FLIGHT_PER_STREAM, STREAMS, streams};
use crate::parallel::*;

impl Extractor {
    /// [`Extractor::detect_and_describe`] of every image, in input order (each result equal to its
    /// own call). Every image is checked before any work.
    ///
    /// The CPU backend spreads the images over its threads (each image's own work is parallel too);
    /// the CUDA backend keeps several streams busy, each image's upload and kernels queued while
    /// earlier images finish (images in page-locked memory are copied by the copy engine straight
    /// from where they are).
    ///
    /// ```
    /// use clatch::{Backend, Extractor, ExtractorConfig, GrayView};
    ///
    /// let a = clatch::synthetic::rectangles(320, 240, 1)?;
    /// let b = clatch::synthetic::rectangles(200, 300, 2)?;
    /// let images = [GrayView::new(&a, 320, 240, 320)?, GrayView::new(&b, 200, 300, 200)?];
    /// let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
    /// let all = extractor.detect_and_describe_batch(&images)?;
    /// assert_eq!(all[1], extractor.detect_and_describe(&images[1])?);
    /// # Ok::<(), clatch::Error>(())
    /// ```
    pub fn detect_and_describe_batch(&self, images: &[GrayView]) -> Result<Vec<Features>> {
        self.detect_and_describe_batch_with_progress(images, &|_| {})
    }

    /// [`Extractor::detect_and_describe_batch`], calling `progress(i)` as image `i` finishes (in any
    /// order and from any thread on the CPU, in input order on the GPU), e.g. for a progress bar.
    /// The results are the same.
    ///
    /// ```
    /// use std::sync::Mutex;
    /// use clatch::{Backend, Extractor, ExtractorConfig, GrayView};
    ///
    /// let pixels = clatch::synthetic::rectangles(160, 120, 1)?;
    /// let images = [GrayView::new(&pixels, 160, 120, 160)?; 3];
    /// let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
    /// let finished = Mutex::new(Vec::new());
    /// let all = extractor
    ///     .detect_and_describe_batch_with_progress(&images, &|i| finished.lock().unwrap().push(i))?;
    /// let mut finished = finished.into_inner().unwrap();
    /// finished.sort_unstable();
    /// assert_eq!((all.len(), finished), (3, vec![0, 1, 2]));
    /// # Ok::<(), clatch::Error>(())
    /// ```
    pub fn detect_and_describe_batch_with_progress(
        &self,
        images: &[GrayView],
        progress: &(dyn Fn(usize) + Sync),
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
                    progress(i);
                    features
                })
                .collect(),
            Backend::Cuda { device } => {
                let mut all = Vec::with_capacity(images.len());
                self.stream_on_gpu(device, images.iter().map(Ok::<_, Error>), |i, _, f| {
                    all.push(f);
                    progress(i);
                    Ok(())
                })?;
                Ok(all)
            }
        }
    }

    /// [`Extractor::detect_and_describe`] of each image `images` yields, handed to `each(i, image,
    /// features)` in input order (`i` counts from 0) together with the image itself, which this call
    /// keeps alive while it is worked on. Returns how many images there were.
    ///
    /// Images are taken from the iterator only as they are needed, so a producer that decodes files
    /// (on other threads, ahead of the consumer) overlaps decoding with the extraction of earlier
    /// images, and at most a few images are held at once: on the GPU, as many as the streams keep in
    /// flight (8); on the CPU, one per thread (worked on together). The first error, of the iterator,
    /// of an image or of `each`, stops the call and is returned (library errors converted into `E`).
    ///
    /// ```
    /// use clatch::{Backend, Extractor, ExtractorConfig};
    ///
    /// let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
    /// // "Decoding": images made one at a time as the extractor asks for them.
    /// let images = (0..3).map(|i| clatch::synthetic::rectangles(160 + 16 * i, 120, i as u64));
    /// let mut counts = Vec::new();
    /// let n = extractor.detect_and_describe_stream(
    ///     images.map(|pixels| Ok::<_, clatch::Error>(Frame(pixels?, 0))),
    ///     |i, frame, features| {
    ///         counts.push((i, features.keypoints.len()));
    ///         Ok(())
    ///     },
    /// )?;
    /// assert_eq!(n, 3);
    /// # struct Frame(Vec<u8>, usize);
    /// # impl clatch::AsGrayView for Frame {
    /// #     fn gray_view(&self) -> clatch::Result<clatch::GrayView<'_>> {
    /// #         clatch::GrayView::new(&self.0, self.0.len() / 120, 120, self.0.len() / 120)
    /// #     }
    /// # }
    /// # Ok::<(), clatch::Error>(())
    /// ```
    pub fn detect_and_describe_stream<T, E>(
        &self,
        images: impl IntoIterator<Item = std::result::Result<T, E>>,
        each: impl FnMut(usize, T, Features) -> std::result::Result<(), E>,
    ) -> std::result::Result<usize, E>
    where
        T: AsGrayView + Sync,
        E: From<Error>,
    {
        match self.backend() {
            Backend::Cpu => self.stream_on_cpu(images, each),
            Backend::Cuda { device } => self.stream_on_gpu(device, images, each),
        }
    }

    /// The CPU side of [`Extractor::detect_and_describe_stream`]: images in groups of one per
    /// thread, each group's images worked on together.
    fn stream_on_cpu<T, E>(
        &self,
        images: impl IntoIterator<Item = std::result::Result<T, E>>,
        mut each: impl FnMut(usize, T, Features) -> std::result::Result<(), E>,
    ) -> std::result::Result<usize, E>
    where
        T: AsGrayView + Sync,
        E: From<Error>,
    {
        let group = crate::parallel::threads().max(1);
        let mut images = images.into_iter();
        let mut next = 0;
        loop {
            let items = images
                .by_ref()
                .take(group)
                .collect::<std::result::Result<Vec<T>, E>>()?;
            if items.is_empty() {
                return Ok(next);
            }
            let features: Vec<Result<Features>> = items
                .par_iter()
                .map(|item| self.detect_and_describe(&item.gray_view()?))
                .collect();
            for (item, features) in items.into_iter().zip(features) {
                each(next, item, features?)?;
                next += 1;
            }
        }
    }

    /// The GPU side of [`Extractor::detect_and_describe_stream`] (and of the batch): images queued
    /// on the pool's streams in turn, at most `STREAMS * IN_FLIGHT_PER_STREAM` in flight, each kept
    /// with its pending result until that is read. Images are uploaded as [`ImageLife::Work`]: the
    /// copy engine may read an image in page-locked memory until its work has run, so every image
    /// whose work may still be queued is held by [`InFlight`], which waits for the streams before
    /// releasing it on every way out of here: errors, and panics of `each`, of the iterator or of
    /// `gray_view` alike.
    fn stream_on_gpu<T, E>(
        &self,
        device: usize,
        images: impl IntoIterator<Item = std::result::Result<T, E>>,
        mut each: impl FnMut(usize, T, Features) -> std::result::Result<(), E>,
    ) -> std::result::Result<usize, E>
    where
        T: AsGrayView,
        E: From<Error>,
    {
        let streams = streams(device)?;
        let window = STREAMS * IN_FLIGHT_PER_STREAM;
        let mut flight = InFlight {
            streams: &streams,
            queued: VecDeque::with_capacity(window),
            held: None,
        };
        let mut next = 0;
        for item in images {
            if flight.queued.len() >= window {
                flight.finish_oldest(&mut each)?;
            }
            // Held before anything is queued with it, so that it outlives its upload even if queuing
            // fails or panics half-way.
            let item = flight.held.insert(item?);
            let view = item.gray_view()?;
            let pending =
                self.queue_features(&flight.streams[next % STREAMS], &view, ImageLife::Work)?;
            let item = flight.held.take().expect("held above");
            flight.queued.push_back((next, item, Some(pending)));
            next += 1;
        }
        while !flight.queued.is_empty() {
            flight.finish_oldest(&mut each)?;
        }
        Ok(next)
    }
}

/// The images of [`Extractor::stream_on_gpu`] whose work may still be queued: each queued image with
/// its pending result (taken while it is being read), and `held`, the one being queued or whose result
/// is being handed on. Dropped with any of them still here (an error or a panic on the way out), it
/// waits for every stream first, so that no copy still reads an image it releases.
struct InFlight<'s, T> {
    streams: &'s [GpuStream],
    queued: VecDeque<(usize, T, Option<PendingFeatures>)>,
    held: Option<T>,
}

impl<T> InFlight<'_, T> {
    /// Reads the results of the oldest images, one per stream, side by side, and hands each with its
    /// image to `each` in input order. Images go round the streams in turn, so the oldest
    /// `streams.len()` are on different streams; reading a result has a host share (a pyramid's
    /// selection over its levels, then the description queued on the selection) that now runs for
    /// several images at once instead of one after another. Each image stays held until its result
    /// is read (after which its work has run).
    fn finish_oldest<E: From<Error>>(
        &mut self,
        each: &mut impl FnMut(usize, T, Features) -> std::result::Result<(), E>,
    ) -> std::result::Result<(), E> {
        let n = self.queued.len().min(self.streams.len());
        let pending: Vec<PendingFeatures> = self
            .queued
            .iter_mut()
            .take(n)
            .filter_map(|queued| queued.2.take())
            .collect();
        let results: Vec<Result<Features>> =
            pending.into_par_iter().map(PendingFeatures::wait).collect();
        for result in results {
            let (i, item, _) = self.queued.pop_front().expect("an image is queued");
            self.held = Some(item);
            let features = result?;
            let item = self.held.take().expect("held above");
            each(i, item, features)?;
        }
        Ok(())
    }
}

impl<T> Drop for InFlight<'_, T> {
    fn drop(&mut self) {
        // Runs before the fields drop, i.e. before any image is released.
        if !self.queued.is_empty() || self.held.is_some() {
            for stream in self.streams {
                // An error (or the panic) on the way out is the one that matters.
                let _ = stream.synchronize();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ExtractorConfig;

    struct Owned(Vec<u8>, usize, usize);

    impl AsGrayView for Owned {
        fn gray_view(&self) -> Result<GrayView<'_>> {
            GrayView::new(&self.0, self.1, self.2, self.1)
        }
    }

    fn image(i: usize) -> Owned {
        let (w, h) = (96 + 8 * (i % 5), 80 + 4 * (i % 3));
        Owned(
            crate::synthetic::rectangles(w, h, i as u64).expect("synthetic image"),
            w,
            h,
        )
    }

    #[test]
    fn a_stream_on_the_cpu_gives_each_image_its_own_result_in_order() {
        let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap();
        // More images than one group of threads.
        let n = 2 * crate::parallel::threads() + 3;
        let mut seen = Vec::new();
        let count = extractor
            .detect_and_describe_stream((0..n).map(|i| Ok::<_, Error>(image(i))), |i, item, f| {
                assert_eq!(f, extractor.detect_and_describe(&item.gray_view()?)?);
                assert_eq!(
                    item.0,
                    image(i).0,
                    "image {i} handed back with its features"
                );
                seen.push(i);
                Ok(())
            })
            .unwrap();
        assert_eq!(count, n);
        assert_eq!(seen, (0..n).collect::<Vec<_>>());
    }

    #[test]
    fn a_stream_stops_at_the_first_error() {
        let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap();
        let producer = (0..10).map(|i| {
            if i == 6 {
                Err(Error::EmptyGallery)
            } else {
                Ok(image(i))
            }
        });
        let mut handed = 0;
        let result = extractor.detect_and_describe_stream(producer, |_, _, _| {
            handed += 1;
            Ok(())
        });
        assert!(matches!(result, Err(Error::EmptyGallery)));
        assert!(handed <= 6);
        let tiny = (0..3).map(|i| {
            Ok::<_, Error>(if i == 1 {
                Owned(vec![0; 16 * 16], 16, 16)
            } else {
                image(i)
            })
        });
        let result = extractor.detect_and_describe_stream(tiny, |_, _, _| Ok(()));
        assert!(
            matches!(result, Err(Error::ImageTooSmall { .. })),
            "{result:?}"
        );
        let result = extractor.detect_and_describe_stream(
            (0..5).map(|i| Ok::<_, Error>(image(i))),
            |i, _, _| {
                if i == 2 {
                    Err(Error::EmptyGallery)
                } else {
                    Ok(())
                }
            },
        );
        assert!(matches!(result, Err(Error::EmptyGallery)));
    }
}
