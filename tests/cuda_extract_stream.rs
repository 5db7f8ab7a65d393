//! The GPU extraction path in a steady state: streams keep their buffers between calls (a warm
//! stream allocates nothing for images of similar size), images come from an iterator with results in
//! input order, images in page-locked memory are read straight by the copy engine; every result
//! identical to the CPU's.

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_extract_stream")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test(
            "warm_streams_allocate_nothing",
            gpu::warm_streams_allocate_nothing,
        ),
        Trial::test(
            "one_stream_shrinking_and_growing_sizes",
            gpu::shrinking_and_growing,
        ),
        Trial::test("stream_of_images_in_input_order", gpu::stream_in_order),
        Trial::test("stream_stops_at_the_first_error", gpu::stream_errors),
        Trial::test("pinned_and_pageable_images", gpu::pinned_and_pageable),
        Trial::test("large_images_arrive_in_bands", gpu::large_images_in_bands),
        Trial::test(
            "threads_sharing_one_stream",
            gpu::threads_sharing_one_stream,
        ),
        Trial::test(
            "a_panic_in_a_stream_waits_for_the_copies",
            gpu::panics_wait_for_the_copies,
        ),
        Trial::test("release_cached_memory", gpu::release_cached_memory),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::cuda::GpuStream;
    use clatch::cuda::hooks::{
        PinnedBytes, allocations, band_arrivals, buffers_freed, device_allocations,
        is_pinned_for_upload,
    };
    use clatch::{
        AsGrayView, Backend, Error, Extractor, ExtractorConfig, Features, GrayView, Subpixel,
    };
    use libtest_mimic::Failed;

    use super::common::{Gray, astronaut, on_threads, rectangles, scale};

    const GPU: Backend = Backend::Cuda { device: 0 };

    /// The configurations whose GPU paths differ: the default pyramid, the single-scale preset (no
    /// host selection), a single scale with a grid and sub-pixel positions (the one-level selection
    /// path with `clatch_subpixel`).
    fn configs() -> Vec<(&'static str, ExtractorConfig)> {
        let mut grid = ExtractorConfig::single_scale();
        grid.detector.grid = 4;
        grid.detector.subpixel = Subpixel::Score;
        let all = vec![
            ("pyramid", ExtractorConfig::default()),
            ("single scale", ExtractorConfig::single_scale()),
            ("grid and sub-pixel", grid),
        ];
        scale::thin(all, 2)
            .into_iter()
            .map(|(name, config)| (name, scale::budget(config)))
            .collect()
    }

    /// The configurations of the trials on images larger than one upload band: every one, or under
    /// the sanitizer scale the single-scale preset alone (the banded upload and the detection of the
    /// bands that have arrived are the same for all; the pyramid's levels would triple the pixels
    /// racecheck follows, and the other trials cover them).
    fn large_image_configs() -> Vec<(&'static str, ExtractorConfig)> {
        scale::pick(
            configs(),
            vec![(
                "single scale",
                scale::budget(ExtractorConfig::single_scale()),
            )],
        )
    }

    /// `image` with every pixel of a few rows changed, so that images of one size still differ.
    fn varied(image: &Gray, seed: usize) -> Gray {
        let mut out = image.clone();
        for y in (seed % 7..out.height).step_by(23) {
            for x in 0..out.width {
                let p = &mut out.pixels[y * out.width + x];
                *p = p.wrapping_add((seed * 37 + x) as u8);
            }
        }
        out
    }

    fn compare(what: &str, got: &Features, expected: &Features) -> Result<(), Failed> {
        if got != expected {
            return Err(format!("{what}: GPU features differ from the CPU's").into());
        }
        Ok(())
    }

    /// After two warm-up calls on the largest size, further calls of that size and slightly smaller
    /// sizes allocate nothing (device scratch, pinned staging and read-back buffers all reused): on a
    /// stream the caller holds, through the blocking call (the device's pooled streams) and through
    /// a batch. Counted by the allocation hook, which every allocation site of the crate passes.
    pub fn warm_streams_allocate_nothing() -> Result<(), Failed> {
        let calls = scale::pick(12, 3);
        let (w, h) = scale::pick((800, 600), (256, 192));
        let sizes = [(w, h), (w - 8, h - 8), (w - 30, h - 17), (w, h)];
        let images: Vec<Gray> = (0..calls)
            .map(|i| {
                let (iw, ih) = sizes[i % sizes.len()];
                varied(&rectangles(iw, ih, 70 + i as u64), i)
            })
            .collect();
        let warm = rectangles(w, h, 69);
        // Under the sanitizer scale the first configuration alone: allocations are what this counts.
        for (name, config) in scale::pick(configs(), configs().into_iter().take(1).collect()) {
            let gpu = Extractor::new(GPU, config.clone())?;
            let cpu = Extractor::new(Backend::Cpu, config)?;
            let expected: Vec<Features> = images
                .iter()
                .map(|g| cpu.detect_and_describe(&g.view()))
                .collect::<Result<_, _>>()?;

            // A stream the caller holds.
            let stream = GpuStream::new(0)?;
            for _ in 0..2 {
                gpu.detect_and_describe_async(&stream, &warm.view())?
                    .wait()?;
            }
            let before = allocations();
            for (i, image) in images.iter().enumerate() {
                let got = gpu
                    .detect_and_describe_async(&stream, &image.view())?
                    .wait()?;
                compare(
                    &format!("{name}, own stream, image {i}"),
                    &got,
                    &expected[i],
                )?;
            }
            let own = allocations() - before;

            // The blocking call: one thread, so the same pooled stream each time.
            for _ in 0..2 {
                gpu.detect_and_describe(&warm.view())?;
            }
            let before = allocations();
            for (i, image) in images.iter().enumerate() {
                let got = gpu.detect_and_describe(&image.view())?;
                compare(&format!("{name}, blocking, image {i}"), &got, &expected[i])?;
            }
            let blocking = allocations() - before;

            // Batches: the pool's streams, two images in flight on each; warm with batches of the
            // largest size (twice as many images as the batch keeps in flight). With 8 images in
            // flight, how many pinned staging buffers are busy at once depends on timing: the shared
            // staging pool may still grow (up to its bound), so the batch is held to no device
            // allocation and its pinned ones are reported.
            let warm_views = vec![warm.view(); 16];
            for _ in 0..3 {
                gpu.detect_and_describe_batch(&warm_views)?;
            }
            let views: Vec<GrayView> = images.iter().map(Gray::view).collect();
            let (before, before_device) = (allocations(), device_allocations());
            let got = gpu.detect_and_describe_batch(&views)?;
            let (batch, batch_device) =
                (allocations() - before, device_allocations() - before_device);
            for (i, (g, e)) in got.iter().zip(&expected).enumerate() {
                compare(&format!("{name}, batch, image {i}"), g, e)?;
            }
            if (own, blocking, batch_device) != (0, 0, 0) {
                return Err(format!(
                    "{name}: warm calls allocated (own stream {own}, blocking {blocking}, batch {batch_device} on the device, {batch} in all)"
                )
                .into());
            }
            println!(
                "{name}: {calls} warm calls on each path: 0 allocations on one stream and through the blocking call, 0 device allocations in the batch ({batch} pinned staging buffers added), identical to the CPU"
            );
        }
        Ok(())
    }

    /// One stream, images getting smaller and larger in turn (the arena grows, then serves smaller
    /// images from larger buffers holding an earlier image's bytes): every result the CPU's.
    pub fn shrinking_and_growing() -> Result<(), Failed> {
        let sizes = scale::pick(
            vec![
                (640, 480),
                (1280, 720),
                (320, 240),
                (1920, 1080),
                (700, 500),
                (64, 1500),
                (1500, 64),
                (1919, 1081),
                (512, 512),
            ],
            vec![(320, 240), (640, 480), (200, 150), (700, 90)],
        );
        for (name, config) in configs() {
            let gpu = Extractor::new(GPU, config.clone())?;
            let cpu = Extractor::new(Backend::Cpu, config)?;
            let stream = GpuStream::new(0)?;
            let mut compared = 0;
            for (i, &(w, h)) in sizes.iter().enumerate() {
                let image = if (w, h) == (512, 512) {
                    astronaut()
                } else {
                    rectangles(w, h, 200 + i as u64)
                };
                let got = gpu
                    .detect_and_describe_async(&stream, &image.view())?
                    .wait()?;
                let expected = cpu.detect_and_describe(&image.view())?;
                compare(&format!("{name}, {w}x{h}"), &got, &expected)?;
                compared += got.keypoints.len();
            }
            println!(
                "{name}: {} sizes on one stream, {compared} keypoints identical",
                sizes.len()
            );
        }
        Ok(())
    }

    /// An owned image as a producer would hand it over.
    struct Owned(Gray, usize);

    impl AsGrayView for Owned {
        fn gray_view(&self) -> clatch::Result<GrayView<'_>> {
            Ok(self.0.view())
        }
    }

    /// `detect_and_describe_stream` from a lazy iterator (images made as they are asked for, more of
    /// them than are kept in flight): results in input order, each with its own image handed back,
    /// each the CPU's; at most 8 images taken ahead of the one handed back.
    pub fn stream_in_order() -> Result<(), Failed> {
        let n = scale::pick(30, 11);
        for (name, config) in configs() {
            let gpu = Extractor::new(GPU, config.clone())?;
            let cpu = Extractor::new(Backend::Cpu, config)?;
            let made = std::cell::Cell::new(0usize);
            let images = (0..n).map(|i| {
                made.set(made.get() + 1);
                let base = if i % 5 == 0 {
                    astronaut()
                } else {
                    rectangles(400 + 16 * (i % 7), 300 + 8 * (i % 3), i as u64)
                };
                Ok::<_, Error>(Owned(base, i))
            });
            let mut seen = Vec::new();
            let count = gpu.detect_and_describe_stream(images, |i, image, features| {
                if made.get() > i + 1 + 8 {
                    return Err(Error::Internal {
                        operation: "test",
                        message: format!(
                            "{} images taken while handing back image {i}",
                            made.get()
                        ),
                    });
                }
                let expected = cpu.detect_and_describe(&image.0.view())?;
                if image.1 != i || features != expected {
                    return Err(Error::Internal {
                        operation: "test",
                        message: format!("image {i} (made as {}) differs from the CPU", image.1),
                    });
                }
                seen.push(i);
                Ok(())
            })?;
            if count != n || seen != (0..n).collect::<Vec<_>>() {
                return Err(format!("{name}: {count} images, handed back as {seen:?}").into());
            }
            println!("{name}: {n} images streamed in input order, identical to the CPU");
        }
        Ok(())
    }

    /// The first error stops the stream: the producer's (after some images), an image too small,
    /// the consumer's. Each comes back as itself, and the extractor works afterwards.
    pub fn stream_errors() -> Result<(), Failed> {
        let gpu = Extractor::new(GPU, scale::budget(ExtractorConfig::default()))?;
        let cpu = Extractor::new(Backend::Cpu, scale::budget(ExtractorConfig::default()))?;
        let images = |fail_at: usize| {
            (0..12).map(move |i| {
                if i == fail_at {
                    Err(Error::EmptyGallery)
                } else {
                    Ok(Owned(rectangles(320, 240, i as u64), i))
                }
            })
        };
        let mut handed = 0;
        match gpu.detect_and_describe_stream(images(10), |_, _, _| {
            handed += 1;
            Ok(())
        }) {
            Err(Error::EmptyGallery) if handed <= 10 => {}
            other => return Err(format!("producer error: got {other:?} after {handed}").into()),
        }
        let tiny = Gray::new(vec![0; 20 * 20], 20, 20);
        let with_tiny = (0..6).map(|i| {
            Ok::<_, Error>(if i == 4 {
                Owned(tiny.clone(), i)
            } else {
                Owned(rectangles(320, 240, i as u64), i)
            })
        });
        match gpu.detect_and_describe_stream(with_tiny, |_, _, _| Ok(())) {
            Err(Error::ImageTooSmall { .. }) => {}
            other => return Err(format!("small image: got {other:?}").into()),
        }
        match gpu.detect_and_describe_stream(images(99), |i, _, _| {
            if i == 3 {
                Err(Error::EmptyGallery)
            } else {
                Ok(())
            }
        }) {
            Err(Error::EmptyGallery) => {}
            other => return Err(format!("consumer error: got {other:?}").into()),
        }
        let image = rectangles(320, 240, 5);
        compare(
            "after the errors",
            &gpu.detect_and_describe(&image.view())?,
            &cpu.detect_and_describe(&image.view())?,
        )?;
        println!("producer, image and consumer errors stop the stream; the extractor works after");
        Ok(())
    }

    /// The same images from pageable and from page-locked memory (rows packed and with a stride),
    /// through the blocking call, the batch and the stream (which read page-locked images straight)
    /// and the asynchronous call (which stages them): all identical to the CPU.
    pub fn pinned_and_pageable() -> Result<(), Failed> {
        let (w, h) = scale::pick((1280, 720), (480, 320));
        let stride = w + 77;
        let sources: Vec<Gray> = (0..scale::pick(6, 3))
            .map(|i| varied(&rectangles(w, h, 300 + i as u64), i))
            .collect();
        let mut pinned = Vec::new();
        for g in &sources {
            let mut bytes = PinnedBytes::new(0, stride * h)?;
            let host = bytes.as_mut_slice()?;
            for y in 0..h {
                host[y * stride..y * stride + w].copy_from_slice(&g.pixels[y * w..(y + 1) * w]);
            }
            pinned.push(bytes);
        }
        let pinned_views: Vec<GrayView> = pinned
            .iter()
            .map(|b| GrayView::new(b.as_slice().expect("pinned bytes"), w, h, stride))
            .collect::<Result<_, _>>()?;
        if !is_pinned_for_upload(0, pinned_views[0].data())?
            || is_pinned_for_upload(0, &sources[0].pixels)?
        {
            return Err("page-locked memory not told apart from pageable memory".into());
        }
        for (name, config) in configs() {
            let gpu = Extractor::new(GPU, config.clone())?;
            let cpu = Extractor::new(Backend::Cpu, config)?;
            let expected: Vec<Features> = sources
                .iter()
                .map(|g| cpu.detect_and_describe(&g.view()))
                .collect::<Result<_, _>>()?;
            let stream = GpuStream::new(0)?;
            for (i, view) in pinned_views.iter().enumerate() {
                compare(
                    &format!("{name}, pinned, blocking, {i}"),
                    &gpu.detect_and_describe(view)?,
                    &expected[i],
                )?;
                compare(
                    &format!("{name}, pinned, async, {i}"),
                    &gpu.detect_and_describe_async(&stream, view)?.wait()?,
                    &expected[i],
                )?;
                compare(
                    &format!("{name}, pageable, blocking, {i}"),
                    &gpu.detect_and_describe(&sources[i].view())?,
                    &expected[i],
                )?;
            }
            let batch = gpu.detect_and_describe_batch(&pinned_views)?;
            let mut streamed = Vec::new();
            gpu.detect_and_describe_stream(pinned_views.iter().map(Ok::<_, Error>), |_, _, f| {
                streamed.push(f);
                Ok(())
            })?;
            for (i, e) in expected.iter().enumerate() {
                compare(&format!("{name}, pinned, batch, {i}"), &batch[i], e)?;
                compare(&format!("{name}, pinned, stream, {i}"), &streamed[i], e)?;
            }
            println!(
                "{name}: {} images of {w}x{h} (stride {stride}) from page-locked and pageable memory, identical",
                sources.len()
            );
        }
        Ok(())
    }

    /// Images larger than one upload band (4 MiB) are copied band by band on the stream's copy stream
    /// while the detector suppresses the bands that have arrived: from pageable and from page-locked
    /// memory, through the blocking call, the asynchronous call (two in flight on one stream) and the
    /// stream, with every configuration, the results are the CPU's.
    pub fn large_images_in_bands() -> Result<(), Failed> {
        let sizes = scale::pick(vec![(4000, 3000), (2400, 1801)], vec![(2100, 2100)]);
        for (w, h) in sizes {
            let pageable: Vec<Gray> = (0..2)
                .map(|i| varied(&rectangles(w, h, 500 + i as u64), i))
                .collect();
            let mut pinned = Vec::new();
            for g in &pageable {
                let mut bytes = PinnedBytes::new(0, w * h)?;
                bytes.as_mut_slice()?.copy_from_slice(&g.pixels);
                pinned.push(bytes);
            }
            let pinned_views: Vec<GrayView> = pinned
                .iter()
                .map(|b| GrayView::new(b.as_slice().expect("pinned bytes"), w, h, w))
                .collect::<Result<_, _>>()?;
            for (name, config) in large_image_configs() {
                let gpu = Extractor::new(GPU, config.clone())?;
                let cpu = Extractor::new(Backend::Cpu, config)?;
                let expected: Vec<Features> = pageable
                    .iter()
                    .map(|g| cpu.detect_and_describe(&g.view()))
                    .collect::<Result<_, _>>()?;
                let stream = GpuStream::new(0)?;
                // Every upload below must take the banded path: at least two bands per image.
                let banded = |what: &str, images: usize, before: usize| -> Result<usize, Failed> {
                    let bands = band_arrivals() - before;
                    if bands < 2 * images {
                        return Err(format!(
                            "{name}, {w}x{h}, {what}: {bands} bands for {images} image(s)"
                        )
                        .into());
                    }
                    Ok(bands)
                };
                let before = band_arrivals();
                let in_flight = [
                    gpu.detect_and_describe_async(&stream, &pageable[0].view())?,
                    gpu.detect_and_describe_async(&stream, &pinned_views[1])?,
                ];
                let bands = banded("async", 2, before)?;
                for (i, pending) in in_flight.into_iter().enumerate() {
                    compare(
                        &format!("{name}, {w}x{h}, async {i}"),
                        &pending.wait()?,
                        &expected[i],
                    )?;
                }
                for i in 0..2 {
                    let before = band_arrivals();
                    compare(
                        &format!("{name}, {w}x{h}, pageable, blocking {i}"),
                        &gpu.detect_and_describe(&pageable[i].view())?,
                        &expected[i],
                    )?;
                    banded("pageable, blocking", 1, before)?;
                    let before = band_arrivals();
                    compare(
                        &format!("{name}, {w}x{h}, pinned, blocking {i}"),
                        &gpu.detect_and_describe(&pinned_views[i])?,
                        &expected[i],
                    )?;
                    banded("pinned, blocking", 1, before)?;
                }
                let before = band_arrivals();
                let mut streamed = Vec::new();
                gpu.detect_and_describe_stream(
                    pinned_views.iter().map(Ok::<_, Error>),
                    |_, _, f| {
                        streamed.push(f);
                        Ok(())
                    },
                )?;
                banded("stream", 2, before)?;
                for (i, f) in streamed.iter().enumerate() {
                    compare(&format!("{name}, {w}x{h}, stream {i}"), f, &expected[i])?;
                }
                println!(
                    "{name}: {w}x{h} in bands ({} per image), pageable and page-locked, identical",
                    bands / 2
                );
            }
        }
        Ok(())
    }

    /// Several threads queue on clones of one stream at once (its arena and pinned buffers shared,
    /// each call's buffers its own): every result the CPU's.
    pub fn threads_sharing_one_stream() -> Result<(), Failed> {
        let (threads, rounds) = scale::pick((8, 4), (3, 1));
        let stream = GpuStream::new(0)?;
        let gpu = Extractor::new(GPU, scale::budget(ExtractorConfig::default()))?;
        let cpu = Extractor::new(Backend::Cpu, scale::budget(ExtractorConfig::default()))?;
        let total = on_threads(threads, |t| {
            let mut compared = 0;
            for round in 0..rounds {
                let image = rectangles(480 + 32 * t, 360 + 8 * round, (t * 10 + round) as u64);
                let pending = gpu
                    .detect_and_describe_async(&stream, &image.view())
                    .map_err(|e| e.to_string())?;
                let expected = cpu
                    .detect_and_describe(&image.view())
                    .map_err(|e| e.to_string())?;
                let got = pending.wait().map_err(|e| e.to_string())?;
                if got != expected {
                    return Err(format!("thread {t}, round {round}: GPU and CPU differ"));
                }
                compared += got.keypoints.len();
            }
            Ok(compared)
        })?;
        println!("{threads} threads x {rounds} rounds on one stream: {total} keypoints identical");
        Ok(())
    }

    /// A page-locked image owned by the stream's items, so that dropping an item frees its memory.
    struct PinnedImage {
        bytes: PinnedBytes,
        width: usize,
        height: usize,
        /// Its `gray_view` panics (a producer's type with a bug).
        panics: bool,
    }

    impl AsGrayView for PinnedImage {
        fn gray_view(&self) -> clatch::Result<GrayView<'_>> {
            if self.panics {
                panic!("gray_view panics (on purpose)");
            }
            GrayView::new(self.bytes.as_slice()?, self.width, self.height, self.width)
        }
    }

    /// A panic in `detect_and_describe_stream` (of the consumer, of the producer's iterator, of an
    /// item's `gray_view`) while images in page-locked memory are still being copied straight from
    /// where they are: it reaches the caller, the items are released only after the streams were
    /// waited for (the sanitizer's memcheck sees a copy reading freed memory otherwise), and the
    /// extractor gives the CPU's results afterwards.
    pub fn panics_wait_for_the_copies() -> Result<(), Failed> {
        let (w, h) = scale::pick((1920, 1080), (480, 320));
        let gpu = Extractor::new(GPU, scale::budget(ExtractorConfig::default()))?;
        let cpu = Extractor::new(Backend::Cpu, scale::budget(ExtractorConfig::default()))?;
        let sources: Vec<Gray> = (0..6)
            .map(|i| varied(&rectangles(w, h, 700 + i as u64), i))
            .collect();
        let items = |panic_at: Option<usize>| -> Result<Vec<PinnedImage>, Failed> {
            sources
                .iter()
                .enumerate()
                .map(|(i, g)| {
                    let mut bytes = PinnedBytes::new(0, w * h)?;
                    bytes.as_mut_slice()?.copy_from_slice(&g.pixels);
                    Ok(PinnedImage {
                        bytes,
                        width: w,
                        height: h,
                        panics: panic_at == Some(i),
                    })
                })
                .collect()
        };
        // The three panics below are on purpose (their messages go to stderr).
        let caught = |run: &dyn Fn() -> Result<usize, Failed>| {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)).is_err()
        };
        let consumer = std::cell::RefCell::new(Some(items(None)?));
        let by_consumer = caught(&|| {
            let images = consumer.borrow_mut().take().unwrap_or_default();
            Ok(gpu.detect_and_describe_stream(
                images.into_iter().map(Ok::<_, Error>),
                |i, _, _| {
                    if i == 1 {
                        panic!("the consumer panics (on purpose)");
                    }
                    Ok(())
                },
            )?)
        });
        let producer = std::cell::RefCell::new(Some(items(None)?));
        let by_producer = caught(&|| {
            let images = producer.borrow_mut().take().unwrap_or_default();
            Ok(gpu.detect_and_describe_stream(
                images.into_iter().enumerate().map(|(i, image)| {
                    if i == 4 {
                        panic!("the producer panics (on purpose)");
                    }
                    Ok::<_, Error>(image)
                }),
                |_, _, _| Ok(()),
            )?)
        });
        let viewed = std::cell::RefCell::new(Some(items(Some(3))?));
        let by_view = caught(&|| {
            let images = viewed.borrow_mut().take().unwrap_or_default();
            Ok(gpu
                .detect_and_describe_stream(images.into_iter().map(Ok::<_, Error>), |_, _, _| {
                    Ok(())
                })?)
        });
        if !(by_consumer && by_producer && by_view) {
            return Err(format!(
                "panics reached the caller: consumer {by_consumer}, producer {by_producer}, gray_view {by_view}"
            )
            .into());
        }
        let after = items(None)?;
        let mut got = Vec::new();
        gpu.detect_and_describe_stream(after.iter().map(Ok::<_, Error>), |_, _, f| {
            got.push(f);
            Ok(())
        })?;
        for (i, (g, source)) in got.iter().zip(&sources).enumerate() {
            compare(
                &format!("after the panics, image {i}"),
                g,
                &cpu.detect_and_describe(&source.view())?,
            )?;
        }
        println!(
            "panics of the consumer, the producer and gray_view reach the caller; {} images identical after",
            got.len()
        );
        Ok(())
    }

    /// `GpuStream::release_cached_memory` frees a warm stream's buffers (the next call allocates
    /// again, the one after nothing); `clatch::cuda::release_cached_memory` frees the pooled streams'
    /// (the blocking call still gives the CPU's results after); and a pooled stream going back to the
    /// pool frees a buffer over 256 MiB (a 9000 x 9000 image's quad texture, full scale only), so
    /// every such call allocates on the device.
    pub fn release_cached_memory() -> Result<(), Failed> {
        let (w, h) = scale::pick((1280, 720), (480, 320));
        let gpu = Extractor::new(GPU, scale::budget(ExtractorConfig::default()))?;
        let cpu = Extractor::new(Backend::Cpu, scale::budget(ExtractorConfig::default()))?;
        let image = rectangles(w, h, 900);
        let expected = cpu.detect_and_describe(&image.view())?;
        let stream = GpuStream::new(0)?;
        let on_stream = |what: &str| -> Result<usize, Failed> {
            let before = allocations();
            let got = gpu
                .detect_and_describe_async(&stream, &image.view())?
                .wait()?;
            compare(what, &got, &expected)?;
            Ok(allocations() - before)
        };
        on_stream("warming")?;
        on_stream("warming")?;
        let warm = on_stream("warm")?;
        let freed_before = buffers_freed();
        stream.release_cached_memory()?;
        let freed = buffers_freed() - freed_before;
        let cold = on_stream("after release")?;
        let warm_again = on_stream("warm again")?;
        if warm != 0 || freed == 0 || cold == 0 || warm_again != 0 {
            return Err(format!(
                "own stream: {warm} allocations warm, {freed} buffers released, {cold} allocations after, {warm_again} warm again"
            )
            .into());
        }
        for _ in 0..2 {
            gpu.detect_and_describe(&image.view())?;
        }
        let freed_before = buffers_freed();
        clatch::cuda::release_cached_memory(0)?;
        // Other trials may hold the pooled streams meanwhile: reported, not asserted.
        let pool_freed = buffers_freed() - freed_before;
        compare(
            "blocking, after releasing the pool",
            &gpu.detect_and_describe(&image.view())?,
            &expected,
        )?;
        let huge = scale::pick(Some(9000), None).map(|side| rectangles(side, side, 901));
        if let Some(huge) = &huge {
            for call in 0..2 {
                let (freed_before, device_before) = (buffers_freed(), device_allocations());
                let features = gpu.detect_and_describe(&huge.view())?;
                let freed = buffers_freed() - freed_before;
                let allocated = device_allocations() - device_before;
                if features.keypoints.is_empty() || freed == 0 || allocated == 0 {
                    return Err(format!(
                        "9000x9000, call {call}: {} keypoints, {allocated} device allocations, {freed} buffers trimmed on give-back",
                        features.keypoints.len()
                    )
                    .into());
                }
            }
        }
        println!(
            "own stream: {freed} buffers released, {cold} allocations after, 0 warm; pool: {pool_freed} released by this thread{}",
            if huge.is_some() {
                "; 9000x9000: its buffers over 256 MiB trimmed on give-back"
            } else {
                ""
            }
        );
        Ok(())
    }
}
