#!/usr/bin/env python3
"""Is a sharper low-pass filter than Taubin's λ|μ a better first step?

VTK's windowed-sinc filter (Taubin, Zhang and Golub 1996: a Chebyshev polynomial of the umbrella
operator with a sharper transition band than λ|μ) against `vcsmooth smooth --method taubin
--iterations 10` on the same noisy scan, measured as tools/quality_table.py measures (rms distance
to the clean surface and mean face-normal error, both relative to Taubin 10, in %). The filter is
not volume-preserving; the question is only whether its family has headroom over λ|μ on the
normal error, which a volume step could then keep.

    tools/quality_windowed_sinc.py SCAN SIGMA SEEDS ITERATIONS:PASSBAND ...
    e.g. tools/quality_windowed_sinc.py armadillo-86k 0.2 1,3,5 25:0.12 20:0.1 20:0.05

Needs numpy and vtk (tools/requirements-peers.txt); the release binary makes the noisy meshes.
"""

import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import quality_table as q  # noqa: E402
from compare_peers import read_ply, vtk_polydata  # noqa: E402

BINARY = os.path.join(HERE, "..", "target", "release", "vcsmooth")
MESHES = os.path.join(HERE, "..", "..", "shared", "meshes")


def windowed_sinc(v, f, iterations, pass_band):
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersCore import vtkWindowedSincPolyDataFilter

    poly = vtk_polydata(v, f)
    s = vtkWindowedSincPolyDataFilter()
    s.SetInputData(poly)
    s.SetNumberOfIterations(iterations)
    s.SetPassBand(pass_band)
    # Boundaries stay put, as vcsmooth's fixed boundary does.
    s.BoundarySmoothingOff()
    s.FeatureEdgeSmoothingOff()
    s.NonManifoldSmoothingOn()
    s.NormalizeCoordinatesOn()
    s.Update()
    return vtk_to_numpy(s.GetOutput().GetPoints().GetData()).astype(np.float64)


def main():
    if len(sys.argv) < 5:
        sys.exit(__doc__)
    scan, sigma, seeds = sys.argv[1], float(sys.argv[2]), [int(s) for s in sys.argv[3].split(",")]
    configs = [(int(a), float(b)) for a, b in (c.split(":") for c in sys.argv[4:])]
    path = os.path.join(MESHES, scan + ".ply")
    clean, f = read_ply(path)
    scale = q.mean_edge_length(clean, f)
    sd = q.SurfaceDistance(clean, f, cell=scale)
    with tempfile.TemporaryDirectory() as tmp:
        noisy, taubin = os.path.join(tmp, "noisy.ply"), os.path.join(tmp, "taubin.ply")
        for seed in seeds:
            q.run([BINARY, "generate", "mesh", noisy, "--from", path, "--subdivide", "0",
                   "--noise", str(sigma), "--seed", str(seed)])
            q.run([BINARY, "smooth", noisy, taubin, "--method", "taubin", "--iterations", "10"])
            nv, _ = read_ply(noisy)
            base = q.surface_metrics(clean, f, read_ply(taubin)[0], sd, scale)
            cells = [f"seed {seed}: taubin 10 rms {base['rms']:.4f} nerr {base['nerr']:.3f}"]
            for iterations, pass_band in configs:
                m = q.surface_metrics(clean, f, windowed_sinc(nv, f, iterations, pass_band), sd, scale)
                cells.append(f"ws {iterations}/{pass_band}: rms {100 * (m['rms'] / base['rms'] - 1):+.2f} % "
                             f"nerr {100 * (m['nerr'] / base['nerr'] - 1):+.2f} %")
            print(" | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
