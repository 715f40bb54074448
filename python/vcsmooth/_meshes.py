"""Meshes as their users hold them: ``(vertices, faces)`` arrays, or a trimesh ``Trimesh``, an
Open3D ``TriangleMesh`` or a PyVista ``PolyData``, recognised by their attributes (none of those
libraries is imported here, nor needed by the package), and the smoothed positions given back in
the same kind of object.

- :func:`take` reads what a caller gave into the arrays the native module takes (polygons
  fan-triangulated), with a way back (:attr:`Taken.back`) to the caller's kind of object.
- :func:`fan_rows` and :func:`fan_cells` fan-triangulate polygons as the library's file readers
  do: ``(v0, v1, ..., vk)`` becomes ``(v0, v1, v2), (v0, v2, v3), ...``, in the polygons' order.

The objects given back are copies with the new vertex positions and everything else of the input
kept (colours, texture coordinates, point and cell data, face order and polygons, since only
positions change). Normals the input carries are recomputed from the new positions rather than
handed back stale: trimesh does so by itself (its caches follow the vertices), Open3D's by its own
``compute_*_normals``, PyVista's active point and cell normals here (area-weighted). Normals the
input does not carry are not added.
"""

import copy
from typing import Any, Callable, NamedTuple, Optional

import numpy as np


class Taken(NamedTuple):
    """What a call smooths: ``vertices`` ``(n, 3)`` and ``triangles`` ``(m, 3)`` as the native
    module takes them (any dtype: it checks them), and ``back``, which makes the caller's kind of
    result from the new ``(n, 3)`` float64 positions."""

    vertices: Any
    triangles: Any
    back: Callable[[np.ndarray], Any]


def _module(obj: Any) -> str:
    """The top-level package of ``obj``'s type (``"trimesh"``, ``"open3d"``, ``"pyvista"``)."""
    return type(obj).__module__.split(".")[0]


def kind(obj: Any) -> Optional[str]:
    """Which kind of mesh object ``obj`` is, by its attributes: ``"trimesh"`` (``vertices`` and
    ``faces``), ``"open3d"`` (``vertices`` and ``triangles``) or ``"pyvista"`` (``points`` and
    ``faces``); ``None`` for anything else (arrays, lists). Checked in this order: a ``Trimesh``
    also has a ``triangles`` property (its corners' coordinates)."""
    if isinstance(obj, (np.ndarray, list, tuple)):
        return None
    if hasattr(obj, "vertices") and hasattr(obj, "faces"):
        return "trimesh"
    if hasattr(obj, "vertices") and hasattr(obj, "triangles"):
        return "open3d"
    if hasattr(obj, "points") and hasattr(obj, "faces"):
        return "pyvista"
    return None


def take(vertices: Any, faces: Any, function: str) -> Taken:
    """The mesh a caller of ``function`` gave: ``(vertices, faces)`` arrays, or one mesh object
    as ``vertices`` with ``faces`` left ``None``."""
    what = kind(vertices)
    if what is None:
        if faces is None:
            raise TypeError(
                f"{function}() takes (vertices, faces) arrays or a mesh object (a trimesh "
                f"Trimesh, an Open3D TriangleMesh, a PyVista PolyData), got "
                f"{type(vertices).__name__} and no faces"
            )
        return Taken(vertices, triangles_of(faces, _rows(vertices)), lambda positions: positions)
    if faces is not None:
        raise TypeError(
            f"{function}() takes faces only with a vertices array: a "
            f"{type(vertices).__name__} carries its own"
        )
    return {"trimesh": _trimesh, "open3d": _open3d, "pyvista": _pyvista}[what](vertices)


def _rows(vertices: Any) -> Optional[int]:
    """The vertex count of a vertices array-like, if it has one (for the polygons' checks)."""
    shape = np.shape(vertices)
    return shape[0] if len(shape) >= 1 else None


def triangles_of(faces: Any, n: Optional[int]) -> Any:
    """``faces`` as triangles: ``(m, 3)`` as given (the native module checks it); ``(m, k)``
    with ``k > 3`` (quads, ...) or a list of polygons of different sizes fan-triangulated, their
    indices checked here against ``n`` vertices (the native module's messages would name rows
    of the triangles)."""
    if isinstance(faces, np.ndarray) or not isinstance(faces, (list, tuple)):
        array = np.asarray(faces)
    else:
        try:
            array = np.asarray(faces)
        except ValueError:
            # Rows of different lengths: polygons of different sizes.
            return fan_polygons(faces, n)
    if array.ndim == 2 and array.shape[1] > 3:
        _check_indices(array, n, "faces")
        return fan_rows(array)
    if array.ndim == 2 and array.shape[1] < 3:
        raise ValueError(
            f"faces must have shape (m, 3), or (m, k) for polygons of k > 3 corners, got "
            f"{array.shape}"
        )
    return faces


def _check_indices(array: np.ndarray, n: Optional[int], name: str) -> None:
    """Integer indices in ``0..n``, else a ``ValueError`` naming the first bad entry."""
    if array.dtype.kind not in "iu":
        raise ValueError(f"{name} must be of an integer type, got {array.dtype}")
    if n is None or array.size == 0:
        return
    bad = np.argwhere((array < 0) | (array >= n))
    if len(bad):
        where = ", ".join(str(i) for i in bad[0])
        raise ValueError(
            f"{name}[{where}] = {array[tuple(bad[0])]} is out of range: vertices has {n} rows"
        )


def fan_rows(polygons: np.ndarray) -> np.ndarray:
    """``(m, k)`` polygons as ``(m * (k - 2), 3)`` triangles: each polygon's fan from its first
    corner, polygon after polygon."""
    k = polygons.shape[1]
    first = np.repeat(polygons[:, :1], k - 2, axis=1)
    fans = np.stack([first, polygons[:, 1 : k - 1], polygons[:, 2:k]], axis=2)
    return fans.reshape(-1, 3)


def fan_cells(cells: np.ndarray, n: Optional[int], name: str = "faces"):
    """A VTK cell array (``[k, i0, ..., i(k-1), k, ...]``, PyVista's ``PolyData.faces``) as
    triangles, and for each triangle the index of its polygon."""
    cells = np.asarray(cells)
    _check_indices(cells, None, name)
    if cells.size == 0:
        return np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    k = int(cells[0])
    # The common case, every cell of one size: a reshape.
    if k >= 3 and cells.size % (k + 1) == 0 and np.all(cells[:: k + 1] == k):
        polygons = cells.reshape(-1, k + 1)[:, 1:]
        _check_indices(polygons, n, name)
        return fan_rows(polygons), np.repeat(np.arange(len(polygons)), k - 2)
    # Mixed sizes: find where each cell starts (a walk: each size says where the next is).
    starts, sizes, at = [], [], 0
    while at < cells.size:
        size = int(cells[at])
        if size < 3:
            raise ValueError(f"{name}: cell {len(starts)} has {size} corners; a face needs 3 or more")
        if at + size >= cells.size:
            raise ValueError(f"{name}: cell {len(starts)} runs past the end of the cell array")
        starts.append(at)
        sizes.append(size)
        at += size + 1
    starts, sizes = np.asarray(starts), np.asarray(sizes)
    _check_indices(np.delete(cells, starts), n, name)
    return _fan(cells, starts + 1, sizes)


def fan_polygons(polygons, n: Optional[int]) -> np.ndarray:
    """A list of polygons (index sequences) of different sizes as triangles."""
    sizes = np.fromiter((len(p) for p in polygons), dtype=np.int64, count=len(polygons))
    if len(sizes) and sizes.min() < 3:
        i = int(np.argmax(sizes < 3))
        raise ValueError(f"faces[{i}] has {sizes[i]} corners; a face needs 3 or more")
    flat = np.asarray([i for p in polygons for i in p]) if len(sizes) else np.zeros(0, np.int64)
    _check_indices(flat, n, "faces")
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]) if len(sizes) else sizes
    return _fan(flat, starts, sizes)[0]


def _fan(flat: np.ndarray, starts: np.ndarray, sizes: np.ndarray):
    """The fans of polygons whose corners are ``flat[starts[i] : starts[i] + sizes[i]]``, in
    order, and each triangle's polygon."""
    per = sizes - 2
    polygon = np.repeat(np.arange(len(sizes)), per)
    # Each triangle's place in its polygon's fan: 0, 1, ..., per - 1.
    j = np.arange(len(polygon)) - np.repeat(np.cumsum(per) - per, per)
    first = starts[polygon]
    triangles = np.stack([flat[first], flat[first + 1 + j], flat[first + 2 + j]], axis=1)
    return triangles, polygon


def _copy(mesh: Any) -> Any:
    """A deep copy: the object's own ``copy()`` when it has one (trimesh, PyVista: deep by
    default), else ``copy.deepcopy`` (Open3D's is its copy constructor)."""
    own = getattr(mesh, "copy", None)
    return own() if callable(own) else copy.deepcopy(mesh)


def _trimesh(mesh: Any) -> Taken:
    """A ``trimesh.Trimesh`` (or anything with ``vertices`` and ``faces`` arrays)."""
    vertices = np.asarray(mesh.vertices)

    def back(positions):
        out = _copy(mesh)
        # trimesh's caches (normals, volume, ...) follow the vertices' hash; its visual (colours,
        # UVs) and faces are the copy's, untouched. Setting vertices never merges or reorders.
        out.vertices = positions
        return out

    return Taken(vertices, triangles_of(mesh.faces, len(vertices)), back)


def _open3d(mesh: Any) -> Taken:
    """An Open3D ``TriangleMesh``: ``vertices`` a ``Vector3dVector``, ``triangles`` a
    ``Vector3iVector`` (``numpy.asarray`` reads both without a copy)."""
    vertices = np.asarray(mesh.vertices)
    triangles = np.asarray(mesh.triangles)

    def has(obj, what):
        test = getattr(obj, f"has_{what}", None)
        return bool(test()) if callable(test) else False

    def back(positions):
        out = _copy(mesh)
        # The vertices' own type (Vector3dVector) made from the array.
        out.vertices = type(mesh.vertices)(positions)
        # Stale normals recomputed as Open3D computes them; triangle normals first, since
        # compute_vertex_normals sums the triangle normals it finds.
        had_triangle_normals = has(mesh, "triangle_normals")
        if had_triangle_normals:
            out.compute_triangle_normals()
        if has(mesh, "vertex_normals"):
            out.compute_vertex_normals()
            if not had_triangle_normals and has(out, "triangle_normals"):
                # compute_vertex_normals leaves its triangle normals behind: not the input's.
                out.triangle_normals = type(out.triangle_normals)()
        return out

    return Taken(vertices, triangles, back)


def _pyvista(mesh: Any) -> Taken:
    """A PyVista ``PolyData``: ``points`` ``(n, 3)``, ``faces`` a VTK cell array of polygons
    (triangles, quads, any). Its lines and vertex cells are not faces and stay as they are; its
    triangle strips are refused (``mesh.triangulate()`` makes them triangles)."""
    points = np.asarray(mesh.points)
    if getattr(mesh, "n_strips", 0):
        raise ValueError(
            "a PolyData with triangle strips: smooth mesh.triangulate() (strips are not read)"
        )
    triangles, polygon = fan_cells(mesh.faces, len(points), "PolyData.faces")

    def back(positions):
        out = _copy(mesh)
        # The input's precision: a float32 PolyData stays float32.
        out.points = positions.astype(points.dtype, copy=False)
        _pyvista_normals(out, positions, triangles, polygon)
        return out

    return Taken(points, triangles, back)


def _pyvista_normals(out: Any, positions, triangles, polygon) -> None:
    """Recompute ``out``'s active point and cell normals, if it has them, from the new positions:
    area-weighted sums of the fans' triangle normals, of unit length (zero where undefined)."""
    point_name = getattr(getattr(out, "point_data", None), "active_normals_name", None)
    cell_name = getattr(getattr(out, "cell_data", None), "active_normals_name", None)
    if point_name is None and cell_name is None:
        return
    corners = positions[triangles]
    # Twice each triangle's area along its normal.
    area = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])

    def unit(v):
        length = np.linalg.norm(v, axis=1, keepdims=True)
        return np.divide(v, length, out=np.zeros_like(v), where=length > 0)

    if point_name is not None:
        sums = np.zeros_like(positions)
        for k in range(3):
            np.add.at(sums, triangles[:, k], area)
        old = out.point_data[point_name]
        out.point_data[point_name] = unit(sums).astype(old.dtype, copy=False)
    if cell_name is not None:
        # Cell data runs over vertex cells, lines, polygons and strips, in that order.
        skip = getattr(out, "n_verts", 0) + getattr(out, "n_lines", 0)
        old = np.array(out.cell_data[cell_name])
        sums = np.zeros((len(old) - skip, 3))
        np.add.at(sums, polygon, area)
        old[skip:] = unit(sums)
        out.cell_data[cell_name] = old
