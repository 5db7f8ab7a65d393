//! Device-time spans of the extraction path, for benches (`internals` feature; without it every call
//! here does nothing).
//!
//! The extraction path marks where its device work starts and ends between host round trips
//! ([`start`], [`end`]: an event recorded on the stream). [`hooks::device_time`] turns the marks of one
//! call into the device's busy time for it: the sum of the spans, without the gaps where the device
//! waits for the host (selection over the levels, the read-backs' waits).

use std::sync::Arc;

use cudarc::driver::CudaStream;

#[cfg(feature = "internals")]
use cudarc::driver::CudaEvent;

#[cfg(feature = "internals")]
thread_local! {
    /// `Some` while a [`hooks::device_time`] collects: the spans so far, and the open one.
    static SPANS: std::cell::RefCell<Option<Collecting>> = const { std::cell::RefCell::new(None) };
}

/// The spans of a [`hooks::device_time`] so far.
#[cfg(feature = "internals")]
#[derive(Default)]
struct Collecting {
    done: Vec<(CudaEvent, CudaEvent)>,
    /// The start of the outermost open span, and how many starts are open (spans nest: an inner one
    /// is part of the outer one).
    open: Option<CudaEvent>,
    depth: usize,
}

/// An open span: [`start`] when made, [`end`] when dropped (errors included).
pub(crate) struct Span<'a>(&'a Arc<CudaStream>);

impl<'a> Span<'a> {
    /// Opens a span on `stream`.
    pub(crate) fn open(stream: &'a Arc<CudaStream>) -> Self {
        start(stream);
        Self(stream)
    }
}

impl Drop for Span<'_> {
    fn drop(&mut self) {
        end(self.0);
    }
}

/// Marks the start of device work queued next on `stream` (when collecting).
fn start(stream: &Arc<CudaStream>) {
    #[cfg(feature = "internals")]
    SPANS.with_borrow_mut(|spans| {
        if let Some(c) = spans {
            if c.depth == 0 {
                c.open = record(stream);
            }
            c.depth += 1;
        }
    });
    let _ = stream;
}

/// Marks the end of the device work queued so far on `stream` since the last [`start`].
fn end(stream: &Arc<CudaStream>) {
    #[cfg(feature = "internals")]
    SPANS.with_borrow_mut(|spans| {
        if let Some(c) = spans {
            c.depth = c.depth.saturating_sub(1);
            if c.depth == 0
                && let (Some(begin), Some(finish)) = (c.open.take(), record(stream))
            {
                c.done.push((begin, finish));
            }
        }
    });
    let _ = stream;
}

/// An event with timing recorded on `stream` now (none if the driver refuses: the span is dropped).
#[cfg(feature = "internals")]
fn record(stream: &Arc<CudaStream>) -> Option<CudaEvent> {
    let event = stream
        .context()
        .new_event(Some(cudarc::driver::sys::CUevent_flags::CU_EVENT_DEFAULT))
        .ok()?;
    event.record(stream).ok()?;
    Some(event)
}

#[cfg(feature = "internals")]
pub mod hooks {
    use super::*;
    use crate::cuda::error::driver_error;
    use crate::error::Result;

    /// Runs `f` (calls of the extraction path on this thread, which wait for their results) and
    /// returns its result with the device's busy time for it in milliseconds: the sum of the spans
    /// the calls marked, host round trips excluded. Spans of work on several streams at once add up.
    pub fn device_time<R>(f: impl FnOnce() -> Result<R>) -> Result<(R, f64)> {
        SPANS.set(Some(Collecting::default()));
        let result = f();
        let spans = SPANS.take().map(|c| c.done).unwrap_or_default();
        let result = result?;
        let mut total = 0.0;
        for (begin, finish) in &spans {
            finish
                .synchronize()
                .map_err(driver_error("device-time span"))?;
            total += f64::from(
                begin
                    .elapsed_ms(finish)
                    .map_err(driver_error("device-time span"))?,
            );
        }
        Ok((result, total))
    }
}
