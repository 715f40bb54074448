"""The package's functions, with their real signatures (what ``help()`` and
``inspect.signature`` show) and documentation, over the native module ``_vcsmooth``, which does
the work and checks every value (its messages name the keyword, what it takes and the value
given; ranges are the library's).

Every keyword is passed to the native function as given, defaults included; the defaults written
here are the library's (``tests/test_package.py`` checks each against a native call without it).
"""

# Annotations as written (``help()`` would print NumPy's ArrayLike spelled out in full).
from __future__ import annotations

from os import PathLike
from typing import Any, Dict, Optional, Tuple, TypeVar, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _vcsmooth as _native
from ._meshes import take

Path = Union[str, "PathLike[str]"]  # for type checkers
Mesh = TypeVar("Mesh")
Report = Dict[str, Any]

_MESHES = """\
``vertices`` and ``faces``: arrays, or one mesh object as ``vertices`` (no ``faces``):

- ``vertices``: ``(n, 3)`` float32 or float64, any memory layout (C, Fortran, strided views).
- ``faces``: ``(m, 3)`` of any integer type, 0-based indices into ``vertices``, outward faces
  counter-clockwise; or ``(m, k)`` polygons of ``k > 3`` corners, or a list of polygons of
  different sizes, fan-triangulated from each polygon's first corner as the file readers do.
  Both may be anything ``numpy.asarray`` takes.
- a ``trimesh.Trimesh``, an Open3D ``TriangleMesh`` or a PyVista ``PolyData`` (triangles, quads,
  any polygons; its lines and vertex cells stay as they are), recognised by their attributes
  (none of these libraries is needed by vcsmooth)."""

_OPTIONS = """\
Keyword arguments (those of ``vcsmooth smooth``, in snake_case; each is checked, and a value out
of range raises a ``ValueError`` that names it):

- ``method``: one of ``vcsmooth.METHODS`` (what each does: ``vcsmooth smooth --help``); default:
  the library's default method, ``vcsmooth.DEFAULT_METHOD``.
- ``iterations``: a count (0 changes nothing), or ``"auto"``: stop when the noise is gone, after
  at most 100.
- ``lam``: the Laplacian step λ, in (0, 1].
- ``mu``: Taubin's second step, in [-1, 0); ``None``: the method's own (-0.53 for taubin, -0.52
  for vcs-lowpass).
- ``reject_energy_increase``: skip a stencil whose result has a higher energy than before.
- ``crease_angle``: vertices on edges whose faces' normals differ by more than this many
  degrees, in (0, 180), stay where they are; ``None``: no creases.
- ``max_deviation``: no vertex ends farther than this (> 0) from its input position.
- ``boundary``: ``"fixed"``, or ``"smooth"``: smooth each boundary loop keeping each hole's size
  (with the methods that take it, which ``vcsmooth smooth --help`` lists).
- ``weld``: vertices at exactly one position (a texture seam's or unmerged corners' copies) are
  one vertex to smooth, and each copy gets the same new position; ``False`` keeps them apart,
  each seam a boundary that never moves.
- ``weld_tolerance``: also weld vertices closer than this (> 0), the copies of a seam that an
  exporter rounded apart; ``None``: exactly equal positions only.
- ``pinned``: vertices that do not move: indices, or a boolean mask of length n.
- ``threads``: worker threads, 1 to 4096; ``None``: all cores. The result is the same for any.
- ``patch_size``: vertices per patch (part of the result's definition).
- ``stats``: ``"every"`` or ``"last"``: which iterations measure volume and area; the positions
  are the same either way."""


def smooth(
    vertices: Union[ArrayLike, Mesh],
    faces: Optional[ArrayLike] = None,
    *,
    method: str = _native.DEFAULT_METHOD,
    iterations: Union[int, str] = 10,
    lam: float = 0.5,
    mu: Optional[float] = None,
    reject_energy_increase: bool = False,
    crease_angle: Optional[float] = None,
    max_deviation: Optional[float] = None,
    boundary: str = "fixed",
    weld: bool = True,
    weld_tolerance: Optional[float] = None,
    pinned: Optional[ArrayLike] = None,
    threads: Optional[int] = None,
    patch_size: int = 16384,
    stats: str = "last",
) -> Union[NDArray[np.float64], Mesh]:
    options = dict(locals())
    mesh = take(options.pop("vertices"), options.pop("faces"), "smooth")
    return mesh.back(_native.smooth(mesh.vertices, mesh.triangles, **options))


smooth.__doc__ = f"""Smooth a triangle mesh without shrinking it; the inputs are not modified.

Returns the new vertex positions, an ``(n, 3)`` float64 array, for arrays; for a mesh object, a
copy of it with the new positions and everything else kept (colours, texture coordinates, point
and cell data, faces and their order). Normals it carries are recomputed from the new positions
(Open3D's by its own ``compute_*_normals``; trimesh's by trimesh; PyVista's active point and cell
normals area-weighted); none are added. A PyVista mesh keeps its points' dtype.

{_MESHES}

{_OPTIONS}

The positions are bit-identical to ``vcsmooth smooth``'s (before the output file's rounding) for
the same options, for any ``threads``. Boundary vertices never move (``boundary="fixed"``). The
GIL is released while smoothing; Ctrl-C raises ``KeyboardInterrupt`` after the current iteration.

Raises ``ValueError`` for arrays of the wrong shape or dtype, coordinates that are NaN or
infinite, an index out of range and options out of range; ``TypeError`` for an unknown keyword or
a value of the wrong type (each named).
"""


def smooth_report(
    vertices: Union[ArrayLike, Mesh],
    faces: Optional[ArrayLike] = None,
    *,
    method: str = _native.DEFAULT_METHOD,
    iterations: Union[int, str] = 10,
    lam: float = 0.5,
    mu: Optional[float] = None,
    reject_energy_increase: bool = False,
    crease_angle: Optional[float] = None,
    max_deviation: Optional[float] = None,
    boundary: str = "fixed",
    weld: bool = True,
    weld_tolerance: Optional[float] = None,
    pinned: Optional[ArrayLike] = None,
    threads: Optional[int] = None,
    patch_size: int = 16384,
    stats: str = "every",
) -> Tuple[Union[NDArray[np.float64], Mesh], Report]:
    options = dict(locals())
    mesh = take(options.pop("vertices"), options.pop("faces"), "smooth_report")
    positions, report = _native.smooth_report(mesh.vertices, mesh.triangles, **options)
    return mesh.back(positions), report


smooth_report.__doc__ = f"""``smooth`` with the run's report: returns ``(result, report)``.

``result`` is what ``smooth`` returns (positions, or a mesh object of the kind given);
``report`` is the dictionary ``vcsmooth smooth --report FILE.json`` writes (``options``,
``engine``, ``input`` and ``output`` statistics, ``plan``, ``timings``, ``disk``, ``summary`` and
``iterations``, one row per iteration: ``volume_pct``, ``area_pct``, ``max_displacement``,
``mean_displacement``, ``stencils``, ``seconds``). Figures that were not measured are ``None``.
The mesh's "file" is ``"<memory>"``; polygons count as their fans' triangles.

Takes what ``smooth`` takes; ``stats`` defaults to ``"every"`` here, as on the command line.

{_MESHES}

{_OPTIONS}
"""


def smooth_file(
    input: Path,
    output: Path,
    *,
    method: str = _native.DEFAULT_METHOD,
    iterations: Union[int, str] = 10,
    lam: float = 0.5,
    mu: Optional[float] = None,
    reject_energy_increase: bool = False,
    crease_angle: Optional[float] = None,
    max_deviation: Optional[float] = None,
    boundary: str = "fixed",
    weld: bool = True,
    weld_tolerance: Optional[float] = None,
    pinned: Optional[ArrayLike] = None,
    pin: Optional[Path] = None,
    pin_property: Optional[str] = None,
    threads: Optional[int] = None,
    patch_size: int = 16384,
    stats: str = "every",
    memory_budget: Union[int, str, None] = None,
    scratch: Optional[Path] = None,
    deviation_field: bool = False,
    deviation_colours: bool = False,
    deviation_stats: bool = False,
    tolerance: Optional[float] = None,
    report: Optional[Path] = None,
    progress: bool = False,
) -> Report:
    options = dict(locals())
    return _native.smooth_file(options.pop("input"), options.pop("output"), **options)


smooth_file.__doc__ = f"""Smooth the mesh file ``input`` into ``output`` exactly as ``vcsmooth
smooth input output`` does, with the same output bytes; returns the report dictionary (see
``smooth_report``).

Formats from the extension: .ply, .obj, .off, .stl, .gltf, .glb. The file-to-file engine works
from memory-mapped scratch files when the mesh does not fit the memory budget, and keeps
everything else the file carries (colours, UVs, polygons, other properties).

{_OPTIONS}

``pinned`` indexes the file's vertices; ``stats`` defaults to ``"every"``. And:

- ``pin`` (a text file of vertex indices) or ``pin_property`` (a PLY vertex property whose
  non-zero values pin), instead of ``pinned``.
- ``memory_budget``: bytes, or a size such as ``"2G"``; ``None``: 3/4 of available memory.
- ``scratch``: a directory for scratch files; ``None``: the output's directory.
- ``deviation_field``: write each vertex's deviation from the input (along its normal) into a
  PLY ``output`` as the vertex property ``quality``; ``deviation_colours`` also as ``red green
  blue``. ``deviation_stats`` (implied by the others and by ``tolerance``): the report's
  ``deviation`` (RMS, mean, percentiles, histogram).
- ``tolerance``: the report's ``deviation["tolerance"]`` says how many vertices moved farther
  (``beyond``) and whether none did (``within``); nothing is raised.
- ``report``: a path to write the report to as JSON, as ``--report`` does.
- ``progress``: print one line per iteration on ``sys.stderr``.

The output is written to a temporary file and renamed into place: on any error, and on Ctrl-C
(``KeyboardInterrupt`` after the current iteration), the previous ``output`` is untouched and no
partial file is left. Raises ``OSError`` (``FileNotFoundError``, ...) for files the system
refuses, ``vcsmooth.MeshError`` for a file that is not a readable mesh or an unknown output
extension, ``ValueError`` for options out of range.
"""


def info(vertices: Union[ArrayLike, Any], faces: Optional[ArrayLike] = None) -> Dict[str, Any]:
    mesh = take(vertices, faces, "info")
    return _native.info(mesh.vertices, mesh.triangles)


info.__doc__ = f"""Describe a mesh: the dictionary ``vcsmooth info --json`` prints.

Vertices, triangles, edges, boundary and non-manifold edges and vertices, degenerate
triangles, orientation, components, unreferenced vertices, ``closed``, ``volume``, ``area``,
bounding box, mean edge length, roughness; ``path`` is ``"<memory>"``. Figures a mesh does not
define are ``None``. Polygons count as their fans' triangles.

{_MESHES}
"""


def write_mesh(path: Path, vertices: Union[ArrayLike, Any], faces: Optional[ArrayLike] = None) -> None:
    mesh = take(vertices, faces, "write_mesh")
    _native.write_mesh(path, mesh.vertices, mesh.triangles)


write_mesh.__doc__ = f"""Write a mesh to ``path``, its format from the extension (.ply, binary;
.obj; .off; .stl, always float32); polygons are written as their fans' triangles.

Coordinates are written as float32 when they all are float32 values, else as float64 (PLY
``double``, text that reads back to the same float64): nothing is rounded. Written to a temporary
file and renamed into place. Raises what ``smooth`` raises for the mesh, ``OSError`` for the file
and ``vcsmooth.MeshError`` for an unknown extension.

{_MESHES}
"""
