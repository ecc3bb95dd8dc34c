//! Keyword arguments to [`abysslight::Options`] through serde: each `name=value` becomes the config file's key
//! (`seafloor_colour` is `seafloor-colour`) with the value as JSON, over [`Options::default`] (or over a
//! `config=` file, as `--config` is read), and `Options`' own `Deserialize` reads them: the names, defaults and
//! value forms are those of the config file and the command; then the command's checks ([`Options::validate`],
//! [`Options::params`]). No command-line parser is involved.

use std::path::PathBuf;

use abysslight::Options;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use serde_json::{Map, Value};

use crate::to_py;

/// The options of `correct` that are the method's (the engine's); the others are about files and runs.
const METHOD_OPTIONS: &[&str] = &[
    "window",
    "contamination",
    "risk",
    "downsample",
    "near_window",
    "seafloor_colour",
    "factor_floor",
    "transfer",
    "method",
    "degree",
    "relative_floor",
    "level_exposures",
    "photo_gain",
    "backscatter_scale",
    "denoise",
    "level_by_light",
    "bright_spots",
    "overlaps",
    "laser_paths",
];

/// Fields of `Options` that a Python call has no use for: `watch` runs until stopped.
const COMMAND_ONLY: &[&str] = &["watch"];

/// On/off options the command turns off with `--no-NAME`: `no_NAME=True` is accepted too.
const NEGATABLE: &[&str] = &[
    "level_exposures",
    "photo_gain",
    "denoise",
    "level_by_light",
    "laser_paths",
];

/// Options whose value is a path: set on `Options` directly (a path need not be valid UTF-8, which JSON needs).
const PATHS: &[&str] = &[
    "water_column",
    "scatter",
    "survey",
    "out",
    "mask",
    "report",
    "navigation",
];

/// Fields of `Options` that a config file and `correct()` take but that `Options::default()` leaves out when
/// serialised (left at their default, a report does not name them).
const UNLISTED_WHEN_DEFAULT: &[&str] = &["navigation_columns", "navigation_clock_offset"];

/// Keyword arguments of `correct()` that are not fields of `Options`.
const CORRECT_EXTRAS: &[&str] = &["config", "cruise"];

/// What the call takes: `Engine()` and `correct_arrays()` the method's options, `correct()` every option.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Scope {
    Engine,
    Correct,
}

/// `correct()`'s options, and the cruise folder when `cruise=` was given.
pub struct CorrectOptions {
    pub options: Options,
    pub cruise: Option<PathBuf>,
}

/// The options of an `Engine` (or of `correct_arrays`): only the method's, checked as a run checks them.
pub fn engine_kwargs(kwargs: Option<&Bound<'_, PyDict>>, caller: &str) -> PyResult<Options> {
    let given = given(kwargs, Scope::Engine, caller)?;
    let opts = build(Options::default(), &given)?;
    opts.validate().map_err(to_py)?;
    opts.params().map_err(to_py)?;
    Ok(opts)
}

/// The options of `correct()`: every option of `abysslight correct` but `watch`, with `config=` read first as
/// `--config` is and the keywords over it, and `cruise=`.
pub fn correct_kwargs(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<CorrectOptions> {
    let mut given = given(kwargs, Scope::Correct, "correct()")?;
    let config = take_path(&mut given, "config")?;
    let cruise = take_path(&mut given, "cruise")?;
    let base = match &config {
        Some(p) => Options::from_toml_file(p).map_err(to_py)?,
        None => Options::default(),
    };
    if cruise.is_some() {
        if let Some((k, _)) = given
            .iter()
            .find(|(k, _)| k == "survey" || k == "water_column" || k == "navigation")
        {
            return Err(PyValueError::new_err(format!(
                "give either cruise or {k}: a cruise gives each dive its survey/ and water-column/ folders \
                 (and its navigation.csv)"
            )));
        }
    }
    let options = build(base, &given)?;
    if cruise.is_none() {
        required(&options.survey, "survey")?;
    }
    required(&options.out, "out")?;
    options.validate().map_err(to_py)?;
    options.params().map_err(to_py)?;
    // The config file is an input too: no output may overwrite or surround it (as the command checks).
    if let Some(cfg) = &config {
        let outs: Vec<(&str, &std::path::Path)> = [
            ("out", options.out.as_deref()),
            ("report", options.report.as_deref()),
        ]
        .into_iter()
        .filter_map(|(f, p)| Some((f, p.filter(|p| *p != std::path::Path::new("-"))?)))
        .collect();
        abysslight::io::check_outputs(&outs, &[("config file", cfg)]).map_err(to_py)?;
    }
    Ok(CorrectOptions { options, cruise })
}

/// A folder `correct` needs, with the command's message.
fn required(p: &Option<PathBuf>, name: &str) -> PyResult<()> {
    match p {
        Some(_) => Ok(()),
        None => Err(PyValueError::new_err(format!(
            "{name} is required: {name}=\"DIR\" (or {name} = \"DIR\" in the config file)"
        ))),
    }
}

/// A message of the library (written for the command line) as Python speaks: each `--flag-name` as the keyword
/// `flag_name` (`--window must be odd` → `window must be odd`, `--no-denoise` → `no_denoise`).
pub fn keyword_names(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    let mut rest = message;
    while let Some(i) = rest.find("--") {
        let (before, after) = rest.split_at(i);
        out.push_str(before);
        let name_len = after[2..]
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
            .unwrap_or(after.len() - 2);
        let name = &after[2..2 + name_len];
        let starts_word =
            before.is_empty() || !before.ends_with(|c: char| c.is_ascii_alphanumeric());
        if starts_word && name.starts_with(|c: char| c.is_ascii_lowercase()) {
            out.push_str(&name.replace('-', "_"));
        } else {
            out.push_str(&after[..2 + name_len]);
        }
        rest = &after[2 + name_len..];
    }
    out.push_str(rest);
    out
}

/// The accepted name nearest to a misspelt `key` (at most a third of its letters off), for "did you mean".
fn nearest<'a>(key: &str, accepted: &'a [String]) -> Option<&'a str> {
    let distance = |a: &str, b: &str| -> usize {
        let b: Vec<char> = b.chars().collect();
        let mut row: Vec<usize> = (0..=b.len()).collect();
        for (i, ca) in a.chars().enumerate() {
            let mut diag = row[0];
            row[0] = i + 1;
            for (j, &cb) in b.iter().enumerate() {
                let next = (diag + usize::from(ca != cb))
                    .min(row[j] + 1)
                    .min(row[j + 1] + 1);
                diag = row[j + 1];
                row[j + 1] = next;
            }
        }
        row[b.len()]
    };
    let key = key.to_lowercase().replace('-', "_");
    accepted
        .iter()
        .map(|a| (distance(&key, a), a.as_str()))
        .filter(|&(d, _)| d <= (key.chars().count() / 3).max(1))
        .min_by_key(|&(d, _)| d)
        .map(|(_, a)| a)
}

/// A keyword's value, converted: a path, or the JSON value of a config file's key.
enum Given {
    Path(PathBuf),
    Json(Value),
}

/// The keywords as `(option name, value)`, names normalised (`seafloor_color`, `no_NAME`), `None` left out.
fn given(
    kwargs: Option<&Bound<'_, PyDict>>,
    scope: Scope,
    caller: &str,
) -> PyResult<Vec<(String, Given)>> {
    let Some(d) = kwargs else {
        return Ok(Vec::new());
    };
    let accepted = accepted(scope);
    let mut out: Vec<(String, Given)> = Vec::new();
    for (k, v) in d.iter() {
        let key: String = k.extract()?;
        if !accepted.contains(&key) {
            let hint = nearest(&key, &accepted)
                .map(|n| format!(" (did you mean `{n}`?)"))
                .unwrap_or_default();
            return Err(PyTypeError::new_err(format!(
                "{caller} got an unexpected option {key:?}{hint}; accepted: {}",
                accepted.join(", ")
            )));
        }
        if v.is_none() {
            continue;
        }
        let (name, value) = if let Some(base) = key.strip_prefix("no_") {
            let Ok(b) = v.downcast::<PyBool>() else {
                return Err(PyTypeError::new_err(format!(
                    "{key} must be True or False, got {}",
                    v.get_type().name()?
                )));
            };
            (base.to_string(), Given::Json(Value::Bool(!b.is_true())))
        } else {
            let name = if key == "seafloor_color" {
                "seafloor_colour".to_string()
            } else {
                key.clone()
            };
            let value = if PATHS.contains(&name.as_str()) || CORRECT_EXTRAS.contains(&name.as_str())
            {
                Given::Path(path(&key, &v)?)
            } else {
                Given::Json(json(&key, &name, &v)?)
            };
            (name, value)
        };
        if out.iter().any(|(n, _)| *n == name) {
            let alias = if name == "seafloor_colour" {
                "seafloor_color".to_string()
            } else {
                format!("no_{name}")
            };
            return Err(PyValueError::new_err(format!(
                "give either {name} or {alias}, not both"
            )));
        }
        out.push((name, value));
    }
    Ok(out)
}

/// The keyword names a call accepts: `Options`' fields (the config file's keys with `_`) of its scope, the
/// `no_NAME` forms, `seafloor_color`, and `correct()`'s `config` and `cruise`.
fn accepted(scope: Scope) -> Vec<String> {
    let fields: Vec<String> = match serde_json::to_value(Options::default()) {
        Ok(Value::Object(m)) => m.keys().map(|k| k.replace('-', "_")).collect(),
        _ => Vec::new(),
    };
    let mut names: Vec<String> = fields
        .into_iter()
        .filter(|f| match scope {
            Scope::Engine => METHOD_OPTIONS.contains(&f.as_str()),
            Scope::Correct => !COMMAND_ONLY.contains(&f.as_str()),
        })
        .collect();
    let negatable: Vec<String> = names
        .iter()
        .filter(|n| NEGATABLE.contains(&n.as_str()))
        .map(|n| format!("no_{n}"))
        .collect();
    names.extend(negatable);
    names.push("seafloor_color".into());
    if scope == Scope::Correct {
        names.extend(CORRECT_EXTRAS.iter().map(|s| s.to_string()));
        names.extend(UNLISTED_WHEN_DEFAULT.iter().map(|s| s.to_string()));
    }
    names.sort();
    names
}

fn take_path(given: &mut Vec<(String, Given)>, name: &str) -> PyResult<Option<PathBuf>> {
    let Some(i) = given.iter().position(|(n, _)| n == name) else {
        return Ok(None);
    };
    match given.remove(i).1 {
        Given::Path(p) => Ok(Some(p)),
        Given::Json(_) => Err(PyTypeError::new_err(format!("{name} must be a path"))),
    }
}

/// A path: a `str` or an `os.PathLike`.
fn path(key: &str, v: &Bound<'_, PyAny>) -> PyResult<PathBuf> {
    if v.downcast::<PyString>().is_ok() || v.hasattr("__fspath__")? {
        if let Ok(p) = v.extract::<PathBuf>() {
            return Ok(p);
        }
    }
    Err(PyTypeError::new_err(format!(
        "{key} must be a path (str or os.PathLike), got {}",
        v.get_type().name()?
    )))
}

/// A value as the config file would hold it: bool, integer, finite number or string; a sequence of numbers for
/// `seafloor_colour` (the file's `"r,g,b"`), an integer for `jpeg_subsampling` (`420`). Anything else (bytes, a
/// dict, an object) is a TypeError.
fn json(key: &str, name: &str, v: &Bound<'_, PyAny>) -> PyResult<Value> {
    let type_error = || -> PyResult<Value> {
        Err(PyTypeError::new_err(format!(
            "{key} must be a number, a string or True/False as the option takes, got {}",
            v.get_type().name()?
        )))
    };
    if v.downcast::<PyBytes>().is_ok() {
        return type_error();
    }
    if let Ok(b) = v.downcast::<PyBool>() {
        return Ok(Value::Bool(b.is_true()));
    }
    if v.downcast::<PyString>().is_ok() {
        return Ok(Value::String(v.extract::<String>()?));
    }
    if v.downcast::<PyInt>().is_ok() || (v.hasattr("__index__")? && !v.hasattr("__len__")?) {
        let n: i128 = v
            .call_method0("__index__")?
            .extract()
            .map_err(|_| PyValueError::new_err(format!("{key} is too large")))?;
        if name == "jpeg_subsampling" {
            return Ok(Value::String(n.to_string()));
        }
        return match (i64::try_from(n), u64::try_from(n)) {
            (Ok(i), _) => Ok(Value::from(i)),
            (_, Ok(u)) => Ok(Value::from(u)),
            _ => Err(PyValueError::new_err(format!(
                "{key} is too large, got {n}"
            ))),
        };
    }
    if v.downcast::<PyFloat>().is_ok() || (v.hasattr("__float__")? && !v.hasattr("__len__")?) {
        let f: f64 = v.call_method0("__float__")?.extract()?;
        return serde_json::Number::from_f64(f)
            .map(Value::Number)
            .ok_or_else(|| {
                PyValueError::new_err(format!("{key} must be a finite number, got {f}"))
            });
    }
    if name == "seafloor_colour"
        && (v.downcast::<PyList>().is_ok() || v.downcast::<PyTuple>().is_ok())
    {
        let parts = v
            .try_iter()?
            .map(|i| {
                let i = i?;
                match i.extract::<f64>() {
                    Ok(f) if i.downcast::<PyBool>().is_err() => Ok(f.to_string()),
                    _ => Err(PyTypeError::new_err(format!(
                        "{key} must be a colour (\"#8a7560\", \"grey\") or numbers (r, g, b), got an item of type {}",
                        i.get_type().name()?
                    ))),
                }
            })
            .collect::<PyResult<Vec<_>>>()?;
        return Ok(Value::String(parts.join(",")));
    }
    // The log's columns as a dict of names ({"time": "t_log", "altitude": "range"}), as a config file's table.
    if name == "navigation_columns" {
        if let Ok(d) = v.downcast::<PyDict>() {
            let mut table = Map::new();
            for (k, n) in d.iter() {
                let (Ok(k), Ok(n)) = (k.extract::<String>(), n.extract::<String>()) else {
                    return Err(PyTypeError::new_err(format!(
                        "{key} must map file, time or altitude to a column name (str), e.g. {{\"time\": \"t_log\"}}"
                    )));
                };
                table.insert(k, Value::String(n));
            }
            return Ok(Value::Object(table));
        }
    }
    type_error()
}

/// `base` with the given options over it, read by `Options`' `Deserialize`. A window given undoes the base's
/// contamination and the other way round, a water column the base's scatter image and the other way round, as
/// the command's flags undo a config file's.
fn build(base: Options, given: &[(String, Given)]) -> PyResult<Options> {
    let has = |n: &str| given.iter().any(|(k, _)| k == n);
    let mut base = base;
    // Paths go around JSON (they need not be UTF-8) and come back afterwards.
    let mut paths = [
        base.water_column.take(),
        base.scatter.take(),
        base.survey.take(),
        base.out.take(),
        base.mask.take(),
        base.report.take(),
        base.navigation.take(),
    ];
    let Value::Object(mut map) =
        serde_json::to_value(&base).map_err(|e| PyValueError::new_err(e.to_string()))?
    else {
        return Err(PyValueError::new_err("options are not a table"));
    };
    for (a, b) in [("window", "contamination"), ("contamination", "window")] {
        if has(a) && !has(b) {
            map.insert(b.into(), Value::Null);
        }
    }
    let base_map = map.clone();
    for (name, value) in given {
        match value {
            Given::Json(v) => {
                map.insert(name.replace('_', "-"), v.clone());
            }
            Given::Path(p) => {
                let i = PATHS.iter().position(|n| n == name).expect("a path option");
                paths[i] = Some(p.clone());
            }
        }
    }
    if has("water_column") && !has("scatter") {
        paths[1] = None;
    }
    if has("scatter") && !has("water_column") {
        paths[0] = None;
    }
    let mut opts: Options = serde_json::from_value(Value::Object(map)).map_err(|e| {
        // Name the option: the first one given that fails alone over the base.
        let culprit = given.iter().find(|(name, value)| match value {
            Given::Json(v) => {
                let mut one: Map<String, Value> = base_map.clone();
                one.insert(name.replace('_', "-"), v.clone());
                serde_json::from_value::<Options>(Value::Object(one)).is_err()
            }
            Given::Path(_) => false,
        });
        let message = match culprit {
            Some((name, _)) => format!("{name}: {e}"),
            None => e.to_string(),
        };
        if message.contains("invalid type") {
            PyTypeError::new_err(message)
        } else {
            PyValueError::new_err(message)
        }
    })?;
    let [water_column, scatter, survey, out, mask, report, navigation] = paths;
    opts.water_column = water_column;
    opts.scatter = scatter;
    opts.survey = survey;
    opts.out = out;
    opts.mask = mask;
    opts.report = report;
    opts.navigation = navigation;
    Ok(opts)
}
