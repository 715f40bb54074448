//! The `vcsmooth` Python package's native module (`vcsmooth._vcsmooth`): NumPy arrays in and
//! out of the vcsmooth library.
//!
//! - [`arrays`]: vertices, faces and pins from any NumPy layout and dtype the package takes,
//!   checked; arrays back.
//! - [`options`]: the keyword arguments, the one place that maps them to the library's
//!   `Options` and `EngineSettings`.
//! - [`run`]: the library's work on a thread of its own without the GIL, stopped by Ctrl-C.
//! - [`errors`]: the library's errors as Python exceptions, `vcsmooth.MeshError`.
//! - [`keywords`]: the library's parameter names that Python callers know by another keyword
//!   (`lambda` → `lam`), for the messages of errors.
//!
//! Every smoothing call goes through the library's engine (`vcsmooth::smooth_with`,
//! `vcsmooth::engine::run_file`), so its results are the CLI's, bit for bit.

use std::path::{Path, PathBuf};

use numpy::PyArray2;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use serde::Serialize;
use vcsmooth::engine::{self, Statistics};
use vcsmooth::report::{InfoDoc, SmoothReport, undefined_as_nan};
use vcsmooth::{Mesh, Method};

mod arrays;
mod errors;
mod keywords;
mod options;
mod run;

use errors::{MeshError, to_py};
use options::Settings;
use run::without_gil;

/// What the reports and `info` name as the file of a mesh given as arrays.
const IN_MEMORY: &str = "<memory>";

/// Check that a mesh can be written to `path` before any work: an existing directory
/// (`FileNotFoundError` / `NotADirectoryError` otherwise, as `open` raises) and an extension the
/// writer knows (`MeshError`).
fn check_output(path: &Path) -> PyResult<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if let Err(e) = std::fs::read_dir(dir) {
            return Err(to_py(vcsmooth::Error::io(dir, e)));
        }
    }
    vcsmooth::cli::output::mesh_output(path).map_err(to_py)
}

/// Check that `path` is not a directory, which the library reports as a malformed mesh: the
/// system's own error (`IsADirectoryError`), as `open` raises it.
fn check_not_directory(path: &Path) -> PyResult<()> {
    use std::io::Read;
    if path.is_dir() {
        let read = std::fs::File::open(path).and_then(|mut f| f.read(&mut [0u8; 1]));
        if let Err(e) = read {
            return Err(to_py(vcsmooth::Error::io(path, e)));
        }
    }
    Ok(())
}

/// The mesh of `vertices` and `faces`, checked (see [`arrays`]).
fn mesh_of(vertices: &Bound<'_, PyAny>, faces: &Bound<'_, PyAny>) -> PyResult<Mesh> {
    let positions = arrays::vertices(vertices)?;
    let triangles = arrays::faces(faces, positions.len())?;
    Ok(Mesh::new(positions, triangles))
}

/// `value` as a Python object through JSON, as the CLI writes it (NaN as `None`).
fn to_python<'py>(py: Python<'py>, value: &impl Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// The `--report` document of a run of `settings` (what `vcsmooth smooth --report` writes).
fn report_of(
    function: &str,
    settings: &Settings,
    run: &engine::Report,
    files: (&Path, &Path),
) -> SmoothReport {
    SmoothReport::new(
        vec![format!("vcsmooth.{function}")],
        settings.options,
        settings.engine.clone(),
        files,
        run,
        None,
    )
}

/// Smooth the arrays with `settings` on the engine; the positions and the run's report.
fn smooth_arrays<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    settings: &Settings,
) -> PyResult<(Bound<'py, PyArray2<f64>>, engine::Report)> {
    let mut mesh = mesh_of(vertices, faces)?;
    let (opts, engine) = (&settings.options, &settings.engine);
    let report = without_gil(py, false, |observer| {
        vcsmooth::smooth_with(&mut mesh, opts, engine, observer)
    })?;
    Ok((arrays::positions_out(py, &mesh.positions), report))
}

/// Smooth a triangle mesh and return its new vertex positions, an ``(n, 3)`` float64 array
/// (the inputs are not modified).
///
/// ``vertices``: ``(n, 3)`` float32 or float64, any memory layout (C, Fortran, strided views).
/// ``faces``: ``(m, 3)`` of any integer type, 0-based indices into ``vertices``, outward faces
/// counter-clockwise. Both may be anything ``numpy.asarray`` takes (e.g. trimesh's arrays).
///
/// Keyword arguments (those of ``vcsmooth smooth``, in snake_case):
///
/// - ``method``: one of ``vcsmooth.METHODS`` (what each does: ``vcsmooth smooth --help``);
///   default: the library's default method, ``vcsmooth.DEFAULT_METHOD``.
/// - ``iterations`` (10, or ``"auto"``: stop when the noise is gone, after at most 100), ``lam`` (0.5, the Laplacian step λ, in (0, 1]), ``mu`` (None: the
///   method's own, -0.53 for taubin and -0.52 for vcs-lowpass; Taubin's second step, in [-1, 0)), ``reject_energy_increase`` (False).
/// - ``crease_angle`` (None): vertices on edges whose faces' normals differ by more than this
///   many degrees, in (0, 180), stay where they are.
/// - ``max_deviation`` (None): no vertex ends farther than this from its input position.
/// - ``boundary`` (``"fixed"``): ``"smooth"`` smooths each boundary loop keeping each hole's
///   size (with the methods that take it, which ``vcsmooth smooth --help`` lists).
/// - ``weld`` (True): vertices at exactly one position (a texture seam's or unmerged corners'
///   copies) are one vertex to smooth, and each copy gets the same new position; False keeps
///   them apart, each seam a boundary that never moves.
/// - ``pinned`` (None): vertices that do not move: indices, or a boolean mask of length n.
/// - ``threads`` (None: all cores), ``patch_size`` (16384: part of the result's definition).
/// - ``stats`` (``"last"`` here): which iterations measure volume and area; the positions are
///   the same either way.
///
/// The result is bit-identical to ``vcsmooth smooth``'s positions (before the output file's
/// rounding) for the same options, for any ``threads``. Boundary vertices never move. The GIL is
/// released while smoothing; Ctrl-C raises ``KeyboardInterrupt`` after the current iteration.
///
/// Raises ``ValueError`` for arrays of the wrong shape or dtype, coordinates that are NaN or
/// infinite, an index out of range and options out of range (each named); ``TypeError`` for an
/// unknown keyword.
#[pyfunction]
#[pyo3(signature = (vertices, faces, **options))]
fn smooth<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    // Nobody reads the iterations' statistics: measure only the last (the positions are the same).
    let mut defaults = Settings::default();
    defaults.engine.statistics = Statistics::Last;
    let settings = Settings::parse("smooth", options, false, defaults)?;
    Ok(smooth_arrays(py, vertices, faces, &settings)?.0)
}

/// ``smooth`` with the run's report: returns ``(vertices, report)``, where ``report`` is the
/// dictionary ``vcsmooth smooth --report FILE.json`` writes (``options``, ``engine``, ``input``
/// and ``output`` statistics, ``plan``, ``timings``, ``disk``, ``summary`` and ``iterations``,
/// one row per iteration: ``volume_pct``, ``area_pct``, ``max_displacement``,
/// ``mean_displacement``, ``stencils``, ``seconds``). Figures that were not measured are
/// ``None``. The mesh's "file" is ``"<memory>"``. Takes the keyword arguments of ``smooth``; ``stats`` defaults to
/// ``"every"``, as on the command line.
#[pyfunction]
#[pyo3(signature = (vertices, faces, **options))]
fn smooth_report<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let mut settings = Settings::parse("smooth_report", options, false, Settings::default())?;
    settings.engine.with_stats = true;
    let (positions, run) = smooth_arrays(py, vertices, faces, &settings)?;
    let memory = Path::new(IN_MEMORY);
    let report = report_of("smooth_report", &settings, &run, (memory, memory));
    PyTuple::new(py, [positions.into_any(), to_python(py, &report)?])
}

/// Smooth the mesh file ``input`` into ``output`` (its format from the extension: .ply, .obj,
/// .off, .stl, .gltf, .glb) exactly as ``vcsmooth smooth input output`` does, with the same
/// output bytes: the file-to-file engine, which works from memory-mapped scratch files when the
/// mesh does not fit the memory budget, and keeps everything else the file carries. Returns the
/// report dictionary (see ``smooth_report``).
///
/// Takes the keyword arguments of ``smooth`` (``pinned`` indexes the file's vertices; ``stats``
/// defaults to ``"every"``) and:
///
/// - ``pin`` (a text file of vertex indices) or ``pin_property`` (a PLY vertex property whose
///   non-zero values pin), instead of ``pinned``.
/// - ``memory_budget``: bytes, or a size such as ``"2G"`` (default: 3/4 of available memory).
/// - ``scratch``: a directory for scratch files (default: the output's directory).
/// - ``deviation_field`` (False): write each vertex's deviation from the input (along its
///   normal) into a PLY ``output`` as the vertex property ``quality``; ``deviation_colours``
///   (False) also as ``red green blue``. ``deviation_stats`` (False; implied by the others and by
///   ``tolerance``): the report's ``deviation`` (RMS, mean, percentiles, histogram).
/// - ``tolerance`` (None): the report's ``deviation["tolerance"]`` says how many vertices moved
///   farther (``beyond``) and whether none did (``within``); nothing is raised.
/// - ``report``: a path to write the report to as JSON, as ``--report`` does.
/// - ``progress`` (False): print one line per iteration on ``sys.stderr``.
///
/// The output is written to a temporary file and renamed into place: on any error, and on
/// Ctrl-C (``KeyboardInterrupt`` after the current iteration), the previous ``output`` is
/// untouched and no partial file is left. Raises ``OSError`` (``FileNotFoundError``, …) for files
/// the system refuses, ``vcsmooth.MeshError`` for a file that is not a readable mesh or an
/// unknown output extension, ``ValueError`` for options out of range.
#[pyfunction]
#[pyo3(signature = (input, output, **options))]
fn smooth_file<'py>(
    py: Python<'py>,
    input: PathBuf,
    output: PathBuf,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let mut settings = Settings::parse("smooth_file", options, true, Settings::default())?;
    // The checks `vcsmooth smooth` makes before reading anything.
    check_not_directory(&input)?;
    check_output(&output)?;
    let sides: Vec<(&str, &Path)> = settings
        .report
        .as_deref()
        .map(|r| ("report", r))
        .into_iter()
        .collect();
    vcsmooth::cli::output::check_files(&[("input", &input)], Some(("output", &output)), &sides)
        .map_err(to_py)?;
    settings.engine.with_stats = true;
    let (opts, engine) = (&settings.options, &settings.engine);
    let (input_ref, output_ref) = (&input, &output);
    let run = without_gil(py, settings.progress, |observer| {
        engine::run_file(input_ref, output_ref, opts, engine, observer)
    })?;
    let report = report_of("smooth_file", &settings, &run, (&input, &output));
    if let Some(path) = &settings.report {
        vcsmooth::cli::output::write_json(path, &report).map_err(to_py)?;
    }
    to_python(py, &report)
}

/// Read a mesh file (PLY, OBJ, OFF, STL, glTF; the format from its content or extension) and
/// return ``(vertices, faces)``: ``(n, 3)`` float64 and ``(m, 3)`` int64, in the file's vertex
/// order. Polygons are fan-triangulated. Raises ``OSError`` when the file cannot be read and
/// ``vcsmooth.MeshError`` when it is not a mesh the library reads (the message says where).
#[pyfunction]
fn read_mesh<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyTuple>> {
    check_not_directory(&path)?;
    let mesh = without_gil(py, false, |_| vcsmooth::io::read_mesh(&path))?;
    PyTuple::new(
        py,
        [
            arrays::positions_out(py, &mesh.positions).into_any(),
            arrays::faces_out(py, &mesh.triangles).into_any(),
        ],
    )
}

/// Write a triangle mesh to ``path``, its format from the extension (.ply, binary; .obj; .off;
/// .stl, always float32). Coordinates are written as float32 when they all are float32 values,
/// else as float64 (PLY ``double``, text that reads back to the same float64): nothing is
/// rounded. Written to a temporary file and renamed into place. Takes the arrays ``smooth``
/// takes and raises what it raises, plus ``OSError`` for the file and ``vcsmooth.MeshError`` for
/// an unknown extension.
#[pyfunction]
fn write_mesh(
    py: Python<'_>,
    path: PathBuf,
    vertices: &Bound<'_, PyAny>,
    faces: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let mut mesh = mesh_of(vertices, faces)?;
    check_output(&path)?;
    // Lossless: double precision when a coordinate is not a float32 (smoothed float64 positions).
    let exact = |x: f64| x as f32 as f64 == x;
    if !mesh
        .positions
        .iter()
        .all(|p| p.to_array().into_iter().all(exact))
    {
        mesh.source.precision = vcsmooth::mesh::Precision::Double;
    }
    without_gil(py, false, |_| vcsmooth::io::write_mesh(&path, &mesh))
}

/// Describe a mesh: the dictionary ``vcsmooth info --json`` prints (vertices, triangles, edges,
/// boundary and non-manifold edges and vertices, degenerate triangles, orientation, components,
/// unreferenced vertices, ``closed``, ``volume``, ``area``, bounding box, mean edge length,
/// roughness), with ``path`` ``"<memory>"``. Figures a mesh does not define are ``None``.
#[pyfunction]
fn info<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let mesh = mesh_of(vertices, faces)?;
    let doc = without_gil(py, false, |_| {
        Ok(InfoDoc {
            path: IN_MEMORY.to_string(),
            format: None,
            info: undefined_as_nan(&vcsmooth::engine::mesh_info(&mesh, vcsmooth::partition::Weld::Exact)?),
            carries: Default::default(),
        })
    })?;
    to_python(py, &doc)
}

#[pymodule]
fn _vcsmooth(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("RESULTS_VERSION", vcsmooth::RESULTS_VERSION)?;
    m.add("DEFAULT_METHOD", Method::default().name())?;
    let methods: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
    m.add("METHODS", PyTuple::new(m.py(), methods)?)?;
    m.add("MeshError", m.py().get_type::<MeshError>())?;
    m.add_function(wrap_pyfunction!(smooth, m)?)?;
    m.add_function(wrap_pyfunction!(smooth_report, m)?)?;
    m.add_function(wrap_pyfunction!(smooth_file, m)?)?;
    m.add_function(wrap_pyfunction!(read_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(write_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(info, m)?)?;
    Ok(())
}
