//! Backend selection: `Backend::auto()` picks CUDA only when it can really run, and a CUDA backend
//! that cannot run is a typed error, never a panic (this runs in CI, where there is no driver).

#[cfg(feature = "cuda")]
use clatch::Error;
use clatch::{Backend, Extractor, ExtractorConfig, MatchConfig, Matcher};

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

#[cfg(feature = "cuda")]
#[test]
fn auto_agrees_with_device_availability() {
    match clatch::cuda::device(0) {
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
