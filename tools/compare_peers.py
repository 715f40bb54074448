#!/usr/bin/env python3
"""Compare vcsmooth with the established mesh smoothers installed from PyPI.

The same noisy mesh and the same iteration count go through

  * pymeshlab  - Laplacian, Taubin, HC Laplacian, two-step smoothing
  * Open3D     - Laplacian, Taubin
  * trimesh    - Laplacian (plain and with trimesh's default volume constraint), Taubin, Humphrey
  * VTK        - vtkSmoothPolyDataFilter (Laplacian), vtkWindowedSincPolyDataFilter
  * vcsmooth   - laplacian, taubin, vcs (and optionally lem, vcs-triangle, vcs-lowpass, hc)

and the script prints, side by side, the median time of the smoothing alone (no file or format
conversion is timed), the volume change against the noisy input and the RMS distance to the clean
mesh.

Each peer library runs in its own child process (this script re-invoked with --worker), so a
library that is missing, fails to import or crashes is reported as such and the rest still run.
The noisy mesh is handed to it as numpy arrays and converted to the library's own mesh type
before the clock starts; only the smoothing call is timed (time.perf_counter). For vcsmooth the
time is taken from its --report JSON (the sum of the per-iteration seconds), not from the process
wall time, which includes reading and writing the PLY files.

Only numpy is needed by the driver; scipy is used for the nearest-vertex fallback distance.
See tools/README-peers.md.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import traceback

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
REQUIREMENTS = os.path.join(HERE, "requirements-peers.txt")

PEERS = ["pymeshlab", "open3d", "trimesh", "vtk"]
VCS_METHODS_ALL = ["laplacian", "taubin", "lem", "vcs", "vcs-triangle", "vcs-lowpass", "hc"]
VCS_METHODS_DEFAULT = ["laplacian", "taubin", "vcs"]

# Methods that are the same kind of filter, for the "x same-kind peer" column: a Laplacian is
# compared with the Laplacians, Taubin's lambda|mu filter with Taubin and with VTK's windowed
# sinc (Taubin, Zhang & Golub's generalisation of lambda|mu), the HC Laplacian with MeshLab's and
# trimesh's (filter_humphrey, the same filter under its author's name); the other methods have no
# same-kind peer and are compared with the fastest peer of any method only.
FAMILY = {
    "laplacian": "laplacian",
    "taubin": "taubin",
    "windowed-sinc": "taubin",
    "hc": "hc",
    "humphrey": "hc",
}


# --------------------------------------------------------------------------------------------
# PLY reading and writing (binary and ASCII), enough for vcsmooth's output and common scans
# --------------------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def read_ply(path):
    """Return (vertices float64 (n,3), triangles int64 (m,3)); polygons are fan-triangulated."""
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise ValueError(f"{path}: not a PLY file")
        fmt = None
        elements = []  # [name, count, [(prop name, dtype) | (prop name, ("list", count dt, item dt))]]
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: header has no end_header")
            words = line.decode("ascii", "replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                elements.append([words[1], int(words[2]), []])
            elif words[0] == "property":
                if words[1] == "list":
                    elements[-1][2].append((words[4], ("list", _PLY_TYPES[words[2]], _PLY_TYPES[words[3]])))
                else:
                    elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
            elif words[0] == "end_header":
                break
        if fmt == "ascii":
            data = f.read().split()
            return _read_ply_ascii(path, elements, data)
        if fmt not in ("binary_little_endian", "binary_big_endian"):
            raise ValueError(f"{path}: unsupported PLY format {fmt}")
        end = "<" if fmt == "binary_little_endian" else ">"
        buf = f.read()
    pos = 0
    verts = tris = None
    for name, count, props in elements:
        lists = [p for p in props if isinstance(p[1], tuple)]
        if not lists:
            dt = np.dtype([(p, end + t) for p, t in props])
            arr = np.frombuffer(buf, dtype=dt, count=count, offset=pos)
            pos += dt.itemsize * count
            if name == "vertex":
                verts = np.stack([arr[c].astype(np.float64) for c in "xyz"], axis=1)
            continue
        if name != "face" or len(props) != 1:
            raise ValueError(f"{path}: element {name} with list properties is not supported")
        _, (_, cdt, idt) = props[0]
        # Fast path: every face is a triangle.
        dt = np.dtype([("n", end + cdt), ("v", end + idt, (3,))])
        if pos + dt.itemsize * count <= len(buf):
            arr = np.frombuffer(buf, dtype=dt, count=count, offset=pos)
            if (arr["n"] == 3).all():
                tris = arr["v"].astype(np.int64)
                pos += dt.itemsize * count
                continue
        # Slow path: polygons of any size.
        cdtype, idtype = np.dtype(end + cdt), np.dtype(end + idt)
        out = []
        for _ in range(count):
            n = int(np.frombuffer(buf, cdtype, 1, pos)[0])
            pos += cdtype.itemsize
            idx = np.frombuffer(buf, idtype, n, pos)
            pos += idtype.itemsize * n
            out.extend((idx[0], idx[i], idx[i + 1]) for i in range(1, n - 1))
        tris = np.asarray(out, dtype=np.int64).reshape(-1, 3)
    if verts is None or tris is None:
        raise ValueError(f"{path}: needs vertex and face elements")
    return verts, tris


def _read_ply_ascii(path, elements, data):
    pos = 0
    verts = tris = None
    for name, count, props in elements:
        if all(not isinstance(p[1], tuple) for p in props):
            k = len(props)
            arr = np.asarray(data[pos:pos + k * count], dtype=np.float64).reshape(count, k)
            pos += k * count
            if name == "vertex":
                names = [p[0] for p in props]
                verts = arr[:, [names.index(c) for c in "xyz"]]
            continue
        if name != "face" or len(props) != 1:
            raise ValueError(f"{path}: element {name} with list properties is not supported")
        out = []
        for _ in range(count):
            n = int(data[pos])
            idx = [int(x) for x in data[pos + 1:pos + 1 + n]]
            pos += 1 + n
            out.extend((idx[0], idx[i], idx[i + 1]) for i in range(1, n - 1))
        tris = np.asarray(out, dtype=np.int64).reshape(-1, 3)
    if verts is None or tris is None:
        raise ValueError(f"{path}: needs vertex and face elements")
    return verts, tris


def write_ply(path, verts, tris):
    """Binary little-endian PLY, float32 positions (as vcsmooth generate writes them)."""
    verts = np.ascontiguousarray(verts, dtype="<f4")
    face = np.empty(len(tris), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    face["n"] = 3
    face["v"] = tris
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment written by tools/compare_peers.py\n"
        f"element vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(tris)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(verts.tobytes())
        f.write(face.tobytes())


# --------------------------------------------------------------------------------------------
# Metrics
# --------------------------------------------------------------------------------------------

def signed_volume(v, t, origin):
    """Signed volume by the divergence theorem, about a fixed reference point."""
    a, b, c = v[t[:, 0]] - origin, v[t[:, 1]] - origin, v[t[:, 2]] - origin
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def mean_edge_length(v, t):
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e.sort(axis=1)
    e = np.unique(e, axis=0)
    return float(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1).mean())


def vertex_normals(v, t):
    fn = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])  # area-weighted
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, t[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(length > 0, length, 1.0)


def rms_distance(out_v, order_kept, clean_v):
    """(rms, how): per-vertex when the vertex order is kept, otherwise the RMS distance from each
    output vertex to the nearest clean vertex (scipy cKDTree)."""
    if order_kept:
        return float(np.sqrt(np.mean(np.sum((out_v - clean_v) ** 2, axis=1)))), "per-vertex"
    try:
        from scipy.spatial import cKDTree
    except ImportError:
        return None, "n/a (vertex order changed, no scipy)"
    d, _ = cKDTree(clean_v).query(out_v, workers=-1)
    return float(np.sqrt(np.mean(d ** 2))), "nearest-vertex"


# --------------------------------------------------------------------------------------------
# Peer workers: one child process per library
# --------------------------------------------------------------------------------------------

def _timed(run, reset, repeats):
    """Call reset() (untimed: builds a fresh input in the library's format), then time run()."""
    times, out = [], None
    for _ in range(repeats):
        state = reset()
        t0 = time.perf_counter()
        out = run(state)
        times.append(time.perf_counter() - t0)
    return times, out


def worker_pymeshlab(V, F, a):
    import pymeshlab

    def version():
        try:
            import importlib.metadata as md
            return md.version("pymeshlab")
        except Exception:
            return "?"

    def apply(ms, names, **kw):
        # Filter names changed in pymeshlab 2022.2; try the current one first.
        for name in names:
            if hasattr(ms, name):
                return getattr(ms, name)(**kw)
        raise AttributeError(f"pymeshlab has none of {names}")

    def reset():
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32)))
        return ms

    def fetch(ms):
        m = ms.current_mesh()
        return m.vertex_matrix(), m.face_matrix()

    n = a.iterations
    # Parameter mapping (checked with pymeshlab.print_filter_parameter_list):
    # - apply_coord_laplacian_smoothing(stepsmoothnum=N, boundary=True, cotangentweight=False):
    #   each step moves a vertex to the average of its neighbours (no lambda: a full step,
    #   lambda = 1). Uniform (umbrella) weights like vcsmooth's laplacian; MeshLab's default
    #   cotangentweight=True costs more, so the cheaper uniform variant is the faster peer.
    # - apply_coord_taubin_smoothing(lambda_=0.5, mu=-0.53, stepsmoothnum=N): one step = a
    #   lambda pass then a mu pass, as in vcsmooth.
    # - apply_coord_hc_laplacian_smoothing(): no parameters, one HC step per call (Vollmer et
    #   al. 1999), so it is called N times inside the timed region.
    # - apply_coord_two_steps_smoothing(stepsmoothnum=N, normalthr=60, stepnormalnum=20,
    #   stepfitnum=20): MeshLab's defaults for the inner normal-smoothing and vertex-fitting
    #   steps; each of the N outer steps does 20 + 20 inner passes, so it is far heavier.
    methods = {
        "laplacian": (["apply_coord_laplacian_smoothing", "laplacian_smooth"],
                      dict(stepsmoothnum=n, boundary=True, cotangentweight=False), 1),
        "taubin": (["apply_coord_taubin_smoothing", "taubin_smooth"],
                   dict(lambda_=a.lam, mu=a.mu, stepsmoothnum=n), 1),
        "hc": (["apply_coord_hc_laplacian_smoothing", "hc_laplacian_smooth"], {}, n),
        "two-step": (["apply_coord_two_steps_smoothing", "two_step_smooth"],
                     dict(stepsmoothnum=n, normalthr=60.0, stepnormalnum=20, stepfitnum=20), 1),
    }
    for method, (names, kw, calls) in methods.items():
        def run(ms, names=names, kw=kw, calls=calls):
            for _ in range(calls):
                apply(ms, names, **kw)
            return ms
        desc = f"{names[0]}({', '.join(f'{k}={v}' for k, v in kw.items())})"
        if calls > 1:
            desc += f" x{calls} calls"
        yield method, desc, run, reset, fetch
    return version()


def worker_open3d(V, F, a):
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V),
                                     o3d.utility.Vector3iVector(F.astype(np.int32)))

    def fetch(m):
        return np.asarray(m.vertices), np.asarray(m.triangles)

    n = a.iterations
    # Parameter mapping: filter_smooth_laplacian(number_of_iterations=N, lambda_filter=0.5)
    # (inverse-distance weights); filter_smooth_taubin(number_of_iterations=N,
    # lambda_filter=0.5, mu=-0.53), one iteration = a lambda pass then a mu pass. Both return
    # a new mesh and leave the input untouched, so the same input serves every repeat; the
    # adjacency list they need is built inside the call (and timed), as the input has none.
    yield ("laplacian", f"TriangleMesh.filter_smooth_laplacian(number_of_iterations={n}, lambda_filter={a.lam})",
           lambda m: m.filter_smooth_laplacian(number_of_iterations=n, lambda_filter=a.lam),
           lambda: mesh, fetch)
    yield ("taubin", f"TriangleMesh.filter_smooth_taubin(number_of_iterations={n}, lambda_filter={a.lam}, mu={a.mu})",
           lambda m: m.filter_smooth_taubin(number_of_iterations=n, lambda_filter=a.lam, mu=a.mu),
           lambda: mesh, fetch)
    return o3d.__version__


def worker_trimesh(V, F, a):
    import trimesh
    from trimesh import smoothing

    def reset():
        # process=False: no vertex merging or reordering, the input order is kept.
        return trimesh.Trimesh(vertices=V.copy(), faces=F.copy(), process=False)

    def fetch(m):
        return np.asarray(m.vertices), np.asarray(m.faces)

    n = a.iterations
    # Parameter mapping (trimesh.smoothing, all in place; the sparse umbrella Laplacian
    # operator is built inside each call and timed):
    # - filter_laplacian(lamb=0.5, iterations=N, volume_constraint=False): plain explicit
    #   Laplacian. trimesh's default volume_constraint=True (rescale about the centre of mass
    #   to the initial volume after each pass) is run too, as "laplacian+volume".
    # - filter_taubin(lamb=0.5, nu=0.53, iterations=2N): trimesh counts single passes,
    #   alternating lambda and -nu, so 2N passes = N lambda|mu iterations; nu = -mu.
    # - filter_humphrey(alpha=0.1, beta=0.5, iterations=N): trimesh's defaults.
    yield ("laplacian", f"smoothing.filter_laplacian(lamb={a.lam}, iterations={n}, volume_constraint=False)",
           lambda m: smoothing.filter_laplacian(m, lamb=a.lam, iterations=n, volume_constraint=False),
           reset, fetch)
    yield ("laplacian+volume", f"smoothing.filter_laplacian(lamb={a.lam}, iterations={n}, volume_constraint=True)",
           lambda m: smoothing.filter_laplacian(m, lamb=a.lam, iterations=n, volume_constraint=True),
           reset, fetch)
    yield ("taubin", f"smoothing.filter_taubin(lamb={a.lam}, nu={-a.mu}, iterations={2 * n})",
           lambda m: smoothing.filter_taubin(m, lamb=a.lam, nu=-a.mu, iterations=2 * n),
           reset, fetch)
    yield ("humphrey", f"smoothing.filter_humphrey(alpha=0.1, beta=0.5, iterations={n})",
           lambda m: smoothing.filter_humphrey(m, alpha=0.1, beta=0.5, iterations=n),
           reset, fetch)
    return trimesh.__version__


def vtk_polydata(V, F):
    """A vtkPolyData of the vertices V (n, 3) and the triangles F (m, 3), copied."""
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData

    pts = vtkPoints()
    pts.SetData(numpy_to_vtk(np.ascontiguousarray(V, dtype=np.float64), deep=True))
    cells = vtkCellArray()
    offsets = np.arange(0, 3 * len(F) + 1, 3, dtype=np.int64)
    cells.SetData(numpy_to_vtkIdTypeArray(offsets, deep=True),
                  numpy_to_vtkIdTypeArray(np.ascontiguousarray(F, dtype=np.int64).ravel(), deep=True))
    poly = vtkPolyData()
    poly.SetPoints(pts)
    poly.SetPolys(cells)
    return poly


def worker_vtk(V, F, a):
    from vtkmodules.vtkCommonCore import vtkSMPTools, vtkVersion
    from vtkmodules.vtkFiltersCore import vtkSmoothPolyDataFilter, vtkWindowedSincPolyDataFilter
    from vtkmodules.util.numpy_support import vtk_to_numpy

    # The pip wheels default to the Sequential SMP backend; give VTK the same thread budget as
    # the others (vtkWindowedSincPolyDataFilter is vtkSMPTools-threaded since VTK 9.2).
    vtkSMPTools.SetBackend("STDThread")
    vtkSMPTools.Initialize(a.threads)
    backend = f"{vtkSMPTools.GetBackend()} x{vtkSMPTools.GetEstimatedNumberOfThreads()}"

    poly = vtk_polydata(V, F)

    def fetch(f):
        out = f.GetOutput()
        v = vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
        polys = out.GetPolys()
        off = vtk_to_numpy(polys.GetOffsetsArray())
        con = vtk_to_numpy(polys.GetConnectivityArray())
        t = con.reshape(-1, 3) if (np.diff(off) == 3).all() else None
        return v, t

    n = a.iterations
    # Parameter mapping:
    # - vtkSmoothPolyDataFilter: NumberOfIterations=N, RelaxationFactor=lambda=0.5 (VTK's
    #   default is 0.01), Convergence=0 (never stop early), FeatureEdgeSmoothing off,
    #   BoundarySmoothing on: a plain umbrella Laplacian.
    # - vtkWindowedSincPolyDataFilter has no lambda/mu: NumberOfIterations=N is the degree of
    #   the Chebyshev polynomial (N Laplacian passes) and PassBand is Taubin's k_PB, here
    #   1/lambda + 1/mu = 0.113 for lambda=0.5, mu=-0.53 (VTK's default is 0.1);
    #   NormalizeCoordinates on (VTK's recommendation), FeatureEdgeSmoothing off,
    #   BoundarySmoothing on.
    def reset_smooth():
        f = vtkSmoothPolyDataFilter()
        f.SetInputData(poly)
        f.SetNumberOfIterations(n)
        f.SetRelaxationFactor(a.lam)
        f.SetConvergence(0.0)
        f.FeatureEdgeSmoothingOff()
        f.BoundarySmoothingOn()
        return f

    def reset_sinc():
        f = vtkWindowedSincPolyDataFilter()
        f.SetInputData(poly)
        f.SetNumberOfIterations(n)
        f.SetPassBand(a.passband)
        f.NormalizeCoordinatesOn()
        f.FeatureEdgeSmoothingOff()
        f.BoundarySmoothingOn()
        return f

    def run(f):
        f.Update()
        return f

    yield ("laplacian", f"vtkSmoothPolyDataFilter(NumberOfIterations={n}, RelaxationFactor={a.lam}, "
                        "Convergence=0, FeatureEdgeSmoothing=off, BoundarySmoothing=on)",
           run, reset_smooth, fetch)
    yield ("windowed-sinc", f"vtkWindowedSincPolyDataFilter(NumberOfIterations={n}, PassBand={a.passband:.4g}, "
                            "NormalizeCoordinates=on, FeatureEdgeSmoothing=off, BoundarySmoothing=on)",
           run, reset_sinc, fetch)
    return f"{vtkVersion.GetVTKVersion()} (SMP {backend})"


WORKERS = {"pymeshlab": worker_pymeshlab, "open3d": worker_open3d,
           "trimesh": worker_trimesh, "vtk": worker_vtk}


def run_worker(a):
    """Child process: smooth workdir/noisy.npz with one library, write workdir/<lib>.json."""
    lib = a.worker
    data = np.load(os.path.join(a.workdir, "noisy.npz"))
    V = np.ascontiguousarray(data["v"], dtype=np.float64)
    F = np.ascontiguousarray(data["t"], dtype=np.int64)
    report = {"library": lib, "status": "ok", "version": None, "methods": []}
    out_json = os.path.join(a.workdir, f"{lib}.json")

    def save():
        with open(out_json, "w") as f:
            json.dump(report, f, indent=1)

    save()
    try:
        gen = WORKERS[lib](V, F, a)
        while True:
            try:
                method, desc, run, reset, fetch = next(gen)
            except StopIteration as stop:
                report["version"] = stop.value
                break
            if method in a.skip or f"{lib}:{method}" in a.skip:
                continue
            entry = {"method": method, "call": desc}
            print(f"  {lib} {method}: {desc}", file=sys.stderr, flush=True)
            try:
                times, out = _timed(run, reset, a.repeats)
                v, t = fetch(out)
                path = os.path.join(a.workdir, f"{lib}-{method}.npz")
                np.savez(path, v=np.asarray(v, dtype=np.float64),
                         t=np.asarray(t, dtype=np.int64) if t is not None else np.zeros((0, 3), np.int64))
                entry.update(times=times, output=path, faces_returned=t is not None)
            except Exception as e:  # one method failing does not stop the others
                entry.update(error=f"{type(e).__name__}: {e}")
                traceback.print_exc()
            report["methods"].append(entry)
            save()
    except ImportError as e:
        report["status"] = f"not installed ({e})"
    except Exception as e:
        report["status"] = f"failed ({type(e).__name__}: {e})"
        traceback.print_exc()
    save()


# --------------------------------------------------------------------------------------------
# vcsmooth
# --------------------------------------------------------------------------------------------

def find_vcsmooth(explicit):
    if explicit and not (os.path.isfile(explicit) and os.access(explicit, os.X_OK)):
        sys.exit(f"compare_peers: --vcsmooth {explicit}: not an executable file")
    for cand in (explicit, os.environ.get("VCSMOOTH"),
                 os.path.join(REPO, "target", "release", "vcsmooth"), shutil.which("vcsmooth")):
        if cand and os.path.isfile(cand) and os.access(cand, os.X_OK):
            return os.path.abspath(cand)
    return None


def run_vcsmooth(binary, method, noisy, workdir, a):
    out = os.path.join(workdir, f"vcsmooth-{method}.ply")
    rep = os.path.join(workdir, f"vcsmooth-{method}.json")
    cmd = [binary, "smooth", noisy, out, "--method", method, "--iterations", str(a.iterations),
           "--threads", str(a.threads), "--stats", "last", "--report", rep]
    if method in ("laplacian", "taubin"):
        cmd += ["--lambda", repr(a.lam)]
    if method == "taubin":
        cmd += ["--mu", repr(a.mu)]
    times, phase, topo = [], [], []
    for _ in range(a.repeats):
        p = subprocess.run(cmd, capture_output=True, text=True)
        if p.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} exited {p.returncode}: {p.stderr.strip()[-500:]}")
        with open(rep) as f:
            r = json.load(f)
        iters = r.get("iterations") or []
        s = r.get("summary", {}).get("seconds")
        if s is None:
            s = sum(it["seconds"] for it in iters)
        times.append(float(s))
        tm = r.get("timings", {})
        phase.append(float(tm.get("smoothing", s)))
        topo.append(float(tm.get("topology", 0.0)))
    return {"times": times, "phase_times": phase, "topology_times": topo, "output": out,
            "call": " ".join([os.path.basename(binary)] + cmd[1:2] + ["IN", "OUT"] + cmd[4:-2])}


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------

def make_meshes(a, k, workdir, binary):
    """Write workdir/clean.ply and workdir/noisy.ply (same connectivity); return their arrays."""
    clean_ply, noisy_ply = os.path.join(workdir, "clean.ply"), os.path.join(workdir, "noisy.ply")
    if a.mesh:
        v, t = read_ply(a.mesh)
        write_ply(clean_ply, v, t)
        v, t = read_ply(clean_ply)  # the float32 copy everyone reads
        rng = np.random.default_rng(a.seed)
        h = a.noise * mean_edge_length(v, t)
        noisy = v + vertex_normals(v, t) * rng.normal(0.0, h, size=(len(v), 1))
        write_ply(noisy_ply, noisy, t)
        source = f"{a.mesh} + numpy noise {a.noise} x mean edge length along vertex normals (seed {a.seed})"
    else:
        if binary is None:
            sys.exit("compare_peers: the vcsmooth binary is needed to generate the sphere "
                     "(cargo build --release, or --vcsmooth PATH), or pass --mesh FILE.ply")
        for out, extra in ((clean_ply, []), (noisy_ply, ["--noise", repr(a.noise), "--seed", str(a.seed)])):
            subprocess.run([binary, "generate", "sphere", out, "--subdivisions", str(k)] + extra,
                           check=True, capture_output=True)
        source = (f"vcsmooth generate sphere --subdivisions {k} --noise {a.noise} --seed {a.seed}")
    cv, ct = read_ply(clean_ply)
    nv, nt = read_ply(noisy_ply)
    if cv.shape != nv.shape or not np.array_equal(ct, nt):
        sys.exit("compare_peers: clean and noisy meshes differ in connectivity")
    np.savez(os.path.join(workdir, "noisy.npz"), v=nv, t=nt)
    return source, clean_ply, noisy_ply, cv, ct, nv, nt


def _order_plausible(v, noisy, edge):
    per_vertex = np.sqrt(np.mean(np.sum((v - noisy) ** 2, axis=1)))
    if per_vertex <= edge:
        return True
    try:
        from scipy.spatial import cKDTree
    except ImportError:
        return False
    d, _ = cKDTree(noisy).query(v, workers=-1)
    return per_vertex <= 3 * np.sqrt(np.mean(d ** 2)) + edge


def evaluate(v, t, ref):
    """Metrics of one smoothed result (positions v, triangles t or None when the library gave
    none back) against the noisy input and the clean mesh."""
    if not np.isfinite(v).all():
        return {"volume_change_pct": None, "rms": None, "rms_edges": None, "distance": "n/a (NaN)", "nan": True}
    if t is not None and len(t) == 0:
        t = None
    same_count = v.shape == ref["clean_v"].shape
    if t is not None:
        order_kept = same_count and np.array_equal(t, ref["t"])
        tris = t
    else:
        # No triangles came back to check the order with: a reordering would move vertices by
        # far more than smoothing does, so compare with the nearest input vertex.
        order_kept = same_count and _order_plausible(v, ref["noisy_v"], ref["edge"])
        tris = ref["t"] if order_kept else None
    vol = signed_volume(v, tris, ref["origin"]) if tris is not None else None
    rms, how = rms_distance(v, order_kept, ref["clean_v"])
    return {
        "volume_change_pct": None if vol is None else 100.0 * (vol - ref["vol_in"]) / abs(ref["vol_in"]),
        "rms": rms, "rms_edges": None if rms is None else rms / ref["edge"],
        "distance": how, "nan": False,
    }


def fmt(x, spec, none="n/a"):
    return none if x is None else format(x, spec)


def _loadavg():
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):
        return None


def compare_one(a, k, binary):
    load_start = _loadavg()
    workdir = tempfile.mkdtemp(prefix="compare_peers_", dir=a.workdir)
    try:
        source, clean_ply, noisy_ply, cv, ct, nv, nt = make_meshes(a, k, workdir, binary)
        origin = cv.mean(axis=0)
        ref = {"clean_v": cv, "noisy_v": nv, "t": ct, "origin": origin, "vol_in": signed_volume(nv, nt, origin),
               "edge": mean_edge_length(cv, ct)}
        rows = []
        base = evaluate(nv, nt, ref)
        rows.append({"library": "input", "method": "noisy", "status": "ok", "median_s": None, **base})
        print(f"\n== {source}: {len(nv)} vertices, {len(nt)} triangles; {a.iterations} iterations, "
              f"median of {a.repeats}, thread budget {a.threads}", file=sys.stderr, flush=True)

        env = dict(os.environ)
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            env[var] = str(a.threads)
        versions = {}
        for lib in a.peers:
            print(f"-- {lib}", file=sys.stderr, flush=True)
            cmd = [sys.executable, os.path.abspath(__file__), "--worker", lib, "--workdir", workdir,
                   "--iterations", str(a.iterations), "--repeats", str(a.repeats),
                   "--threads", str(a.threads), "--lambda", repr(a.lam), "--mu", repr(a.mu),
                   "--passband", repr(a.passband), "--skip", ",".join(a.skip)]
            try:
                p = subprocess.run(cmd, env=env, timeout=a.timeout,
                                   stdout=subprocess.DEVNULL, stderr=None if a.verbose else subprocess.PIPE, text=True)
                crash = None if p.returncode == 0 else f"worker exited {p.returncode}"
                errors = p.stderr
            except subprocess.TimeoutExpired as e:
                crash = f"timed out after {a.timeout} s"
                errors = e.stderr.decode(errors="replace") if isinstance(e.stderr, bytes) else e.stderr
            path = os.path.join(workdir, f"{lib}.json")
            rep = json.load(open(path)) if os.path.exists(path) else {"status": crash or "no report", "methods": []}
            if crash and rep["status"] == "ok":
                rep["status"] = crash
            failed = crash or rep["status"] != "ok" or any("error" in m for m in rep["methods"])
            if failed and errors and rep["status"].split()[0] != "not":
                print("\n".join(errors.strip().splitlines()[-15:]), file=sys.stderr)
            versions[lib] = rep.get("version")
            if not rep["methods"] and rep["status"] != "ok":
                rows.append({"library": lib, "method": "-", "status": rep["status"], "median_s": None})
            for m in rep["methods"]:
                row = {"library": lib, "method": m["method"], "call": m["call"]}
                if "error" in m:
                    row.update(status=f"error: {m['error']}", median_s=None)
                else:
                    d = np.load(m["output"])
                    t = d["t"] if m.get("faces_returned") else None
                    row.update(status="ok", times=m["times"], median_s=statistics.median(m["times"]),
                               **evaluate(d["v"], t, ref))
                rows.append(row)
            if crash and rep["methods"]:
                rows.append({"library": lib, "method": "(rest)", "status": crash, "median_s": None})

        if binary is None:
            rows.append({"library": "vcsmooth", "method": "-", "status": "not built", "median_s": None})
        else:
            v = subprocess.run([binary, "--version"], capture_output=True, text=True).stdout.strip()
            versions["vcsmooth"] = v.split()[-1] if v else "?"
            for method in a.vcs_methods:
                print(f"-- vcsmooth {method}", file=sys.stderr, flush=True)
                row = {"library": "vcsmooth", "method": method}
                try:
                    r = run_vcsmooth(binary, method, noisy_ply, workdir, a)
                    ov, ot = read_ply(r["output"])
                    row.update(status="ok", call=r["call"], times=r["times"], median_s=statistics.median(r["times"]),
                               phase_s=statistics.median(r["phase_times"]),
                               topology_s=statistics.median(r["topology_times"]), **evaluate(ov, ot, ref))
                except Exception as e:
                    row.update(status=f"error: {e}", median_s=None)
                rows.append(row)

        # Ratios against the fastest peer of the same kind and of any kind.
        peer = [r for r in rows if r["library"] in PEERS and r.get("median_s")]
        fastest_any = min(peer, key=lambda r: r["median_s"], default=None)
        for r in rows:
            if not r.get("median_s"):
                continue
            fam = FAMILY.get(r["method"])
            same = [p for p in peer if fam and FAMILY.get(p["method"]) == fam]
            best = min(same, key=lambda p: p["median_s"], default=None)
            r["x_same_kind"] = r["median_s"] / best["median_s"] if best else None
            r["same_kind_peer"] = f"{best['library']} {best['method']}" if best else None
            r["x_fastest_peer"] = r["median_s"] / fastest_any["median_s"] if fastest_any else None
            r["with_setup_s"] = r["median_s"] + r.get("topology_s", 0.0)
        return {
            "load_average": {"start": load_start, "end": _loadavg()},
            "mesh": source, "vertices": int(len(nv)), "triangles": int(len(nt)),
            "iterations": a.iterations, "repeats": a.repeats, "threads": a.threads,
            "lambda": a.lam, "mu": a.mu, "passband": a.passband,
            "mean_edge_length": ref["edge"], "versions": versions,
            "fastest_peer": f"{fastest_any['library']} {fastest_any['method']}" if fastest_any else None,
            "rows": rows,
        }
    finally:
        if a.keep:
            print(f"kept {workdir}", file=sys.stderr)
        else:
            shutil.rmtree(workdir, ignore_errors=True)


def seconds(x):
    if x is None:
        return "-"
    return f"{x:.3f}" if x >= 0.1 else f"{x:.4f}" if x >= 0.001 else f"{x:.2e}"


def speed(x, than=" than"):
    """x = peer time / vcsmooth time, as words."""
    return f"{x:.1f}x faster{than}" if x >= 1 else f"{1 / x:.1f}x slower{than}"


def print_table(res):
    print(f"\nmesh: {res['mesh']}: {res['vertices']} vertices, {res['triangles']} triangles")
    print(f"{res['iterations']} iterations, lambda {res['lambda']}, mu {res['mu']}, windowed-sinc pass band "
          f"{res['passband']:.4g}; median of {res['repeats']} runs; thread budget {res['threads']}; "
          f"machine {platform.machine()}, {os.cpu_count()} cores")
    la = res.get("load_average") or {}
    if la.get("start") and la.get("end"):
        print(f"load average (1 min) at start {la['start'][0]}, at end {la['end'][0]}: other work on the machine "
              "slows everyone; compare figures from one quiet run")
    print("versions: " + ", ".join(f"{k} {v}" for k, v in res["versions"].items() if v))
    head = ["method", "library", "median s", "+setup s", "x same-kind", "x fastest peer", "volume %", "RMS dist", "RMS/edge", "note"]
    body = []
    for r in res["rows"]:
        if r["status"] != "ok":
            body.append([r["method"], r["library"], "-", "-", "-", "-", "-", "-", "-", r["status"]])
            continue
        note = []
        if r.get("nan"):
            note.append("NaN!")
        if r.get("distance") not in (None, "per-vertex"):
            note.append(r["distance"])
        if r["library"] == "vcsmooth":
            note.append(f"phase {seconds(r['phase_s'])} s + topology {seconds(r['topology_s'])} s")
        body.append([
            r["method"], r["library"], seconds(r["median_s"]), seconds(r.get("with_setup_s")),
            fmt(r.get("x_same_kind"), ".2f", "-"), fmt(r.get("x_fastest_peer"), ".2f", "-"),
            fmt(r.get("volume_change_pct"), "+.3f"), fmt(r.get("rms"), ".3e"), fmt(r.get("rms_edges"), ".3f"),
            "; ".join(note)])
    widths = [max(len(str(x)) for x in col) for col in zip(head, *body)]
    line = lambda cells: "  ".join(str(c).ljust(w) if i in (0, 1, 9) else str(c).rjust(w)
                                   for i, (c, w) in enumerate(zip(cells, widths))).rstrip()
    print(line(head))
    print(line(["-" * w for w in widths]))
    for b in body:
        print(line(b))
    print("median s: smoothing call only (vcsmooth: sum of per-iteration seconds of its report; the note adds "
          "its whole smoothing phase, run with --stats last: volume and area after the last iteration "
          "only, as the peers compute none; and its topology build).")
    print("+setup s: peers build their adjacency inside the timed call; for vcsmooth this adds its topology "
          "build to the median, the same work.")
    print("x same-kind: time / fastest peer of the same kind (laplacian; taubin or windowed-sinc; hc or humphrey); "
          f"x fastest peer: time / fastest peer of any method ({res['fastest_peer']}).")
    print("volume %: change vs the noisy input; RMS dist: per-vertex distance to the clean mesh "
          f"(RMS/edge: in mean edge lengths, {res['mean_edge_length']:.4g}).")
    peers = [r for r in res["rows"] if r["library"] in PEERS and r.get("median_s")]
    for r in res["rows"]:
        if r["library"] == "vcsmooth" and r.get("median_s") and r.get("x_same_kind"):
            best = min((p for p in peers if FAMILY.get(p["method"]) == FAMILY.get(r["method"])),
                       key=lambda p: p["median_s"])
            fastest = r["median_s"] / r["x_fastest_peer"]
            print(f"vcsmooth {r['method']}: {speed(best['median_s'] / r['median_s'])} the fastest peer of its kind "
                  f"({r['same_kind_peer']}), {speed(fastest / r['median_s'])} the fastest peer of any method; "
                  f"counting its topology build: {speed(best['median_s'] / r['with_setup_s'], '')} and "
                  f"{speed(fastest / r['with_setup_s'], '')}")
    if not peers:
        print("no peer ran: pip install -r tools/requirements-peers.txt (or --install)")


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    def _get_help_string(self, action):
        if action.default in (None, "", False):
            return action.help
        return super()._get_help_string(action)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=_HelpFormatter)
    p.add_argument("--subdivisions", "--sizes", dest="subdivisions", type=int, nargs="+", default=[8],
                   metavar="K", help="icosphere level(s): 20*4^K triangles (6: 82k, 7: 328k, 8: 1.3M, 9: 5.2M)")
    p.add_argument("--mesh", help="use this PLY as the clean mesh (noise is added with numpy along vertex normals)")
    p.add_argument("--noise", type=float, default=0.3, help="noise sigma, relative to the mean edge length")
    p.add_argument("--seed", type=int, default=1, help="noise seed")
    p.add_argument("--iterations", type=int, default=10, help="iterations, the same for every smoother")
    p.add_argument("--repeats", type=int, default=3, help="timed runs per smoother (the median is reported)")
    p.add_argument("--threads", type=int, default=os.cpu_count() or 1,
                   help="thread budget: vcsmooth --threads, OMP_NUM_THREADS and VTK's SMP threads")
    p.add_argument("--lambda", dest="lam", type=float, default=0.5, help="Laplacian / Taubin lambda")
    p.add_argument("--mu", type=float, default=-0.53, help="Taubin mu (negative)")
    p.add_argument("--passband", type=float, default=None,
                   help="VTK windowed sinc pass band [default: Taubin's k_PB = 1/lambda + 1/mu]")
    p.add_argument("--peers", default=",".join(PEERS), help="comma-separated peer libraries to run ('' for none)")
    p.add_argument("--methods", default=",".join(VCS_METHODS_DEFAULT),
                   help=f"comma-separated vcsmooth methods, from {','.join(VCS_METHODS_ALL)} ('' for none)")
    p.add_argument("--skip", default="", metavar="LIST",
                   help="comma-separated peer methods to leave out, as METHOD or LIBRARY:METHOD "
                        "(e.g. pymeshlab:two-step, which takes minutes at 1M+ triangles)")
    p.add_argument("--vcsmooth", help="vcsmooth binary [default: $VCSMOOTH, target/release/vcsmooth, PATH]")
    p.add_argument("--json", metavar="OUT", help="also write the results as JSON")
    p.add_argument("--install", action="store_true", help="pip install -r tools/requirements-peers.txt first")
    p.add_argument("--timeout", type=float, default=3600, help="seconds allowed per peer library")
    p.add_argument("--workdir", default=None, help="where temporary meshes go [default: system temp dir]")
    p.add_argument("--keep", action="store_true", help="keep the temporary meshes and results")
    p.add_argument("--verbose", action="store_true", help="show the peer workers' progress and errors")
    p.add_argument("--worker", choices=PEERS, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.passband is None:
        a.passband = 1.0 / a.lam + 1.0 / a.mu
    a.skip = {x for x in a.skip.split(",") if x}
    if a.worker:
        return run_worker(a)
    if a.iterations < 1 or a.repeats < 1 or a.threads < 1:
        p.error("--iterations, --repeats and --threads must be at least 1")
    if a.mu >= 0:
        p.error("--mu must be negative")
    if not 0 < a.passband < 2:
        p.error("the windowed sinc pass band must lie in (0, 2); set --passband")
    a.peers = [x for x in a.peers.split(",") if x]
    a.vcs_methods = [x for x in a.methods.split(",") if x]
    for x in a.peers:
        if x not in PEERS:
            p.error(f"unknown peer {x!r}; known: {', '.join(PEERS)}")
    for x in a.vcs_methods:
        if x not in VCS_METHODS_ALL:
            p.error(f"unknown vcsmooth method {x!r}; known: {', '.join(VCS_METHODS_ALL)}")
    if a.workdir:
        # A missing work directory is created (with its parents); a path that cannot be one is
        # reported in one line rather than as a traceback.
        try:
            os.makedirs(a.workdir, exist_ok=True)
        except OSError as e:
            sys.exit(f"compare_peers: --workdir {a.workdir}: cannot create the directory ({e.strerror or e})")
        if not os.access(a.workdir, os.W_OK | os.X_OK):
            sys.exit(f"compare_peers: --workdir {a.workdir}: the directory is not writable")
    if a.json and not os.path.isdir(os.path.dirname(os.path.abspath(a.json))):
        sys.exit(f"compare_peers: --json {a.json}: its directory does not exist")
    if a.mesh and not os.path.isfile(a.mesh):
        sys.exit(f"compare_peers: --mesh {a.mesh}: no such file")
    if a.install:
        subprocess.run([sys.executable, "-m", "pip", "install", "-r", REQUIREMENTS], check=True)
    binary = find_vcsmooth(a.vcsmooth)
    if binary is None:
        print("compare_peers: vcsmooth binary not found (cargo build --release); peers only", file=sys.stderr)
    levels = [None] if a.mesh else a.subdivisions
    results = []
    for k in levels:
        res = compare_one(a, k, binary)
        print_table(res)
        results.append(res)
    if a.json:
        try:
            with open(a.json, "w") as f:
                json.dump({"tool": "tools/compare_peers.py", "argv": sys.argv, "results": results}, f, indent=1)
        except OSError as e:
            sys.exit(f"compare_peers: --json {a.json}: cannot write ({e.strerror or e})")


if __name__ == "__main__":
    main()
