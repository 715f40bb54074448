# Type stubs of the native module. The package's functions (vcsmooth/_api.py) wrap these with
# the same keywords and defaults (tests/test_package.py checks both against the native calls)
# and take mesh objects and polygons too; the native ones take (n, 3) vertices and (m, 3)
# triangles. The keyword arguments are keyword-only (the native functions take them as
# **options) and mirror the `vcsmooth smooth` flags; their defaults are the library's.
from os import PathLike
from typing import Any, Dict, Literal, Optional, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

_Path = Union[str, PathLike[str]]
_Method = Literal["laplacian", "taubin", "lem", "vcs", "vcs-triangle", "vcs-lowpass", "vcs-guided", "hc"]
_Report = Dict[str, Any]

__version__: str
RESULTS_VERSION: int
DEFAULT_METHOD: str
METHODS: tuple[str, ...]

class MeshError(ValueError): ...

def smooth(
    vertices: ArrayLike,
    faces: ArrayLike,
    *,
    method: _Method = ...,
    iterations: Union[int, Literal["auto"]] = 10,
    lam: float = 0.5,
    mu: Optional[float] = None,
    reject_energy_increase: bool = False,
    crease_angle: Optional[float] = None,
    max_deviation: Optional[float] = None,
    boundary: Literal["fixed", "smooth"] = "fixed",
    weld: bool = True,
    weld_tolerance: Optional[float] = None,
    pinned: Optional[ArrayLike] = None,
    threads: Optional[int] = None,
    patch_size: int = 16384,
    stats: Literal["every", "last"] = "last",
) -> NDArray[np.float64]: ...
def smooth_report(
    vertices: ArrayLike,
    faces: ArrayLike,
    *,
    method: _Method = ...,
    iterations: Union[int, Literal["auto"]] = 10,
    lam: float = 0.5,
    mu: Optional[float] = None,
    reject_energy_increase: bool = False,
    crease_angle: Optional[float] = None,
    max_deviation: Optional[float] = None,
    boundary: Literal["fixed", "smooth"] = "fixed",
    weld: bool = True,
    weld_tolerance: Optional[float] = None,
    pinned: Optional[ArrayLike] = None,
    threads: Optional[int] = None,
    patch_size: int = 16384,
    stats: Literal["every", "last"] = "every",
) -> Tuple[NDArray[np.float64], _Report]: ...
def smooth_file(
    input: _Path,
    output: _Path,
    *,
    method: _Method = ...,
    iterations: Union[int, Literal["auto"]] = 10,
    lam: float = 0.5,
    mu: Optional[float] = None,
    reject_energy_increase: bool = False,
    crease_angle: Optional[float] = None,
    max_deviation: Optional[float] = None,
    boundary: Literal["fixed", "smooth"] = "fixed",
    weld: bool = True,
    weld_tolerance: Optional[float] = None,
    pinned: Optional[ArrayLike] = None,
    pin: Optional[_Path] = None,
    pin_property: Optional[str] = None,
    threads: Optional[int] = None,
    patch_size: int = 16384,
    stats: Literal["every", "last"] = "every",
    memory_budget: Union[int, str, None] = None,
    scratch: Optional[_Path] = None,
    deviation_field: bool = False,
    deviation_colours: bool = False,
    deviation_stats: bool = False,
    tolerance: Optional[float] = None,
    report: Optional[_Path] = None,
    progress: bool = False,
) -> _Report: ...
def read_mesh(path: _Path) -> Tuple[NDArray[np.float64], NDArray[np.int64]]: ...
def write_mesh(path: _Path, vertices: ArrayLike, faces: ArrayLike) -> None: ...
def info(vertices: ArrayLike, faces: ArrayLike) -> Dict[str, Any]: ...
