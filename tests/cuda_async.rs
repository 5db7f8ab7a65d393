//! Several images in flight on streams the caller holds: the asynchronous calls return exactly what
//! the CPU reference returns, whatever the interleaving.

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_async")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test("eight_images_in_flight", gpu::eight_in_flight),
        Trial::test("extract_next_while_matching_previous", gpu::pipelined),
        Trial::test("async_needs_a_cuda_backend", gpu::cpu_backend_refused),
        Trial::test("batch_of_images_in_input_order", gpu::batch),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::cuda::GpuStream;
    use clatch::{Backend, Error, Extractor, ExtractorConfig, MatchConfig, Matcher};
    use libtest_mimic::Failed;

    use super::common::{Gray, astronaut, rectangles, scale};

    const GPU: Backend = Backend::Cuda { device: 0 };

    /// Eight images of different sizes (smaller under the sanitizer scale).
    fn images() -> Vec<Gray> {
        let (w, h) = scale::pick((640, 480), (320, 240));
        let mut images: Vec<Gray> = (0..7)
            .map(|i| rectangles(w + 64 * i, h + 8 * i, 40 + i as u64))
            .collect();
        images.push(astronaut());
        images
    }

    pub fn eight_in_flight() -> Result<(), Failed> {
        let images = images();
        let gpu = Extractor::new(GPU, scale::budget(ExtractorConfig::default()))?;
        let cpu = Extractor::new(Backend::Cpu, scale::budget(ExtractorConfig::default()))?;
        let streams: Vec<GpuStream> = (0..4)
            .map(|_| GpuStream::new(0))
            .collect::<Result<_, _>>()?;
        let pending: Vec<_> = images
            .iter()
            .zip(streams.iter().cycle())
            .map(|(image, stream)| gpu.detect_and_describe_async(stream, &image.view()))
            .collect::<Result<_, _>>()?;
        let mut compared = 0;
        // Wait in reverse order: results must not depend on the order of waiting.
        for (i, p) in pending.into_iter().enumerate().rev() {
            let got = p.wait()?;
            let expected = cpu.detect_and_describe(&images[i].view())?;
            if got != expected {
                return Err(format!("image {i}: GPU features differ from the CPU's").into());
            }
            compared += got.descriptors.len();
        }
        println!(
            "8 images on 4 streams: {compared} keypoints and descriptors identical to the CPU"
        );
        Ok(())
    }

    pub fn pipelined() -> Result<(), Failed> {
        let images = images();
        let gpu = Extractor::new(GPU, scale::budget(ExtractorConfig::default()))?;
        let cpu = Extractor::new(Backend::Cpu, scale::budget(ExtractorConfig::default()))?;
        let gpu_matcher = Matcher::new(GPU, MatchConfig::default())?;
        let cpu_matcher = Matcher::new(Backend::Cpu, MatchConfig::default())?;
        let (extract_stream, match_stream) = (GpuStream::new(0)?, GpuStream::new(0)?);
        let expected_features: Vec<_> = images
            .iter()
            .map(|image| cpu.detect_and_describe(&image.view()))
            .collect::<Result<_, _>>()?;
        let mut features = vec![
            gpu.detect_and_describe_async(&extract_stream, &images[0].view())?
                .wait()?,
        ];
        let mut kept = 0;
        let mut check_pair = |a: usize, got: Vec<clatch::Match>| -> Result<(), Failed> {
            let expected = cpu_matcher.match_descriptors(
                &expected_features[a].descriptors,
                &expected_features[a + 1].descriptors,
            )?;
            if got != expected {
                return Err(
                    format!("pair {a}-{}: GPU matches differ from the CPU's", a + 1).into(),
                );
            }
            kept += got.len();
            Ok(())
        };
        for i in 1..=images.len() {
            // Queue the extraction of image i, then the matching of pair (i - 2, i - 1) on the other
            // stream, so the device has both at once.
            let next = match images.get(i) {
                Some(image) => Some(gpu.detect_and_describe_async(&extract_stream, &image.view())?),
                None => None,
            };
            let matching = if i >= 2 {
                let (a, b) = (&features[i - 2], &features[i - 1]);
                Some(gpu_matcher.match_descriptors_async(
                    &match_stream,
                    &a.descriptors,
                    &b.descriptors,
                )?)
            } else {
                None
            };
            if let Some(next) = next {
                let got = next.wait()?;
                if got != expected_features[i] {
                    return Err(format!("image {i}: GPU features differ from the CPU's").into());
                }
                features.push(got);
            }
            if let Some(matching) = matching {
                check_pair(i - 2, matching.wait()?)?;
            }
        }
        let n = images.len();
        println!(
            "{n} images extracted while the previous pairs were matched on a second stream: {kept} matches identical to the CPU"
        );
        Ok(())
    }

    pub fn cpu_backend_refused() -> Result<(), Failed> {
        let stream = GpuStream::new(0)?;
        let image = rectangles(200, 200, 1);
        let cpu = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
        match cpu.detect_and_describe_async(&stream, &image.view()) {
            Err(Error::InvalidInput { what: "stream", .. }) => Ok(()),
            other => Err(format!("expected InvalidInput for a CPU backend, got {other:?}").into()),
        }
    }

    /// `Extractor::detect_and_describe_batch` on the GPU (streams the library holds) against the
    /// CPU's, image by image, with the default pyramid and the single-scale preset; more images than
    /// the library keeps in flight, so the window turns over.
    pub fn batch() -> Result<(), Failed> {
        // More images than streams and slots in flight. CLATCH_TEST_SCALE=sanitizer: two copies and
        // the default configuration only (racecheck's host memory passed 110 GB on the full workload).
        let owned: Vec<_> = (0..scale::pick(3, 2)).flat_map(|_| images()).collect();
        let views: Vec<_> = owned.iter().map(|g| g.view()).collect();
        let mut compared = 0;
        let configs = scale::pick(
            vec![
                scale::budget(ExtractorConfig::default()),
                scale::budget(ExtractorConfig::single_scale()),
            ],
            vec![scale::budget(ExtractorConfig::default())],
        );
        for config in configs {
            let gpu = Extractor::new(GPU, config.clone())?;
            let cpu = Extractor::new(Backend::Cpu, config)?;
            let done = std::sync::Mutex::new(Vec::new());
            let got = gpu.detect_and_describe_batch_with_progress(&views, &|i| {
                done.lock().unwrap().push(i)
            })?;
            let expected = cpu.detect_and_describe_batch(&views)?;
            if *done.lock().unwrap() != (0..views.len()).collect::<Vec<_>>() {
                return Err("images not reported once each in input order".into());
            }
            for (i, (g, c)) in got.iter().zip(&expected).enumerate() {
                if g != c {
                    return Err(format!("image {i} differs").into());
                }
                compared += g.keypoints.len();
            }
        }
        println!(
            "{} images x {} configurations: {compared} keypoints and descriptors identical",
            views.len(),
            scale::pick(2, 1)
        );
        Ok(())
    }
}
