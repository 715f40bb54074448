//! Long calls without the GIL, stoppable by Ctrl-C.
//!
//! The library's work runs on a thread of its own while the calling thread, without the GIL,
//! waits for it in slices of [`POLL`]. Between slices it takes the GIL to print progress and
//! to run Python's signal handlers (`Python::check_signals`): Python only runs them on the main
//! thread, and only when some code asks, so a call that kept the GIL or never asked would not see
//! Ctrl-C until it ended. When a handler raises (`KeyboardInterrupt`), the work is asked to stop
//! through its observer ([`vcsmooth::engine::Observer::interrupted`], asked after each
//! iteration and after each phase before the write: reading, reordering, the topology, the
//! schedule, the statistics) and the exception is raised once the work has ended, so that no
//! file is being written behind the caller's back: an interrupted file run leaves the previous
//! output (or none) and no temporary file. A phase itself is not cut short (each takes a
//! fraction of a second per million triangles), nor is the write.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crossbeam_channel::{RecvTimeoutError, Sender};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use vcsmooth::engine::{IterationRecord, Observer};

use crate::errors::to_py;

/// How long the calling thread waits without the GIL between two looks at signals and progress.
const POLL: Duration = Duration::from_millis(50);

/// The observer of a run: sends each iteration to the calling thread (for progress), and stops
/// the run when the caller was interrupted.
struct Watch<'a> {
    stop: &'a AtomicBool,
    progress: Option<Sender<(IterationRecord, usize)>>,
}

impl Observer for Watch<'_> {
    fn iteration(&mut self, record: &IterationRecord, total: usize) {
        if let Some(tx) = &self.progress {
            let _ = tx.send((*record, total));
        }
    }

    fn interrupted(&mut self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// Run `work` without the GIL on a thread of its own (see the module's documentation), printing
/// one line per iteration on `sys.stderr` when `progress` is set; the library's error as the
/// matching Python exception.
pub fn without_gil<T: Send>(
    py: Python<'_>,
    progress: bool,
    work: impl FnOnce(&mut dyn Observer) -> vcsmooth::Result<T> + Send,
) -> PyResult<T> {
    let stop = AtomicBool::new(false);
    let (done_tx, done) = crossbeam_channel::bounded(1);
    let (events_tx, events) = crossbeam_channel::unbounded();
    let mut interrupt: Option<PyErr> = None;
    let outcome = std::thread::scope(|s| {
        let stop = &stop;
        s.spawn(move || {
            let mut watch = Watch {
                stop,
                progress: progress.then_some(events_tx),
            };
            // A panic in the library must not take the interpreter down with it.
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(&mut watch)));
            let _ = done_tx.send(r);
        });
        loop {
            let got = py.detach(|| done.recv_timeout(POLL));
            for (record, total) in events.try_iter() {
                print_progress(py, &record, total);
            }
            match got {
                Ok(outcome) => break outcome,
                Err(RecvTimeoutError::Timeout) => {
                    if interrupt.is_none() {
                        if let Err(e) = py.check_signals() {
                            stop.store(true, Ordering::Relaxed);
                            interrupt = Some(e);
                        }
                    }
                }
                Err(RecvTimeoutError::Disconnected) => {
                    break Err(Box::new("the worker thread ended without a result"));
                }
            }
        }
    });
    if let Some(e) = interrupt {
        return Err(e);
    }
    match outcome {
        Ok(result) => result.map_err(to_py),
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            Err(PyRuntimeError::new_err(format!(
                "vcsmooth: internal error (please report it): {what}"
            )))
        }
    }
}

/// One line of progress on `sys.stderr` (where Jupyter shows it; Rust's stderr is the server's).
fn print_progress(py: Python<'_>, r: &IterationRecord, total: usize) {
    // '-': not measured; `undefined`: measured, but the input's volume (or area) is 0.
    let measured = |x: f64, decimals: usize| {
        if x.is_finite() {
            format!("{x:.decimals$} %")
        } else if r.volume.is_nan() {
            "-".to_string()
        } else {
            "undefined".to_string()
        }
    };
    let line = format!(
        "vcsmooth: iteration {}/{total}: volume {}, area {}, {:.3} s\n",
        r.iteration,
        measured(r.volume_pct, 6),
        measured(r.area_pct, 4),
        r.seconds
    );
    if let Ok(stderr) = py.import("sys").and_then(|sys| sys.getattr("stderr")) {
        let _ = stderr.call_method1("write", (line,));
    }
}
