//! The keyword arguments of `smooth`, `smooth_report` and `smooth_file`: the one place that maps
//! them to the library's [`Options`] and [`EngineSettings`].
//!
//! They mirror `vcsmooth smooth`'s flags in snake_case (`--max-deviation` → `max_deviation`;
//! `--lambda` → `lam`, as `lambda` is a Python keyword). A keyword that is not given keeps the
//! library's default (`Options::default()`, `EngineSettings::default()`), so a default changed
//! in the library changes here too. A new option is one entry of [`KWARGS`] (and, when its keyword
//! is not the library's name of the parameter, one line of `keywords::RENAMED`, which names it
//! in errors).

use std::path::PathBuf;

use pyo3::exceptions::{PyOverflowError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyString};
use vcsmooth::engine::{EngineSettings, Pins, Statistics};
use vcsmooth::{Method, Options};

use crate::arrays;

/// Everything the keyword arguments of a smoothing call set.
#[derive(Debug, Clone, Default)]
pub struct Settings {
    pub options: Options,
    pub engine: EngineSettings,
    /// `smooth_file`: where to write the JSON report.
    pub report: Option<PathBuf>,
    /// `smooth_file`: print one line per iteration on `sys.stderr`.
    pub progress: bool,
}

/// Which calls take a keyword argument.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scope {
    /// `smooth`, `smooth_report` and `smooth_file`.
    Smoothing,
    /// `smooth_file` only (files, the memory budget, reports, progress).
    File,
}

/// One keyword argument: its name, who takes it, what it takes (for messages: "`name` must be
/// `what`, got …"), and how it sets it.
struct Kwarg {
    name: &'static str,
    scope: Scope,
    what: &'static str,
    set: fn(&Bound<'_, PyAny>, &mut Settings) -> PyResult<()>,
}

use Scope::{File, Smoothing};

/// Every keyword argument, in the order of `vcsmooth smooth --help`.
#[rustfmt::skip]
const KWARGS: &[Kwarg] = &[
    Kwarg { name: "method", scope: Smoothing, what: "one of vcsmooth.METHODS", set: |v, s| { s.options.method = method(v)?; Ok(()) } },
    Kwarg { name: "iterations", scope: Smoothing, what: "a non-negative integer or \"auto\"", set: iterations },
    Kwarg { name: "lam", scope: Smoothing, what: "a number", set: |v, s| { s.options.lambda = v.extract()?; Ok(()) } },
    Kwarg { name: "mu", scope: Smoothing, what: "a number or None", set: |v, s| { s.options.mu = v.extract()?; Ok(()) } },
    Kwarg { name: "reject_energy_increase", scope: Smoothing, what: "True or False", set: |v, s| { s.options.reject_energy_increase = v.extract()?; Ok(()) } },
    Kwarg { name: "crease_angle", scope: Smoothing, what: "a number or None", set: |v, s| { s.options.crease_angle = v.extract()?; Ok(()) } },
    Kwarg { name: "max_deviation", scope: Smoothing, what: "a number or None", set: |v, s| { s.options.max_deviation = v.extract()?; Ok(()) } },
    Kwarg { name: "boundary", scope: Smoothing, what: "\"fixed\" or \"smooth\"", set: |v, s| { s.options.boundary = boundary(v)?; Ok(()) } },
    Kwarg { name: "weld", scope: Smoothing, what: "True or False", set: |v, s| { s.options.weld = v.extract()?; Ok(()) } },
    Kwarg { name: "weld_tolerance", scope: Smoothing, what: "a number or None", set: |v, s| { s.options.weld_tolerance = v.extract::<Option<f64>>()?.unwrap_or(0.0); Ok(()) } },
    Kwarg { name: "pinned", scope: Smoothing, what: "vertex indices, a boolean mask or None", set: |v, s| set_pins(s, arrays::pins(v)?) },
    Kwarg { name: "pin", scope: File, what: "a path or None", set: |v, s| set_pins(s, Pins::File(v.extract()?)) },
    Kwarg { name: "pin_property", scope: File, what: "a PLY vertex property name or None", set: |v, s| set_pins(s, Pins::Property(v.extract()?)) },
    Kwarg { name: "threads", scope: Smoothing, what: "a positive integer or None", set: |v, s| { s.engine.threads = if v.is_none() { None } else { Some(count(v)?) }; Ok(()) } },
    Kwarg { name: "patch_size", scope: Smoothing, what: "a positive integer", set: |v, s| { s.engine.patch_size = patch_size(v)?; Ok(()) } },
    Kwarg { name: "stats", scope: Smoothing, what: "\"every\" or \"last\"", set: |v, s| { s.engine.statistics = stats(v)?; Ok(()) } },
    Kwarg { name: "memory_budget", scope: File, what: "a number of bytes, a size such as \"2G\", or None", set: |v, s| { s.engine.memory_budget = memory_budget(v)?; Ok(()) } },
    Kwarg { name: "scratch", scope: File, what: "a path or None", set: |v, s| { s.engine.scratch = v.extract()?; Ok(()) } },
    Kwarg { name: "deviation_field", scope: File, what: "True or False", set: |v, s| { s.engine.deviation.field = v.extract()?; Ok(()) } },
    Kwarg { name: "deviation_colours", scope: File, what: "True or False", set: |v, s| { s.engine.deviation.colours = v.extract()?; Ok(()) } },
    Kwarg { name: "deviation_stats", scope: File, what: "True or False", set: |v, s| { s.engine.deviation.stats = v.extract()?; Ok(()) } },
    Kwarg { name: "tolerance", scope: File, what: "a number or None", set: |v, s| { s.engine.deviation.tolerance = v.extract()?; Ok(()) } },
    Kwarg { name: "report", scope: File, what: "a path or None", set: |v, s| { s.report = v.extract()?; Ok(()) } },
    Kwarg { name: "progress", scope: File, what: "True or False", set: |v, s| { s.progress = v.extract()?; Ok(()) } },
];

impl Settings {
    /// `defaults` with what `kwargs` ask of `function` (`smooth_file` takes the file-only ones
    /// too): a `TypeError` for a keyword `function` does not take or a value of the wrong type,
    /// a `ValueError` for a value out of range (others are checked by the engine).
    pub fn parse(
        function: &str,
        kwargs: Option<&Bound<'_, PyDict>>,
        file: bool,
        defaults: Settings,
    ) -> PyResult<Settings> {
        let mut s = defaults;
        let mut pins_from: Option<&str> = None;
        for (key, value) in kwargs.into_iter().flatten() {
            let key: String = key.extract()?;
            let arg = KWARGS
                .iter()
                .find(|k| k.name == key && (file || k.scope == Smoothing))
                .ok_or_else(|| {
                    PyTypeError::new_err(format!(
                        "{function}() got an unexpected keyword argument '{key}'"
                    ))
                })?;
            // `None` is "not given" for the optional keywords; pins have no default to restore.
            if value.is_none() && arg.name.starts_with("pin") {
                continue;
            }
            if arg.name.starts_with("pin") {
                if let Some(other) = pins_from.replace(arg.name) {
                    return Err(PyValueError::new_err(format!(
                        "{} and {other} cannot both be given",
                        arg.name
                    )));
                }
            }
            (arg.set)(&value, &mut s).map_err(|e| {
                // A conversion error says neither which keyword it is about nor what it takes
                // ("can't convert negative int to unsigned"): say both, and the value given.
                let py = value.py();
                let wrong = || format!("{} must be {}, got {}", arg.name, arg.what, shown(&value));
                if e.is_instance_of::<PyTypeError>(py) {
                    PyTypeError::new_err(wrong())
                } else if e.is_instance_of::<PyOverflowError>(py) {
                    // A negative count or one too large for its type: a value out of range.
                    PyValueError::new_err(wrong())
                } else {
                    e
                }
            })?;
        }
        // The method's own defaults written out, as the command line's report shows them.
        s.options = s.options.resolved();
        Ok(s)
    }
}

/// `value` as Python shows it (its `repr`), cut short when long.
fn shown(value: &Bound<'_, PyAny>) -> String {
    let text = value
        .repr()
        .map(|r| r.to_string())
        .unwrap_or_else(|_| "an object without a repr".into());
    match text.char_indices().nth(60) {
        Some((cut, _)) => format!("{}...", &text[..cut]),
        None => text,
    }
}

/// A count: a Python integer (or NumPy's, anything with `__index__`) that fits `T`; `True` and
/// `False` are refused although Python counts them as integers (`iterations=True` is a slip).
/// The caller's message says what the keyword takes (see [`Settings::parse`]).
fn count<'a, 'py, T>(v: &'a Bound<'py, PyAny>) -> PyResult<T>
where
    T: FromPyObject<'a, 'py>,
    PyErr: From<T::Error>,
{
    if v.is_instance_of::<PyBool>() {
        return Err(PyTypeError::new_err("a bool is not a count"));
    }
    Ok(v.extract()?)
}

fn set_pins(s: &mut Settings, pins: Pins) -> PyResult<()> {
    s.engine.pins = pins;
    Ok(())
}

/// A count, or `"auto"` (`--iterations auto`: stop when the noise is gone, at most
/// `engine::auto::DEFAULT_CAP` iterations).
fn iterations(v: &Bound<'_, PyAny>, s: &mut Settings) -> PyResult<()> {
    if let Ok(text) = v.extract::<String>() {
        if text != "auto" {
            return Err(PyValueError::new_err(format!(
                "iterations must be a non-negative integer or \"auto\", got {}",
                shown(v)
            )));
        }
        s.options.auto_stop = true;
        s.options.iterations = vcsmooth::engine::auto::DEFAULT_CAP;
    } else {
        s.options.auto_stop = false;
        s.options.iterations = count(v)?;
    }
    Ok(())
}

fn boundary(v: &Bound<'_, PyAny>) -> PyResult<vcsmooth::smooth::Boundary> {
    let name: String = v.extract()?;
    name.parse()
        .map_err(|e: String| PyValueError::new_err(format!("boundary: {e}")))
}

fn method(v: &Bound<'_, PyAny>) -> PyResult<Method> {
    let name: String = v.extract()?;
    name.parse()
        .map_err(|e: String| PyValueError::new_err(format!("method: {e}")))
}

fn patch_size(v: &Bound<'_, PyAny>) -> PyResult<usize> {
    let n: u64 = count(v)?;
    // As `--patch-size`: patch ids and local vertex ids are 32-bit.
    if !(1..u32::MAX as u64).contains(&n) {
        return Err(PyValueError::new_err(format!(
            "patch_size must be in 1..{}, got {n}",
            u32::MAX
        )));
    }
    Ok(n as usize)
}

fn stats(v: &Bound<'_, PyAny>) -> PyResult<Statistics> {
    match v.extract::<String>()?.as_str() {
        "every" => Ok(Statistics::Every),
        "last" => Ok(Statistics::Last),
        other => Err(PyValueError::new_err(format!(
            "stats must be 'every' or 'last', got '{other}'"
        ))),
    }
}

/// Bytes, or a size with a K/M/G/T suffix (binary units) as `--memory-budget` takes; `None`: the
/// library's default.
fn memory_budget(v: &Bound<'_, PyAny>) -> PyResult<Option<u64>> {
    if v.is_none() {
        return Ok(None);
    }
    let bytes = match v.cast::<PyString>() {
        Ok(text) => vcsmooth::engine::memory::parse_size(&text.to_string())
            .map_err(|e| PyValueError::new_err(format!("memory_budget: {e}")))?,
        Err(_) => count(v)?,
    };
    vcsmooth::engine::memory::check_budget(bytes).map_err(crate::errors::to_py)?;
    Ok(Some(bytes))
}
