//! NumPy arrays in and out: `(n, 3)` vertices of float32 or float64 and `(m, 3)` faces of any
//! integer type, in any memory layout (C, Fortran, strided views), copied into the library's
//! `DVec3` and `[u32; 3]`; and `(n, 3)` float64 / int64 arrays back. Every check raises a
//! `ValueError` that names the array and, for a bad value, its row.

use glam::DVec3;
use numpy::ndarray::{Array2, ArrayView2};
use numpy::{
    Element, IntoPyArray, PyArray1, PyArray2, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use vcsmooth::engine::Pins;

/// `obj` as a NumPy array: itself, or `numpy.asarray(obj)` for lists, tuples and other array-likes.
fn as_array<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(a) = obj.cast::<PyUntypedArray>() {
        return Ok(a.clone());
    }
    let numpy = obj.py().import("numpy")?;
    let a = numpy.call_method1("asarray", (obj,))?;
    Ok(a.cast_into::<PyUntypedArray>()?)
}

/// The array `obj` (called `name` in errors), checked to be two-dimensional with 3 columns.
fn rows_of_three<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Bound<'py, PyUntypedArray>> {
    let a = as_array(obj)?;
    if a.ndim() != 2 || a.shape()[1] != 3 {
        let dims: Vec<String> = a.shape().iter().map(|d| d.to_string()).collect();
        // As Python prints a tuple: `(5,)` for one dimension.
        let comma = if dims.len() == 1 { "," } else { "" };
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (n, 3), got ({}{comma})",
            dims.join(", ")
        )));
    }
    Ok(a)
}

/// The dtype of `a` as NumPy prints it (`int64`, `>f8`, …).
fn dtype_name(a: &Bound<'_, PyUntypedArray>) -> String {
    a.dtype()
        .str()
        .map(|s| s.to_string())
        .unwrap_or_else(|_| "unknown".into())
}

/// `a`'s elements as a view when its dtype is `T` (native byte order), any strides.
fn with_view<T: Element, R>(
    a: &Bound<'_, PyUntypedArray>,
    f: impl FnOnce(ArrayView2<'_, T>) -> PyResult<R>,
) -> Option<PyResult<R>> {
    let typed = a.cast::<PyArray2<T>>().ok()?;
    Some(match typed.try_readonly() {
        Ok(r) => f(r.as_array()),
        Err(e) => Err(PyValueError::new_err(e.to_string())),
    })
}

/// `vertices`: `(n, 3)` float32 or float64, every coordinate finite.
pub fn vertices(obj: &Bound<'_, PyAny>) -> PyResult<Vec<DVec3>> {
    let a = rows_of_three(obj, "vertices")?;
    fn convert<T: Copy + Into<f64>>(v: ArrayView2<'_, T>) -> PyResult<Vec<DVec3>> {
        let mut out = Vec::with_capacity(v.nrows());
        for (i, row) in v.rows().into_iter().enumerate() {
            let p = DVec3::new(row[0].into(), row[1].into(), row[2].into());
            if !p.is_finite() {
                return Err(PyValueError::new_err(format!(
                    "vertices[{i}] is not finite: ({}, {}, {})",
                    p.x, p.y, p.z
                )));
            }
            out.push(p);
        }
        Ok(out)
    }
    with_view::<f64, _>(&a, convert)
        .or_else(|| with_view::<f32, _>(&a, convert))
        .unwrap_or_else(|| {
            Err(PyValueError::new_err(format!(
                "vertices must be float32 or float64 (native byte order), got {}",
                dtype_name(&a)
            )))
        })
}

/// `faces`: `(m, 3)` of any integer type, every index in `0..n`.
pub fn faces(obj: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<[u32; 3]>> {
    let a = rows_of_three(obj, "faces")?;
    fn convert<T: Copy + TryInto<i128>>(v: ArrayView2<'_, T>, n: usize) -> PyResult<Vec<[u32; 3]>> {
        let mut out = Vec::with_capacity(v.nrows());
        for (i, row) in v.rows().into_iter().enumerate() {
            let mut t = [0u32; 3];
            for (k, &x) in row.iter().enumerate() {
                // Every NumPy integer fits in an i128.
                let x: i128 = x.try_into().unwrap_or(-1);
                if x < 0 || x >= n as i128 {
                    return Err(PyValueError::new_err(format!(
                        "faces[{i}, {k}] = {x} is out of range: vertices has {n} rows"
                    )));
                }
                t[k] = x as u32;
            }
            out.push(t);
        }
        Ok(out)
    }
    macro_rules! any_int {
        ($($t:ty),*) => {
            None$(.or_else(|| with_view::<$t, _>(&a, |v| convert(v, n))))*
        };
    }
    let converted: Option<PyResult<_>> = any_int!(i64, i32, u32, u64, i16, u16, i8, u8);
    converted.unwrap_or_else(|| {
        Err(PyValueError::new_err(format!(
            "faces must be of an integer type, got {}",
            dtype_name(&a)
        )))
    })
}

/// `pinned`: `None`, vertex indices (any integer type, any shape: flattened) or a boolean mask
/// of one flag per vertex. The engine checks that indices are below the vertex count and that a
/// mask has one flag per vertex.
pub fn pins(obj: &Bound<'_, PyAny>) -> PyResult<Pins> {
    if obj.is_none() {
        return Ok(Pins::None);
    }
    let a = as_array(obj)?;
    let flat = a.call_method0("ravel")?;
    if let Ok(mask) = flat.cast::<PyArray1<bool>>() {
        return Ok(Pins::Mask(mask.to_vec()?));
    }
    if a.len() == 0 {
        return Ok(Pins::Indices(Vec::new()));
    }
    let kind = a.dtype().kind();
    if kind != b'i' && kind != b'u' {
        return Err(PyValueError::new_err(format!(
            "pinned must be vertex indices (integers) or a boolean mask, got {}",
            dtype_name(&a)
        )));
    }
    let indices = flat.call_method1("astype", ("int64",))?;
    let indices = indices.cast::<PyArray1<i64>>()?.to_vec()?;
    indices
        .into_iter()
        .map(|i| {
            u32::try_from(i).map_err(|_| {
                PyValueError::new_err(format!("pinned vertex index {i} is out of range"))
            })
        })
        .collect::<PyResult<_>>()
        .map(Pins::Indices)
}

/// `(n, 3)` float64 from positions.
pub fn positions_out<'py>(py: Python<'py>, p: &[DVec3]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = p.iter().flat_map(|v| v.to_array()).collect();
    Array2::from_shape_vec((p.len(), 3), flat)
        .expect("three coordinates per vertex")
        .into_pyarray(py)
}

/// `(m, 3)` int64 from triangles: the index type NumPy and trimesh use, so that arithmetic on
/// them does not wrap.
pub fn faces_out<'py>(py: Python<'py>, t: &[[u32; 3]]) -> Bound<'py, PyArray2<i64>> {
    let flat: Vec<i64> = t.iter().flatten().map(|&i| i as i64).collect();
    Array2::from_shape_vec((t.len(), 3), flat)
        .expect("three corners per triangle")
        .into_pyarray(py)
}
