"""vcsmooth: smooth triangle meshes without shrinking them.

The volume-constrained stencil smoothing of Liu, Tang, Lu, Wang and Zheng (Graphical Models 64,
2002), plus Laplacian, Taubin and local energy minimisation (``vcsmooth.METHODS``), on NumPy
arrays, on the mesh objects of trimesh, Open3D and PyVista, or on mesh files::

    import trimesh, vcsmooth
    mesh = trimesh.load("scan.ply", process=False)  # keep the file's vertices
    smoothed = vcsmooth.smooth(mesh, iterations=20)  # a Trimesh, colours and UVs kept
    positions = vcsmooth.smooth(mesh.vertices, mesh.faces, iterations=20)  # an (n, 3) array

- ``smooth(vertices, faces, **options)`` or ``smooth(mesh, **options)``: the smoothed ``(n, 3)``
  float64 positions, or a copy of the mesh object with them.
- ``smooth_report(...)``: the same and the run's report.
- ``smooth_file(input, output, **options)``: file to file, as ``vcsmooth smooth`` (same bytes).
- ``read_mesh(path)``, ``write_mesh(path, vertices, faces)``, ``info(vertices, faces)``.
- ``RESULTS_VERSION``: bumped by every change to the bytes a run writes (see ``CHANGELOG.md``).
- ``MeshError``: a file that is not a readable mesh (a ``ValueError``).

The options are the command line's flags in snake_case (``lam`` for ``--lambda``); see
``help(vcsmooth.smooth)``. The native code runs without the GIL, and Ctrl-C stops it.
"""

from ._api import info, smooth, smooth_file, smooth_report, write_mesh
from ._vcsmooth import (
    DEFAULT_METHOD,
    METHODS,
    RESULTS_VERSION,
    MeshError,
    __version__,
    read_mesh,
)

__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "RESULTS_VERSION",
    "MeshError",
    "__version__",
    "info",
    "read_mesh",
    "smooth",
    "smooth_file",
    "smooth_report",
    "write_mesh",
]
