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
    /// With a callback: after each call, the calling thread is asked to look for Ctrl-C (a signal raised in the
    /// callback, e.g. `os.kill(os.getpid(), SIGINT)`, is handled on that thread only) and the run waits for it,
    /// so that the photo after it is never started, however fast the photos go.
    asks: Option<crossbeam_channel::Sender<crossbeam_channel::Sender<()>>>,
}

impl PyProgress {
    fn log(&self, level: &str, message: &str) {
        Python::with_gil(|py| {
            if let Err(e) = log(py, level, message) {
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
        if let Some(asks) = &self.asks {
            let (ack, looked) = crossbeam_channel::bounded(1);
            if asks.send(ack).is_ok() {
                let _ = looked.recv();
            }
        }
    }
    fn finish(&self) {}
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::SeqCst)
    }
}

/// `message` to the `abysslight` logger at `level` (`"info"`, `"warning"`, ...), the command's `--flags` said
/// as Python's keyword names.
pub fn log(py: Python<'_>, level: &str, message: &str) -> PyResult<()> {
    let message = crate::options::keyword_names(message);
    py.import("logging")?
        .call_method1("getLogger", ("abysslight",))?
        .call_method1(level, (message,))?;
    Ok(())
}

/// What the calling thread waits for while a run goes on.
enum Event<R> {
    /// The run's result (`None`: its thread ended without one).
    Ended(Option<R>),
    /// A photo's callback returned: look for Ctrl-C, then let the run go on.
    Asked(Option<crossbeam_channel::Sender<()>>),
    /// Nothing for [`POLL`]: look for Ctrl-C.
    Poll,
}

/// Run `work` (a mission, or a cruise) on a thread of its own with a [`Progress`] for Python; Ctrl-C (or an
/// exception in the callback) stops it before the next photo, with the photos written so far complete, and is
/// raised here.
pub fn run_cancellable<T: Send>(
    py: Python<'_>,
    callback: Option<PyObject>,
    work: impl FnOnce(&dyn Progress) -> abysslight::Result<T> + Send,
) -> PyResult<T> {
    let (ask, asked) = crossbeam_channel::unbounded();
    // Without a callback nothing asks: wait on a channel that never delivers (not on `asked` with its sender
    // dropped, which is ready at once, forever: the calling thread spun on it for the whole run).
    let asked = match callback.is_some() {
        true => asked,
        false => crossbeam_channel::never(),
    };
    let progress = PyProgress {
        asks: callback.is_some().then_some(ask),
        callback,
        cancel: AtomicBool::new(false),
        done: AtomicUsize::new(0),
        total: AtomicUsize::new(0),
        raised: Mutex::new(None),
    };
    // KeyboardInterrupt (Ctrl-C) or another signal handler's exception: stop the run.
    let look = |py: Python<'_>| {
        if let Err(e) = py.check_signals() {
            progress.stop(e);
        }
    };
    let result = std::thread::scope(|scope| {
        let (tx, rx) = crossbeam_channel::bounded(1);
        let p = &progress;
        scope.spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(p)));
            let _ = tx.send(r);
        });
        loop {
            let event = py.allow_threads(|| {
                crossbeam_channel::select! {
                    recv(rx) -> r => Event::Ended(r.ok()),
                    recv(asked) -> ack => Event::Asked(ack.ok()),
                    default(POLL) => Event::Poll,
                }
            });
            match event {
                // A Ctrl-C whose handler had not run when the calling thread last looked (the signal reaches
                // another thread first) is not lost with the run's end: raised as during the run.
                Event::Ended(Some(r)) => {
                    look(py);
                    break r;
                }
                Event::Ended(None) => {
                    break Ok(Err(Error::Usage("the run ended without a result".into())))
                }
                Event::Asked(ack) => {
                    look(py);
                    if let Some(ack) = ack {
                        let _ = ack.send(());
                    }
                }
                Event::Poll => look(py),
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
