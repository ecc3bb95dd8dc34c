//! `correct()`: the run on a thread of its own while the calling thread, without the GIL, waits for it and looks
//! for Ctrl-C; progress to a Python callback and the `logging` module.

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Duration;

use abysslight::{Error, Progress};
use pyo3::prelude::*;

use crate::to_py;

/// How often the waiting thread looks for Ctrl-C.
const POLL: Duration = Duration::from_millis(50);

/// A run's [`Progress`] for Python: `callback(done, total, path, ok)` after each photo, stages and warnings to the
/// `abysslight` logger. An exception in the callback stops the run and is raised by `correct()`.
struct PyProgress {
    callback: Option<PyObject>,
    cancel: AtomicBool,
    done: AtomicUsize,
    total: AtomicUsize,
    raised: Mutex<Option<PyErr>>,
}

impl PyProgress {
    fn log(&self, level: &str, message: &str) {
        Python::with_gil(|py| {
            let r = py
                .import("logging")
                .and_then(|l| l.call_method1("getLogger", ("abysslight",)))
                .and_then(|l| l.call_method1(level, (message,)));
            if let Err(e) = r {
                self.stop(e);
            }
        });
    }

    fn stop(&self, e: PyErr) {
        self.cancel.store(true, Ordering::SeqCst);
        self.raised.lock().unwrap().get_or_insert(e);
    }
}

impl Progress for PyProgress {
    fn warn(&self, m: &str) {
        self.log("warning", m);
    }
    fn stage(&self, m: &str) {
        self.log("info", m);
    }
    fn file_error(&self, e: &Error) {
        self.log("error", &e.to_string());
    }
    fn start(&self, total: usize) {
        self.total.store(total, Ordering::SeqCst);
    }
    fn photo_done(&self, input: &Path, ok: bool) {
        let done = self.done.fetch_add(1, Ordering::SeqCst) + 1;
        let Some(cb) = &self.callback else { return };
        let total = self.total.load(Ordering::SeqCst);
        Python::with_gil(|py| {
            let path = input.to_string_lossy().into_owned();
            if let Err(e) = cb.call1(py, (done, total, path, ok)) {
                self.stop(e);
            }
        });
    }
    fn finish(&self) {}
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::SeqCst)
    }
}

/// Run `work` (a mission, or a cruise) on a thread of its own with a [`Progress`] for Python; Ctrl-C (or an
/// exception in the callback) stops it before the next photo, with the photos written so far complete, and is
/// raised here.
pub fn run_cancellable<T: Send>(
    py: Python<'_>,
    callback: Option<PyObject>,
    work: impl FnOnce(&dyn Progress) -> abysslight::Result<T> + Send,
) -> PyResult<T> {
    let progress = PyProgress {
        callback,
        cancel: AtomicBool::new(false),
        done: AtomicUsize::new(0),
        total: AtomicUsize::new(0),
        raised: Mutex::new(None),
    };
    let result = std::thread::scope(|scope| {
        let (tx, rx) = crossbeam_channel::bounded(1);
        let p = &progress;
        scope.spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(p)));
            let _ = tx.send(r);
        });
        loop {
            match py.allow_threads(|| rx.recv_timeout(POLL)) {
                Ok(r) => break r,
                Err(crossbeam_channel::RecvTimeoutError::Timeout) => {
                    // KeyboardInterrupt (Ctrl-C) or another signal handler's exception: stop the run.
                    if let Err(e) = py.check_signals() {
                        progress.stop(e);
                    }
                }
                Err(crossbeam_channel::RecvTimeoutError::Disconnected) => {
                    break Ok(Err(Error::Usage("the run ended without a result".into())))
                }
            }
        }
    });
    if let Some(e) = progress.raised.lock().unwrap().take() {
        return Err(e);
    }
    match result {
        Ok(r) => r.map_err(to_py),
        Err(_) => Err(pyo3::exceptions::PyRuntimeError::new_err(
            "abysslight: internal error during correct() (a bug: please report it with the command's options)",
        )),
    }
}
