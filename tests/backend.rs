//! Backend selection: `Backend::auto()` picks CUDA only when it can really run, and a CUDA backend
//! that cannot run is a typed error, never a panic (this runs in CI, where there is no driver).

use clatch::cuda::GpuStream;
use clatch::{Backend, Error, Extractor, ExtractorConfig, MatchConfig, Matcher};

#[test]
fn cpu_is_always_available() {
    assert!(Backend::Cpu.ensure_available().is_ok());
    assert!(Extractor::new(Backend::Cpu, ExtractorConfig::default()).is_ok());
    assert!(Matcher::new(Backend::Cpu, MatchConfig::default()).is_ok());
}

#[cfg(not(feature = "cuda"))]
#[test]
fn without_the_cuda_feature_auto_is_the_cpu() {
    assert_eq!(Backend::auto(), Backend::Cpu);
}

/// `Backend::Cuda` and the stream types exist in every build: without the feature they are refused at
/// run time with a typed error that says why.
#[cfg(not(feature = "cuda"))]
#[test]
fn without_the_cuda_feature_cuda_is_a_typed_error() {
    let cuda = Backend::Cuda { device: 0 };
    for result in [
        cuda.ensure_available(),
        Extractor::new(cuda, ExtractorConfig::default()).map(drop),
        Matcher::new(cuda, MatchConfig::default()).map(drop),
        GpuStream::new(0).map(drop),
    ] {
        match result {
            Err(Error::BackendUnavailable { backend, reason }) => {
                assert_eq!(backend, "cuda:0");
                assert!(reason.contains("`cuda` feature"), "{reason}");
            }
            other => panic!("expected BackendUnavailable, got {other:?}"),
        }
    }
}

/// Asynchronous calls need a CUDA extractor: on the CPU they are a typed error in every build.
#[test]
fn asynchronous_calls_on_the_cpu_are_refused() {
    // No stream can be had without a device, so the check is on the extractor: building one for the
    // CPU and asking for a stream of device 0 either fails for the stream (no device) or for the backend.
    let cpu = Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap();
    if let Ok(stream) = GpuStream::new(0) {
        let pixels = vec![0u8; 128 * 128];
        let image = clatch::GrayView::new(&pixels, 128, 128, 128).unwrap();
        let error = cpu.detect_and_describe_async(&stream, &image).unwrap_err();
        assert!(
            matches!(&error, Error::InvalidInput { what: "stream", reason } if reason.contains("cpu")),
            "{error:?}"
        );
        assert_eq!(error.kind(), clatch::ErrorKind::InvalidInput);
    }
}

fn send_sync<T: Send + Sync>() {}

/// What the docs promise: every public type crosses threads, in every build.
#[test]
fn public_types_are_send_and_sync() {
    send_sync::<Backend>();
    send_sync::<Error>();
    send_sync::<Extractor>();
    send_sync::<ExtractorConfig>();
    send_sync::<Matcher>();
    send_sync::<clatch::DevicePool>();
    send_sync::<clatch::DescriptorCollection>();
    send_sync::<MatchConfig>();
    send_sync::<clatch::Features>();
    send_sync::<clatch::DescriptorSet>();
    send_sync::<clatch::Descriptor>();
    send_sync::<clatch::KnnMatches>();
    send_sync::<clatch::Match>();
    send_sync::<clatch::KeyPoint>();
    send_sync::<clatch::GrayView<'static>>();
    send_sync::<clatch::OpencvLatch>();
    send_sync::<clatch::Pyramid>();
    send_sync::<GpuStream>();
    send_sync::<clatch::cuda::PendingFeatures>();
    send_sync::<clatch::cuda::PendingMatches>();
    send_sync::<clatch::colmap::MatchList<Vec<u8>>>();
    send_sync::<clatch::colmap::FolderJob>();
    send_sync::<clatch::colmap::FolderPlan>();
    send_sync::<clatch::colmap::WrittenFolder>();
    send_sync::<clatch::colmap::FolderReport>();
    send_sync::<clatch::colmap::ColmapError>();
    send_sync::<clatch::output::Staged>();
    send_sync::<clatch::output::TempDir>();
    send_sync::<clatch::output::OutputError>();
    // The database holds a SQLite connection: it may move to another thread, not be shared.
    fn send<T: Send>() {}
    send::<clatch::colmap::Database>();
    send::<clatch::colmap::FolderOutput>();
}

/// `Error` fits the usual boxed-error plumbing.
#[test]
fn errors_box_and_keep_their_message() {
    let error: Box<dyn std::error::Error + Send + Sync> = Box::new(Error::EmptyGallery);
    assert!(error.to_string().contains("gallery"));
}

#[cfg(feature = "cuda")]
#[test]
fn auto_agrees_with_device_availability() {
    match clatch::cuda::hooks::device(0) {
        Ok(dev) => {
            assert_eq!(
                Backend::auto(),
                Backend::Cuda { device: 0 },
                "{}",
                dev.name()
            );
        }
        Err(e) => {
            assert!(matches!(e, Error::BackendUnavailable { .. }), "{e}");
            assert_eq!(Backend::auto(), Backend::Cpu);
            let cuda = Backend::Cuda { device: 0 };
            assert!(matches!(
                Extractor::new(cuda, ExtractorConfig::default()),
                Err(Error::BackendUnavailable { .. })
            ));
            assert!(matches!(
                Matcher::new(cuda, MatchConfig::default()),
                Err(Error::BackendUnavailable { .. })
            ));
        }
    }
}

#[cfg(feature = "cuda")]
#[test]
fn a_device_that_does_not_exist_is_a_typed_error() {
    let missing = Backend::Cuda { device: 4096 };
    match missing.ensure_available() {
        Err(Error::BackendUnavailable { backend, .. }) => assert_eq!(backend, "cuda:4096"),
        other => panic!("expected BackendUnavailable, got {other:?}"),
    }
}

/// `Backend::start` gives, in its handle or at once, the answer `ensure_available` gives, and an
/// extractor made from the handle before the set-up ends gives the CPU's features or that error.
#[test]
fn a_background_start_agrees_with_ensure_available() {
    let pixels = clatch::synthetic::rectangles(320, 240, 7).unwrap();
    let image = clatch::GrayView::new(&pixels, 320, 240, 320).unwrap();
    let expected = Extractor::new(Backend::Cpu, ExtractorConfig::default())
        .unwrap()
        .detect_and_describe(&image)
        .unwrap();
    assert!(!expected.keypoints.is_empty());
    for backend in [
        Backend::Cpu,
        Backend::Cuda { device: 0 },
        Backend::Cuda { device: 4096 },
    ] {
        let available = backend.ensure_available();
        let start = match backend.start() {
            Ok(start) => start,
            Err(e) => {
                // Only what needs no set-up may fail at once, and only where the backend cannot run.
                assert!(matches!(e, Error::BackendUnavailable { .. }), "{e}");
                assert!(
                    available.is_err(),
                    "{backend}: start refused a usable backend"
                );
                continue;
            }
        };
        assert_eq!(start.backend(), backend);
        let extractor = Extractor::starting(&start, ExtractorConfig::default()).unwrap();
        match (extractor.detect_and_describe(&image), &available) {
            (Ok(got), Ok(())) => {
                assert_eq!(got.keypoints, expected.keypoints, "{backend}");
                assert_eq!(got.descriptors, expected.descriptors, "{backend}");
            }
            (Err(Error::BackendUnavailable { .. }), Err(_)) => {}
            (got, _) => panic!("{backend}: {got:?} where ensure_available gave {available:?}"),
        }
        match (start.wait(), available) {
            (Ok(took), Ok(())) => {
                if backend == Backend::Cpu {
                    assert_eq!(took, std::time::Duration::ZERO);
                }
            }
            (Err(Error::BackendUnavailable { .. }), Err(_)) => {}
            (got, available) => {
                panic!("{backend}: wait gave {got:?}, ensure_available {available:?}")
            }
        }
    }
}

/// `Extractor::starting` checks the configuration at once, as `new` does.
#[test]
fn a_starting_extractor_refuses_a_bad_configuration_at_once() {
    let mut config = ExtractorConfig::default();
    config.detector.max_keypoints = 0;
    let start = Backend::Cpu.start().unwrap();
    assert!(matches!(
        Extractor::starting(&start, config),
        Err(Error::InvalidConfig { .. })
    ));
}

/// `set_up_steps` is there exactly when the backend has been set up: never for the CPU or a device
/// that cannot run; for a usable GPU once `ensure_available` has returned, each step with its time.
#[test]
fn set_up_steps_are_known_once_a_device_is_set_up() {
    assert_eq!(Backend::Cpu.set_up_steps(), None);
    let missing = Backend::Cuda { device: 4096 };
    assert!(missing.ensure_available().is_err());
    assert_eq!(missing.set_up_steps(), None);
    let gpu = Backend::Cuda { device: 0 };
    match gpu.ensure_available() {
        Ok(()) => {
            let steps = gpu.set_up_steps().expect("a device set up has its steps");
            // Each step makes driver calls (context creation alone is tens of milliseconds).
            for (step, took) in [
                ("driver", steps.driver),
                ("context", steps.context),
                ("kernels", steps.kernels),
                ("tables", steps.tables),
            ] {
                assert!(took > std::time::Duration::ZERO, "{step}: {steps}");
            }
            assert_eq!(
                steps.total(),
                steps.driver + steps.context + steps.kernels + steps.tables
            );
            assert!(steps.to_string().starts_with("driver "), "{steps}");
            // Timed once per process: asking again gives the same figures.
            assert_eq!(gpu.set_up_steps(), Some(steps));
        }
        Err(_) => assert_eq!(gpu.set_up_steps(), None),
    }
}
