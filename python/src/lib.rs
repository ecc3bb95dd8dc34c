//! The Python binding of abysslight: numpy arrays in, numpy arrays out, and the `abysslight` command.
//!
//! A thin layer over the library. Keyword arguments become [`abysslight::Options`] through its serde
//! `Deserialize` (the config file's names and value forms, src/options.rs), checked by the command's own checks;
//! the engine's parameters come from them as a run builds them ([`abysslight::Options::params`]). Long work runs
//! with the GIL released. Errors come back as `TypeError`/`ValueError`/`OSError`/`MemoryError`/
//! `KeyboardInterrupt`, never as a panic or an abort.

mod arrays;
mod options;
mod progress;

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard, TryLockError};

use abysslight::io::Entry;
use pyo3::exceptions::{
    PyKeyboardInterrupt, PyMemoryError, PyOSError, PyRuntimeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use arrays::{array_from_photo, array_from_raster, photo_from_array, Shape};
use options::{correct_kwargs, engine_kwargs};

/// A library error as the Python exception a user expects: a file that cannot be read or written is an `OSError`
/// (`FileNotFoundError`, `PermissionError`, ... by its errno), memory that cannot be had a `MemoryError`, an
/// interrupted call a `KeyboardInterrupt`, everything else (bad values, a photo of another size, a bad file, and
/// any kind of error added later) a `ValueError`, with the command's message.
pub(crate) fn to_py(e: abysslight::Error) -> PyErr {
    use std::io::ErrorKind;
    // The library's messages name the command's flags: said as the keywords a Python caller gives.
    let message = options::keyword_names(&e.to_string());
    match &e {
        abysslight::Error::Io { source, .. } => match source.kind() {
            ErrorKind::OutOfMemory => PyMemoryError::new_err(message),
            ErrorKind::Interrupted => PyKeyboardInterrupt::new_err(message),
            _ => match source.raw_os_error() {
                Some(errno) => PyOSError::new_err((errno, message)),
                None => PyOSError::new_err(message),
            },
        },
        _ => PyValueError::new_err(message),
    }
}

/// A Rust value the library serialises (reports, health figures) as a Python dict, through JSON.
pub(crate) fn to_dict<T: serde::Serialize>(py: Python<'_>, v: &T) -> PyResult<PyObject> {
    let text = serde_json::to_string(v).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
}

/// The backscatter image `S`: the per-pixel temporal median of water-column frames.
#[pyclass(module = "abysslight._abysslight", frozen)]
struct Scatter {
    inner: abysslight::Scatter,
}

#[pymethods]
impl Scatter {
    /// `S` from water-column frames held in memory (a list of HxWx3 or HxW arrays of one size and dtype).
    #[staticmethod]
    fn from_frames(py: Python<'_>, frames: &Bound<'_, PyAny>) -> PyResult<Scatter> {
        scatter_from_frames(py, frames).map(|inner| Scatter { inner })
    }

    /// `S` from water-column frames on disk: a folder (searched as `--water-column` searches it) or a list of
    /// files. Frames that cannot be read are left out with a warning, as in a run. `memory_mib` bounds the frames
    /// held at once (row bands beyond it).
    #[staticmethod]
    #[pyo3(signature = (files, memory_mib = 2048))]
    fn from_files(
        py: Python<'_>,
        files: &Bound<'_, PyAny>,
        memory_mib: usize,
    ) -> PyResult<Scatter> {
        let entries = entries(files)?;
        let mut failed = Vec::new();
        let s = py.allow_threads(|| {
            abysslight::Scatter::from_files(&entries, memory_mib.max(1) << 20, |e| {
                failed.push(e.to_string())
            })
        });
        let warnings = py.import("warnings")?;
        for f in failed {
            warnings.call_method1("warn", (f,))?;
        }
        match s.map_err(to_py)? {
            Some(inner) => Ok(Scatter { inner }),
            None => Err(PyValueError::new_err("no usable water-column frames")),
        }
    }

    /// A scatter image saved by a run (`_abysslight/scatter.png` of `--save-scatter`) or by [`Scatter.save`].
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Scatter> {
        abysslight::Scatter::load(&path)
            .map(|inner| Scatter { inner })
            .map_err(to_py)
    }

    /// Save as a 16-bit PNG (what `Scatter.load` and `correct --scatter` read).
    fn save(&self, path: PathBuf) -> PyResult<()> {
        self.inner.save_png(&path).map_err(to_py)
    }

    /// `S` as a float32 HxWxC array of stored values scaled to [0, 1].
    #[getter]
    fn image<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        array_from_raster(py, &self.inner.to_raster())
    }

    /// Water-column frames the median was taken over.
    #[getter]
    fn frames(&self) -> usize {
        self.inner.frames
    }

    /// (height, width, channels).
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        let l = self.inner.layout;
        (l.height, l.width, l.channels)
    }

    fn __repr__(&self) -> String {
        format!(
            "Scatter({} from {} frames)",
            self.inner.layout, self.inner.frames
        )
    }
}

/// `S` from arrays: each checked and copied as a photo is, all of one shape.
fn scatter_from_frames(py: Python<'_>, frames: &Bound<'_, PyAny>) -> PyResult<abysslight::Scatter> {
    let mut photos = Vec::new();
    let mut shape: Option<Shape> = None;
    for (i, f) in frames.try_iter()?.enumerate() {
        let (photo, s) = photo_from_array(&f?, &format!("frame {i}"))?;
        if let Some(first) = shape.filter(|&first| first != s) {
            return Err(PyValueError::new_err(format!(
                "frame {i} is {}, the first frame is {}",
                s.describe(),
                first.describe()
            )));
        }
        shape = Some(s);
        photos.push(photo);
    }
    let s = py.allow_threads(|| abysslight::Scatter::from_frames(&photos));
    match s.map_err(to_py)? {
        Some(inner) => Ok(inner),
        None => Err(PyValueError::new_err("no water-column frames given")),
    }
}

/// Files to read: a folder (searched recursively, photos in natural order) or a list of paths.
fn entries(files: &Bound<'_, PyAny>) -> PyResult<Vec<Entry>> {
    if let Ok(dir) = files.extract::<PathBuf>() {
        if dir.is_dir() {
            return Ok(abysslight::io::find_photos(&dir).map_err(to_py)?.photos);
        }
        return Ok(vec![entry(dir)]);
    }
    files
        .try_iter()?
        .map(|p| Ok(entry(p?.extract::<PathBuf>()?)))
        .collect()
}

fn entry(path: PathBuf) -> Entry {
    let relative = path.file_name().map(PathBuf::from).unwrap_or_default();
    Entry { path, relative }
}

/// Static pixels (overlays, laser dots, vehicle parts) left out of every median; the photos are corrected
/// beneath them with `F` filled in from around them.
#[pyclass(module = "abysslight._abysslight", frozen)]
#[derive(Clone)]
struct Mask {
    inner: abysslight::Mask,
}

#[pymethods]
impl Mask {
    /// A mask from an HxW array: true (or non-zero) where pixels are ignored.
    #[new]
    fn new(array: &Bound<'_, PyAny>) -> PyResult<Mask> {
        arrays::mask_from_array(array).map(|inner| Mask { inner })
    }

    /// A mask image (white: ignored), as `--mask` reads it (e.g. a run's `_abysslight/mask-auto.png`).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Mask> {
        abysslight::Mask::load(&path)
            .map(|inner| Mask { inner })
            .map_err(to_py)
    }

    /// The mask as an HxW bool array (true: ignored).
    #[getter]
    fn array<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        arrays::array_from_mask(py, &self.inner)
    }

    /// Pixels ignored.
    #[getter]
    fn count(&self) -> usize {
        self.inner.count()
    }

    fn __repr__(&self) -> String {
        format!(
            "Mask({}x{}, {} pixels ignored)",
            self.inner.width,
            self.inner.height,
            self.inner.count()
        )
    }
}

/// One corrected photo, out of `Engine.push` or `Engine.finish`.
#[pyclass(module = "abysslight._abysslight", frozen, get_all)]
struct Corrected {
    /// What was pushed with the photo (`photo_index` in `engine.push(photo, photo_index)`).
    tag: PyObject,
    /// Position among the photos pushed (0-based).
    index: usize,
    /// The corrected photo: same shape and dtype as the photo pushed.
    image: PyObject,
    /// `F` at block resolution, in linear light (float32, h x w x C).
    factor: PyObject,
    /// Health figures and flags of the estimate (a dict, as in the run report's frames).
    health: PyObject,
    /// (first, end) indices of the photos whose median gave this photo's `F`.
    window: (usize, usize),
    /// The altitude the photo was pushed with (None: none).
    altitude: Option<f32>,
    /// Where its window was chosen by altitude: the indices of the photos it took, in order (None: the photos
    /// `window` spans).
    by_altitude: Option<Vec<usize>>,
}

#[pymethods]
impl Corrected {
    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "Corrected(tag={}, index={}, window={:?})",
            self.tag
                .bind(py)
                .repr()
                .map_or_else(|_| "?".into(), |r| r.to_string()),
            self.index,
            self.window
        )
    }
}

/// The method over a stream of photos held in memory, with memory bounded by the window. One engine corrects one
/// mission, from one thread at a time: a call while another thread's call runs, or a photo after `finish()`, is a
/// `RuntimeError` that says so.
#[pyclass(module = "abysslight._abysslight", frozen)]
struct Engine {
    state: Mutex<EngineState>,
    method: abysslight::Method,
}

struct EngineState {
    inner: abysslight::Engine<PyObject>,
    /// The shape of the first photo (its rank and dtype are given back to every output).
    shape: Option<Shape>,
    /// `finish()` was called: the mission is over.
    finished: bool,
    /// Windows by altitude, from the first photo on (`by_altitude=True`, or the first photo had an altitude).
    by_altitude: bool,
}

/// An engine from the keyword options of `caller`: the method's options, `method="mean"` refused.
fn new_engine<T>(
    caller: &str,
    scatter: Option<&abysslight::Scatter>,
    mask: Option<abysslight::Mask>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<(abysslight::Engine<T>, abysslight::Method)> {
    let opts = engine_kwargs(options, caller)?;
    // Arrays carry no file facts: `transfer="auto"` (the default) is what `--transfer auto` assumes for a file
    // that declares nothing, linear; the engine resolves it (`Params::resolved`).
    if opts.method == abysslight::Method::Mean {
        return Err(PyValueError::new_err(
            "method=\"mean\" needs the whole mission's mean image before the first photo; use correct()",
        ));
    }
    let params = opts.params().map_err(to_py)?;
    let inner = abysslight::Engine::new(params, scatter, mask).map_err(to_py)?;
    Ok((inner, opts.method))
}

#[pymethods]
impl Engine {
    /// An engine with `correct`'s method options by their names with `_` (`window=9`, `method="paper"`,
    /// `transfer="srgb"`); none given: the command's defaults. `by_altitude=True`: windows by altitude from the
    /// first photo on, for a navigation log that starts after the first photo (photos pushed without an altitude
    /// keep the window over time); without it they are chosen by altitude when the first photo has one.
    #[new]
    #[pyo3(signature = (scatter = None, mask = None, by_altitude = false, **options))]
    fn new(
        scatter: Option<PyRef<'_, Scatter>>,
        mask: Option<PyRef<'_, Mask>>,
        by_altitude: bool,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Engine> {
        let mask = mask.map(|m| m.inner.clone());
        let (mut inner, method) = new_engine(
            "Engine()",
            scatter.as_ref().map(|s| &s.inner),
            mask,
            options,
        )?;
        if by_altitude {
            inner.expect_altitudes().map_err(to_py)?;
        }
        Ok(Engine {
            state: Mutex::new(EngineState {
                inner,
                shape: None,
                finished: false,
                by_altitude,
            }),
            method,
        })
    }

    /// Give the next photo (HxWx3 or HxW; uint8, uint16, or float32/float64 in 0..1) with a tag of your choice
    /// (e.g. its index or file name), and its altitude above the seafloor in metres where a navigation log gives
    /// it. Returns the photos whose window became complete, in order. A photo of another size or dtype than the
    /// first raises ValueError and leaves the engine as it was. The GIL is released while it works.
    ///
    /// Altitudes (the first photo's given): where the altitude swings along the track, each photo's window is
    /// chosen among the photos around it lit from the nearest heights, as `correct(navigation=...)` does.
    #[pyo3(signature = (photo, tag = None, altitude = None))]
    fn push(
        &self,
        py: Python<'_>,
        photo: &Bound<'_, PyAny>,
        tag: Option<PyObject>,
        altitude: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Vec<Corrected>> {
        let altitude = altitude_of(altitude, "altitude")?;
        let mut state = self.state("push")?;
        if state.finished {
            return Err(finished("push"));
        }
        if altitude.is_some() && !state.by_altitude && state.shape.is_some() {
            return Err(PyValueError::new_err(
                "an altitude after a first photo pushed without one: this engine chooses its windows over \
                 time, and would ignore it. Windows by altitude are chosen from the mission's first photo on: \
                 give the first photo's altitude, or make the engine with Engine(by_altitude=True) when the \
                 log starts later (photos without an altitude then keep the window over time)",
            ));
        }
        let (photo, shape) = photo_from_array(photo, "photo")?;
        if let Some(first) = state.shape {
            if first != shape {
                return Err(PyValueError::new_err(format!(
                    "photo is {}, the mission's photos are {}",
                    shape.describe(),
                    first.describe()
                )));
            }
        }
        let tag = tag.unwrap_or_else(|| py.None());
        let inner = &mut state.inner;
        let out = py
            .allow_threads(|| inner.push((photo, tag, altitude)))
            .map_err(to_py)?;
        // The first photo's altitude: windows by altitude from here on (as the engine does).
        state.by_altitude |= altitude.is_some();
        state.shape.get_or_insert(shape);
        out.into_iter().map(|c| corrected(py, c, shape)).collect()
    }

    /// The end of the mission: every photo still waiting, corrected with the window shifted back from the end.
    /// The engine takes no photo after it (one engine, one mission).
    fn finish(&self, py: Python<'_>) -> PyResult<Vec<Corrected>> {
        let mut state = self.state("finish")?;
        if state.finished {
            return Err(finished("finish"));
        }
        state.finished = true;
        let inner = &mut state.inner;
        let out = py.allow_threads(|| inner.finish());
        let Some(shape) = state.shape else {
            return Ok(Vec::new());
        };
        out.into_iter().map(|c| corrected(py, c, shape)).collect()
    }

    /// The window `n` in photos when it is given (`window=` or `contamination=`); `None` at the default, where
    /// the survey chooses each photo's window as the photos come (each `Corrected` has its own).
    #[getter]
    fn window(&self) -> PyResult<Option<usize>> {
        let p = *self.state("window")?.inner.params();
        Ok((!p.window_is_auto()).then(|| p.window_length()))
    }

    /// The block size `K` (0 until the first photo when `auto` takes it from the photos' size).
    #[getter]
    fn downsample(&self) -> PyResult<usize> {
        Ok(self.state("downsample")?.inner.params().downsample)
    }

    /// The camera curve the engine assumes (`srgb`, `linear`, `gamma:G`).
    #[getter]
    fn transfer(&self) -> PyResult<String> {
        Ok(self.state("transfer")?.inner.params().curve().to_string())
    }

    /// The method (`abyss`, `paper`, `polynomial`).
    #[getter]
    fn method(&self) -> String {
        self.method.to_string()
    }

    /// Photos pushed and not yet out (waiting for the photos after them).
    #[getter]
    fn waiting(&self) -> PyResult<usize> {
        Ok(self.state("waiting")?.inner.waiting())
    }

    fn __repr__(&self) -> String {
        match self.state.try_lock() {
            Ok(s) => {
                let p = s.inner.params();
                format!(
                    "Engine(method={}, window={}, transfer={})",
                    self.method,
                    match p.window_is_auto() {
                        true => "auto".to_string(),
                        false => p.window_length().to_string(),
                    },
                    p.curve()
                )
            }
            Err(_) => format!("Engine(method={}, busy)", self.method),
        }
    }
}

impl Engine {
    /// The engine's state for `call`, or a RuntimeError when another thread is in a call.
    fn state(&self, call: &str) -> PyResult<MutexGuard<'_, EngineState>> {
        match self.state.try_lock() {
            Ok(s) => Ok(s),
            Err(TryLockError::WouldBlock) => Err(PyRuntimeError::new_err(format!(
                "Engine.{call}: this Engine is working in another thread. An Engine corrects one mission, one \
                 photo at a time, from one thread at a time: give each thread (each mission) its own Engine"
            ))),
            Err(TryLockError::Poisoned(_)) => Err(PyRuntimeError::new_err(format!(
                "Engine.{call}: this Engine stopped in an internal error in an earlier call and cannot go on: \
                 make a new Engine (and please report the error)"
            ))),
        }
    }
}

fn finished(call: &str) -> PyErr {
    PyRuntimeError::new_err(format!(
        "Engine.{call}: this Engine has finished its mission (finish() was called). An Engine corrects one \
         mission: make a new Engine for the next one"
    ))
}

/// A corrected photo as Python sees it, in the `shape` of the photos pushed.
fn corrected(
    py: Python<'_>,
    c: abysslight::Corrected<PyObject>,
    shape: Shape,
) -> PyResult<Corrected> {
    let image = match c.photo {
        Some(p) => array_from_photo(py, p, shape)?.unbind(),
        None => py.None(),
    };
    Ok(Corrected {
        tag: c.tag,
        index: c.index,
        image,
        factor: array_from_raster(py, &c.factor)?.unbind(),
        health: to_dict(py, &c.health)?,
        window: (c.window.span().start, c.window.span().end),
        altitude: c.altitude,
        by_altitude: c.window.chosen_by_altitude().map(<[usize]>::to_vec),
    })
}

/// A list of photos corrected in one call, through an [`abysslight::Engine`] (which chooses the windows as it
/// does for any stream): the corrected arrays in the photos' order, each of the shape and dtype of its photo.
/// `water_column`: a `Scatter`, or water-column frames (a list of arrays), or None (`S = 0`). `altitudes`: each
/// photo's altitude in metres (a navigation log), one per photo, None where the log has none, for windows chosen by
/// altitude from the first photo on.
#[pyfunction]
#[pyo3(signature = (photos, water_column = None, mask = None, altitudes = None, **options))]
fn correct_arrays(
    py: Python<'_>,
    photos: &Bound<'_, PyAny>,
    water_column: Option<&Bound<'_, PyAny>>,
    mask: Option<PyRef<'_, Mask>>,
    altitudes: Option<&Bound<'_, PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Py<PyList>> {
    let altitudes = match altitudes.filter(|a| !a.is_none()) {
        None => None,
        Some(a) if a.downcast::<pyo3::types::PyString>().is_ok() => {
            return Err(pyo3::exceptions::PyTypeError::new_err(
                "altitudes must be a list of numbers of metres (None: not in the log), one per photo",
            ))
        }
        Some(a) => Some(
            a.try_iter()?
                .enumerate()
                .map(|(i, v)| altitude_of(Some(&v?), &format!("altitudes[{i}]")))
                .collect::<PyResult<Vec<Option<f32>>>>()?,
        ),
    };
    let scatter = match water_column {
        None => None,
        Some(w) => match w.downcast::<Scatter>() {
            Ok(s) => Some(s.get().inner.clone()),
            Err(_) => Some(scatter_from_frames(py, w)?),
        },
    };
    let mask = mask.map(|m| m.inner.clone());
    let (mut engine, _) = new_engine::<usize>("correct_arrays()", scatter.as_ref(), mask, options)?;
    if altitudes.is_some() {
        engine.expect_altitudes().map_err(to_py)?;
    }
    let mut shape: Option<Shape> = None;
    let mut out: Vec<Option<PyObject>> = Vec::new();
    for (i, p) in photos.try_iter()?.enumerate() {
        let what = format!("photo {i}");
        let (photo, s) = photo_from_array(&p?, &what)?;
        if let Some(first) = shape.filter(|&first| first != s) {
            return Err(PyValueError::new_err(format!(
                "photo {i} is {}, photo 0 is {}",
                s.describe(),
                first.describe()
            )));
        }
        shape = Some(s);
        out.push(None);
        let altitude = match &altitudes {
            Some(a) => *a.get(i).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "altitudes lists {} photos, photos has more",
                    a.len()
                ))
            })?,
            None => None,
        };
        let done = py
            .allow_threads(|| engine.push((photo, i, altitude)))
            .map_err(|e| to_py(e.about(std::path::Path::new(&what))))?;
        keep(py, &mut out, done, s)?;
    }
    let Some(shape) = shape else {
        return Err(PyValueError::new_err("no photos given"));
    };
    if let Some(a) = altitudes.as_ref().filter(|a| a.len() != out.len()) {
        return Err(PyValueError::new_err(format!(
            "altitudes lists {} photos, photos has {}",
            a.len(),
            out.len()
        )));
    }
    let done = py.allow_threads(|| engine.finish());
    keep(py, &mut out, done, shape)?;
    let images: Vec<PyObject> = out
        .into_iter()
        .map(|o| o.unwrap_or_else(|| py.None()))
        .collect();
    Ok(PyList::new(py, images)?.unbind())
}

/// A photo's altitude as Python gives it: a number of metres, or None (not in the log). True and False are
/// refused (True would read as 1 m).
fn altitude_of(v: Option<&Bound<'_, PyAny>>, what: &str) -> PyResult<Option<f32>> {
    let Some(v) = v.filter(|v| !v.is_none()) else {
        return Ok(None);
    };
    let type_error = || -> PyResult<Option<f32>> {
        Err(pyo3::exceptions::PyTypeError::new_err(format!(
            "{what} must be a number of metres, or None where the log has no altitude; got {}",
            v.get_type().name()?
        )))
    };
    let name = v.get_type().name()?.to_string();
    if v.downcast::<pyo3::types::PyBool>().is_ok() || name == "bool_" || name == "bool" {
        return type_error();
    }
    match v.extract::<f64>() {
        Ok(a) => Ok(Some(a as f32)),
        Err(_) => type_error(),
    }
}

/// The corrected photos of `done` into `out`, each at its tag (its position in the list).
fn keep(
    py: Python<'_>,
    out: &mut [Option<PyObject>],
    done: Vec<abysslight::Corrected<usize>>,
    shape: Shape,
) -> PyResult<()> {
    for c in done {
        let image = match c.photo {
            Some(p) => array_from_photo(py, p, shape)?.unbind(),
            None => py.None(),
        };
        out[c.tag] = Some(image);
    }
    Ok(())
}

/// The whole of `abysslight correct`: folders in, folders out, the report as a dict. With `cruise=`, every dive
/// of the cruise: `{"dives": {name: report}, "failed": {name: message}}`.
#[pyfunction]
#[pyo3(signature = (progress = None, **options))]
fn correct(
    py: Python<'_>,
    progress: Option<PyObject>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyObject> {
    let given = correct_kwargs(options)?;
    let opts = &given.options;
    let Some(cruise) = given.cruise else {
        let report =
            progress::run_cancellable(py, progress, |p| abysslight::correct_mission(opts, p))?;
        log_summary(py, &report, opts, "")?;
        return to_dict(py, &report);
    };
    let dives = progress::run_cancellable(py, progress, |p| {
        abysslight::cruise::correct_cruise(opts, &cruise, p)
    })?;
    let (done, failed) = (PyDict::new(py), PyDict::new(py));
    for (dive, result) in dives {
        match result {
            Ok(report) => {
                log_summary(
                    py,
                    &report,
                    &dive.options(
                        opts,
                        opts.out.as_deref().unwrap_or(std::path::Path::new(".")),
                    ),
                    &format!("{}: ", dive.name),
                )?;
                done.set_item(&dive.name, to_dict(py, &report)?)?
            }
            Err(e) => failed.set_item(&dive.name, options::keyword_names(&e.to_string()))?,
        }
    }
    let d = PyDict::new(py);
    d.set_item("dives", done)?;
    d.set_item("failed", failed)?;
    Ok(d.into_any().unbind())
}

/// The end of a run to the `abysslight` logger, as the command prints it (`abysslight::run::summary`): at WARNING
/// when photos were flagged as likely wrong or files failed, else at INFO. `prefix`: a cruise's dive name.
fn log_summary(
    py: Python<'_>,
    report: &abysslight::Report,
    opts: &abysslight::Options,
    prefix: &str,
) -> PyResult<()> {
    let out = opts
        .out
        .as_deref()
        .filter(|o| *o != std::path::Path::new("-"));
    let level = match abysslight::summary::flagged(report) > 0 || !report.all_ok() {
        true => "warning",
        false => "info",
    };
    for line in abysslight::summary::lines(report, opts, out) {
        progress::log(py, level, &format!("{prefix}{line}"))?;
    }
    Ok(())
}

/// Run the `abysslight` command with `argv` (the first is the program's name); returns its exit status. The one
/// part of the extension that needs the library's `cli` feature (the package's console script).
#[cfg(feature = "cli")]
#[pyfunction]
fn run_cli(py: Python<'_>, argv: Vec<String>) -> i32 {
    let args: Vec<std::ffi::OsString> = argv.into_iter().map(Into::into).collect();
    let code = py.allow_threads(|| abysslight::cli::run_from(args));
    (0..=255u8)
        .find(|&k| std::process::ExitCode::from(k) == code)
        .map_or(2, i32::from)
}

/// Decode a photo file into an array (HxWx3 or HxW, uint8 or uint16), as a run decodes it.
#[pyfunction]
fn read<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let photo = py
        .allow_threads(|| abysslight::io::decode(&path))
        .map_err(to_py)?;
    let shape = Shape::of(&photo.layout, photo.layout.channels == 3, &photo.samples);
    array_from_photo(py, photo, shape)
}

/// A simulated dive with known truth, in memory.
#[pyfunction]
#[pyo3(signature = (frames = 30, water_column = 15, width = 320, height = 240, seed = 1, contamination = 0.2, bit_depth = 8, encode = "linear", noise = 1.0))]
#[allow(clippy::too_many_arguments)]
fn simulate(
    py: Python<'_>,
    frames: usize,
    water_column: usize,
    width: usize,
    height: usize,
    seed: u64,
    contamination: f64,
    bit_depth: u32,
    encode: &str,
    noise: f32,
) -> PyResult<PyObject> {
    let encode: abysslight::Transfer = encode.parse().map_err(PyValueError::new_err)?;
    let sim = abysslight::eval::simulate::Simulation {
        frames,
        water_column,
        width,
        height,
        seed,
        contamination,
        bit_depth,
        encode,
        noise,
        ..Default::default()
    };
    // The command's ranges and messages, then whether the dive fits in memory at all.
    sim.validate().map_err(to_py)?;
    fits_in_memory(&sim)?;
    let dive = py.allow_threads(|| sim.render()).map_err(to_py)?;
    let to_list = |photos: Vec<abysslight::Photo>| -> PyResult<Bound<'_, PyList>> {
        let arrays = photos
            .into_iter()
            .map(|p| {
                let shape = Shape::of(&p.layout, true, &p.samples);
                array_from_photo(py, p, shape)
            })
            .collect::<PyResult<Vec<_>>>()?;
        PyList::new(py, arrays)
    };
    let d = PyDict::new(py);
    d.set_item("survey", to_list(dive.survey)?)?;
    d.set_item("water_column", to_list(dive.water)?)?;
    let albedo = dive
        .albedo
        .iter()
        .map(|r| array_from_raster(py, r))
        .collect::<PyResult<Vec<_>>>()?;
    d.set_item("albedo", PyList::new(py, albedo)?)?;
    d.set_item("transfer", encode.to_string())?;
    Ok(d.into_any().unbind())
}

/// Refuse a dive whose photos and albedos could not be allocated: a `MemoryError` instead of an abort midway.
fn fits_in_memory(sim: &abysslight::eval::simulate::Simulation) -> PyResult<()> {
    let pixels = (sim.width as u64).checked_mul(sim.height as u64 * 3);
    let bytes = pixels.and_then(|p| {
        let photos = (sim.frames as u64 + sim.water_column as u64)
            .checked_mul(p * (sim.bit_depth as u64 / 8))?;
        let albedo = (sim.frames as u64).checked_mul(p * 4)?;
        photos.checked_add(albedo)
    });
    let fits = bytes
        .and_then(|b| usize::try_from(b).ok())
        .is_some_and(|b| Vec::<u8>::new().try_reserve_exact(b).is_ok());
    if !fits {
        return Err(PyMemoryError::new_err(format!(
            "simulate(frames={}, water_column={}, width={}, height={}): the dive's photos would take {} bytes, \
             more than can be allocated",
            sim.frames,
            sim.water_column,
            sim.width,
            sim.height,
            bytes.map_or_else(|| "more than 2^64".to_string(), |b| b.to_string())
        )));
    }
    Ok(())
}

/// Score folders of corrected photos (`abysslight evaluate`): `sets` maps a label to a folder.
#[pyfunction]
#[pyo3(signature = (sets, truth = None, placements = None, cell = 8.0, transfer = None, mask = None))]
fn evaluate(
    py: Python<'_>,
    sets: Vec<(String, PathBuf)>,
    truth: Option<PathBuf>,
    placements: Option<PathBuf>,
    cell: f64,
    transfer: Option<&str>,
    mask: Option<PathBuf>,
) -> PyResult<PyObject> {
    let transfer = transfer
        .map(str::parse)
        .transpose()
        .map_err(PyValueError::new_err)?;
    let settings = abysslight::eval::evaluate::EvalSettings {
        cell,
        transfer,
        mask,
        ..Default::default()
    };
    let ev = py
        .allow_threads(|| {
            abysslight::eval::evaluate::evaluate(
                &sets,
                truth.as_deref(),
                placements.as_deref(),
                &settings,
            )
        })
        .map_err(to_py)?;
    to_dict(py, &ev)
}

#[pymodule]
fn _abysslight(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Scatter>()?;
    m.add_class::<Mask>()?;
    m.add_class::<Engine>()?;
    m.add_class::<Corrected>()?;
    m.add_function(wrap_pyfunction!(correct, m)?)?;
    m.add_function(wrap_pyfunction!(correct_arrays, m)?)?;
    #[cfg(feature = "cli")]
    m.add_function(wrap_pyfunction!(run_cli, m)?)?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
