//! Driver errors as the crate's typed errors.

use cudarc::driver::{DriverError, sys};

use crate::error::Error;

/// Maps a driver error to ours, naming the operation and keeping the driver's error as the source.
pub(crate) fn driver_error(operation: &str) -> impl Fn(DriverError) -> Error + '_ {
    move |source| {
        if source.0 == sys::cudaError_enum::CUDA_ERROR_OUT_OF_MEMORY {
            Error::DeviceOutOfMemory {
                operation: operation.to_string(),
                bytes: 0,
            }
        } else {
            Error::Cuda {
                operation: operation.to_string(),
                source,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::error::Error as _;

    #[test]
    fn driver_errors_keep_the_driver_code_as_their_source() {
        let invalid = DriverError(sys::cudaError_enum::CUDA_ERROR_INVALID_VALUE);
        let error = driver_error("uploading the tables")(invalid);
        match &error {
            Error::Cuda { operation, source } => {
                assert_eq!(operation, "uploading the tables");
                assert_eq!(*source, invalid);
            }
            other => panic!("expected Error::Cuda, got {other:?}"),
        }
        let source = error.source().expect("the driver error is the source");
        let driver = source.downcast_ref::<DriverError>().expect("a DriverError");
        assert_eq!(driver.0, sys::cudaError_enum::CUDA_ERROR_INVALID_VALUE);
        // Out of memory has its own variant (the caller may retry with less).
        let oom = DriverError(sys::cudaError_enum::CUDA_ERROR_OUT_OF_MEMORY);
        assert!(matches!(
            driver_error("alloc")(oom),
            Error::DeviceOutOfMemory { .. }
        ));
    }
}
