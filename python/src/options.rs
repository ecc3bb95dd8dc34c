//! Keyword arguments to the command's options: each `name=value` becomes `--name value` and the command line's own
//! parser reads them (abysslight::cli::correct_options), so names, defaults and messages are those of
//! `abysslight correct`.

use std::ffi::OsString;

use abysslight::Options;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyString};

/// The options of `correct` that are the method's (the engine's); the others are about files and runs.
const ENGINE_OPTIONS: &[&str] = &[
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
    "no_level_exposures",
    "photo_gain",
    "no_photo_gain",
    "backscatter_scale",
    "denoise",
    "no_denoise",
    "level_by_light",
    "no_level_by_light",
    "bright_spots",
    "overlaps",
];

/// Flags of the command that a Python call has no use for.
const COMMAND_ONLY: &[&str] = &["dry_run", "quiet", "help", "watch"];

/// On/off options the command turns off with `--no-NAME`: `NAME=False` is accepted too.
const NEGATABLE: &[&str] = &["level_exposures", "photo_gain", "denoise", "level_by_light"];

/// The options of an `Engine`: only the method's, with placeholders for the folders `correct` requires.
pub fn engine_kwargs(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Options> {
    let mut args = vec!["--survey".into(), "-".into(), "--out".into(), "-".into()];
    for (k, v) in items(kwargs)? {
        if !ENGINE_OPTIONS.contains(&k.as_str()) {
            return Err(PyTypeError::new_err(format!(
                "Engine() got an unexpected option {k:?} (the method's options of `abysslight correct`: {})",
                ENGINE_OPTIONS.join(", ")
            )));
        }
        push_arg(&mut args, &k, &v)?;
    }
    parse(args)
}

/// The options of `correct()`: every option of `abysslight correct` but the command-only flags.
pub fn correct_kwargs(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Options> {
    let mut args = Vec::new();
    for (k, v) in items(kwargs)? {
        if COMMAND_ONLY.contains(&k.as_str()) {
            return Err(PyTypeError::new_err(format!(
                "correct() got an unexpected option {k:?} (a flag of the command line only)"
            )));
        }
        push_arg(&mut args, &k, &v)?;
    }
    parse(args)
}

fn items<'py>(kwargs: Option<&Bound<'py, PyDict>>) -> PyResult<Vec<(String, Bound<'py, PyAny>)>> {
    let Some(d) = kwargs else {
        return Ok(Vec::new());
    };
    d.iter()
        .map(|(k, v)| Ok((k.extract::<String>()?, v)))
        .collect()
}

/// `name=value` as command-line arguments: None is left out (the default), True gives the flag, False leaves it
/// out (or gives `--no-NAME`), a sequence is joined by commas (`seafloor_colour=(0.42, 0.36, 0.28)`), a path or
/// anything else is its string.
fn push_arg(args: &mut Vec<OsString>, key: &str, v: &Bound<'_, PyAny>) -> PyResult<()> {
    if key.contains('-') || key.starts_with('_') || key.is_empty() {
        return Err(PyTypeError::new_err(format!(
            "unexpected option {key:?}: options are the command's long names with '_' (window=9, seafloor_colour=...)"
        )));
    }
    let flag = format!("--{}", key.replace('_', "-"));
    if v.is_none() {
        return Ok(());
    }
    if let Ok(b) = v.downcast::<PyBool>() {
        match (b.is_true(), NEGATABLE.contains(&key)) {
            (true, true) => {}
            (true, false) => args.push(flag.into()),
            (false, true) => args.push(format!("--no-{}", key.replace('_', "-")).into()),
            (false, false) => {}
        }
        return Ok(());
    }
    let text = if v.downcast::<PyString>().is_ok() {
        v.extract::<String>()?
    } else if let Ok(p) = v.extract::<std::path::PathBuf>() {
        p.to_string_lossy().into_owned()
    } else if let Ok(items) = v.extract::<Vec<Bound<'_, PyAny>>>() {
        items
            .iter()
            .map(|i| i.str().map(|s| s.to_string()))
            .collect::<PyResult<Vec<_>>>()?
            .join(",")
    } else {
        v.str()?.to_string()
    };
    if NEGATABLE.contains(&key) {
        return Err(PyValueError::new_err(format!(
            "{key} must be True or False, got {text:?}"
        )));
    }
    // `--name=value`, so that a value starting with '-' is not taken for a flag.
    args.push(format!("{flag}={text}").into());
    Ok(())
}

/// Parse as `abysslight correct ARGS` would: an unknown argument is a TypeError, a bad value a ValueError.
fn parse(args: Vec<OsString>) -> PyResult<Options> {
    let argv = ["abysslight".into(), "correct".into()]
        .into_iter()
        .chain(args);
    abysslight::cli::correct_options(argv).map_err(|(unknown, message)| {
        let m = tidy(&message);
        if unknown {
            PyTypeError::new_err(m)
        } else {
            PyValueError::new_err(m)
        }
    })
}

/// The parser's message without its usage lines and `error: ` prefix, flags named as Python options.
fn tidy(message: &str) -> String {
    let head = message.split("\n\nUsage:").next().unwrap_or(message);
    let head = head
        .split("\n\nFor more information")
        .next()
        .unwrap_or(head);
    head.trim().trim_start_matches("error: ").to_string()
}
