//! The Python binding of abysslight: numpy arrays in, numpy arrays out, and the `abysslight` command.
//!
//! A thin layer over the library. Options are parsed by the command line's own parser
//! ([`abysslight::cli::correct_options`]), so their names, defaults and error messages are the command's; the
//! engine's parameters come from them as a run builds them ([`abysslight::Options::params`]). Long work
//! runs with the GIL released. Errors come back as `TypeError`/`ValueError`/`OSError`, never as a panic.

mod arrays;
mod options;
mod progress;

use std::path::PathBuf;

use abysslight::io::Entry;
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use arrays::{array_from_photo, array_from_raster, photo_from_array, Shape};
use options::{correct_kwargs, engine_kwargs};

/// A library error as the Python exception a user expects: a file that cannot be read is an `OSError`, everything
/// else (bad values, a photo of another size, a bad file) a `ValueError`, with the command's message.
pub(crate) fn to_py(e: abysslight::Error) -> PyErr {
    match e {
        abysslight::Error::Io { .. } => PyOSError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
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
    /// `S` from water-column frames held in memory (a list of HxWx3 or HxW uint8/uint16 arrays of one size).
    #[staticmethod]
    fn from_frames(py: Python<'_>, frames: &Bound<'_, PyAny>) -> PyResult<Scatter> {
        let mut photos = Vec::new();
        let mut shape: Option<Shape> = None;
        for (i, f) in frames.try_iter()?.enumerate() {
            let (photo, s) = photo_from_array(&f?, &format!("frame {i}"))?;
            if shape.is_some_and(|first| first != s) {
                return Err(PyValueError::new_err(format!(
                    "frame {i} is {}, the first frame is {}",
                    s.describe(),
                    shape.unwrap().describe()
                )));
            }
            shape = Some(s);
            photos.push(photo);
        }
        let s = py.allow_threads(|| abysslight::Scatter::from_frames(&photos));
        match s.map_err(to_py)? {
            Some(inner) => Ok(Scatter { inner }),
            None => Err(PyValueError::new_err("no water-column frames given")),
        }
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

/// The method over a stream of photos held in memory, with memory bounded by the window.
#[pyclass(module = "abysslight._abysslight")]
struct Engine {
    inner: abysslight::Engine<PyObject>,
    /// The shape of the first photo (its rank is given back to every output).
    shape: Option<Shape>,
    options: abysslight::Options,
}

#[pymethods]
impl Engine {
    /// An engine with `correct`'s options by their long names with `_` (`window=9`, `method="paper"`,
    /// `transfer="srgb"`); none given: the command's defaults.
    #[new]
    #[pyo3(signature = (scatter = None, mask = None, **options))]
    fn new(
        scatter: Option<PyRef<'_, Scatter>>,
        mask: Option<PyRef<'_, Mask>>,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Engine> {
        let opts = engine_kwargs(options)?;
        // Arrays carry no file facts: `transfer="auto"` (the default) is what `--transfer auto` assumes for a
        // file that declares nothing, linear; the engine resolves it (`Params::resolved`).
        if opts.method == abysslight::Method::Mean {
            return Err(PyValueError::new_err(
                "method=\"mean\" needs the whole mission's mean image before the first photo; use correct()",
            ));
        }
        let params = opts.params().map_err(to_py)?;
        let mask = mask.map(|m| m.inner.clone());
        let inner = abysslight::Engine::new(params, scatter.as_ref().map(|s| &s.inner), mask)
            .map_err(to_py)?;
        Ok(Engine {
            inner,
            shape: None,
            options: opts,
        })
    }

    /// Give the next photo (HxWx3 or HxW, uint8 or uint16) with a tag of your choice (e.g. its index or file
    /// name). Returns the photos whose window became complete, in order. A photo of another size or dtype than
    /// the first raises ValueError and leaves the engine as it was. The GIL is released while it works.
    #[pyo3(signature = (photo, tag = None))]
    fn push(
        &mut self,
        py: Python<'_>,
        photo: &Bound<'_, PyAny>,
        tag: Option<PyObject>,
    ) -> PyResult<Vec<Corrected>> {
        let (photo, shape) = photo_from_array(photo, "photo")?;
        if let Some(first) = self.shape {
            if first != shape {
                return Err(PyValueError::new_err(format!(
                    "photo is {}, the mission's photos are {}",
                    shape.describe(),
                    first.describe()
                )));
            }
        }
        let tag = tag.unwrap_or_else(|| py.None());
        let inner = &mut self.inner;
        let out = py.allow_threads(|| inner.push(photo, tag)).map_err(to_py)?;
        self.shape.get_or_insert(shape);
        out.into_iter().map(|c| self.corrected(py, c)).collect()
    }

    /// The end of the mission: every photo still waiting, corrected with the window shifted back from the end.
    fn finish(&mut self, py: Python<'_>) -> PyResult<Vec<Corrected>> {
        let inner = &mut self.inner;
        let out = py.allow_threads(|| inner.finish());
        out.into_iter().map(|c| self.corrected(py, c)).collect()
    }

    /// The window `n` in photos.
    #[getter]
    fn window(&self) -> usize {
        self.inner.params().window
    }

    /// The block size `K` (0 until the first photo when `auto` takes it from the photos' size).
    #[getter]
    fn downsample(&self) -> usize {
        self.inner.params().downsample
    }

    /// The camera curve the engine assumes (`srgb`, `linear`, `gamma:G`).
    #[getter]
    fn transfer(&self) -> String {
        self.inner.params().curve().to_string()
    }

    /// The method (`abyss`, `paper`, `polynomial`).
    #[getter]
    fn method(&self) -> String {
        self.options.method.to_string()
    }

    /// Photos pushed and not yet out (waiting for the photos after them).
    #[getter]
    fn waiting(&self) -> usize {
        self.inner.waiting()
    }

    fn __repr__(&self) -> String {
        let p = self.inner.params();
        format!(
            "Engine(method={}, window={}, transfer={})",
            self.options.method,
            p.window,
            p.curve()
        )
    }
}

impl Engine {
    fn corrected(&self, py: Python<'_>, c: abysslight::Corrected<PyObject>) -> PyResult<Corrected> {
        let shape = self.shape.expect("a photo came out, so one went in");
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
            window: (c.window.start, c.window.end),
        })
    }
}

/// The whole of `abysslight correct`: folders in, folders out, the report as a dict.
#[pyfunction]
#[pyo3(signature = (progress = None, **options))]
fn correct(
    py: Python<'_>,
    progress: Option<PyObject>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyObject> {
    let opts = correct_kwargs(options)?;
    let report = progress::run_cancellable(py, &opts, progress)?;
    to_dict(py, &report)
}

/// Run the `abysslight` command with `argv` (the first is the program's name); returns its exit status.
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
    if !(bit_depth == 8 || bit_depth == 16) {
        return Err(PyValueError::new_err(format!(
            "bit_depth must be 8 or 16, got {bit_depth}"
        )));
    }
    if width < 16 || height < 16 || frames == 0 {
        return Err(PyValueError::new_err(
            "width and height must be at least 16 and frames at least 1",
        ));
    }
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
    if !(cell > 0.0 && cell.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "cell must be above 0, got {cell}"
        )));
    }
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
    m.add_function(wrap_pyfunction!(run_cli, m)?)?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
