#!/usr/bin/env python3
"""Denoising quality of vcsmooth's methods on real scans.

For every scan (PLY) in a folder and every noise level sigma (x mean edge length):

1. make the noisy mesh reproducibly with the binary itself
   (`vcsmooth generate mesh NOISY.ply --from SCAN --subdivide 0 --noise SIGMA --seed S`:
   Gaussian noise along the vertex normals, same vertex order and faces as the scan);
2. smooth it with each column's settings (`vcsmooth smooth NOISY OUT <column args> --report R.json`);
3. measure the result against the clean scan:
   - rms / max: distance of every (referenced) output vertex to the clean SURFACE, i.e. the exact
     closest point on the clean triangles (a uniform grid of triangle boxes gives candidates; a
     point whose best candidate is farther than one cell is searched over all triangles, so the
     result is exact);
   - nerr: mean angle (degrees) between each output face normal and the same face's clean normal
     (the connectivity is unchanged by smoothing);
   - dvol: relative volume change out/in, taken from the report (f64 working positions);
   all distances in units of the scan's mean edge length.

The first column is the baseline (default: --method taubin --iterations 10), the second the
candidate (default: --iterations auto, i.e. the default method with automatic stopping), then any
--extra columns. PASS for a case: candidate rms <= baseline rms, candidate nerr <= baseline nerr,
candidate max <= 1.1 x baseline max, |dvol| <= 1e-9. With --check the exit status is 1 if any case
FAILs (or a run fails).

numpy only. Example:
  tools/quality_table.py --binary target/release/vcsmooth \
      --extra "--method vcs --iterations 5" --check
"""

import argparse
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

# The PLY reader is compare_peers.py's (binary and ASCII; polygons fan-triangulated).
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare_peers import read_ply  # noqa: E402


# --------------------------------------------------------------------------------------------
# geometry

def face_normals(v, f):
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n


def signed_volume(v, f):
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def mean_edge_length(v, f):
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    return float(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1).mean())


def _dot(x, y):
    return np.einsum("ij,ij->i", x, y)


def point_triangle_dist2(p, a, b, c):
    """Exact squared distance from points p to triangles (a, b, c), row by row (Ericson's
    Voronoi-region test). Degenerate triangles fall back to the nearest of their edges."""
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v = vb / den
        w = vc / den
        q = a + ab * v[:, None] + ac * w[:, None]  # interior
        # edge BC
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        q = np.where(m[:, None], b + (c - b) * t[:, None], q)
        # vertex C
        m = (d6 >= 0) & (d5 <= d6)
        q = np.where(m[:, None], c, q)
        # edge AC
        t = d2 / (d2 - d6)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        q = np.where(m[:, None], a + ac * t[:, None], q)
        # edge AB
        t = d1 / (d1 - d3)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        q = np.where(m[:, None], a + ab * t[:, None], q)
        # vertex B
        m = (d3 >= 0) & (d4 <= d3)
        q = np.where(m[:, None], b, q)
        # vertex A
        m = (d1 <= 0) & (d2 <= 0)
        q = np.where(m[:, None], a, q)
    d = p - q
    r = _dot(d, d)
    bad = ~np.isfinite(r)
    if bad.any():  # degenerate triangle: distance to its three segments
        r[bad] = np.minimum.reduce([
            _seg_dist2(p[bad], a[bad], b[bad]),
            _seg_dist2(p[bad], b[bad], c[bad]),
            _seg_dist2(p[bad], c[bad], a[bad])])
    return r


def _seg_dist2(p, a, b):
    ab = b - a
    den = _dot(ab, ab)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(np.where(den > 0, _dot(p - a, ab) / den, 0.0), 0.0, 1.0)
    d = p - (a + ab * t[:, None])
    return _dot(d, d)


class SurfaceDistance:
    """Exact distance from points to a triangle mesh's surface (uniform grid of triangle boxes)."""

    def __init__(self, v, f, cell):
        self.v, self.f = v, f
        self.tri = f[np.all(np.isfinite(v[f].reshape(len(f), -1)), axis=1)]
        self.cell = float(cell)
        tv = v[self.tri]
        self.lo_box = tv.min(axis=1)
        self.hi_box = tv.max(axis=1)

    def query(self, p, chunk=16384):
        h = self.cell
        origin = np.minimum(self.lo_box.min(axis=0), p.min(axis=0)) - 2 * h
        top = np.maximum(self.hi_box.max(axis=0), p.max(axis=0)) + 2 * h
        dims = np.floor((top - origin) / h).astype(np.int64) + 1
        lo = np.floor((self.lo_box - origin) / h).astype(np.int64)
        hi = np.floor((self.hi_box - origin) / h).astype(np.int64)
        ext = hi - lo + 1
        cnt = ext.prod(axis=1)
        tid = np.repeat(np.arange(len(self.tri)), cnt)
        local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ex = ext[tid]
        ix = lo[tid, 0] + local % ex[:, 0]
        iy = lo[tid, 1] + (local // ex[:, 0]) % ex[:, 1]
        iz = lo[tid, 2] + local // (ex[:, 0] * ex[:, 1])
        key = (ix * dims[1] + iy) * dims[2] + iz
        order = np.argsort(key, kind="stable")
        ckey, ctri = key[order], tid[order]
        offs = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)])
        out = np.empty(len(p))
        for s in range(0, len(p), chunk):
            pc = p[s:s + chunk]
            c = np.floor((pc - origin) / h).astype(np.int64)
            cc = c[:, None, :] + offs[None, :, :]  # (P, 27, 3)
            k = (cc[..., 0] * dims[1] + cc[..., 1]) * dims[2] + cc[..., 2]
            st = np.searchsorted(ckey, k, "left").ravel()
            en = np.searchsorted(ckey, k, "right").ravel()
            n = en - st
            npt = n.reshape(len(pc), 27).sum(axis=1)
            tot = int(n.sum())
            pidx = np.repeat(np.arange(len(pc)), npt)
            cand = ctri[np.repeat(st, n) + (np.arange(tot) - np.repeat(np.cumsum(n) - n, n))]
            t = self.tri[cand]
            d2 = point_triangle_dist2(pc[pidx], self.v[t[:, 0]], self.v[t[:, 1]], self.v[t[:, 2]])
            best = np.full(len(pc), np.inf)
            has = npt > 0
            starts = np.cumsum(npt) - npt
            best[has] = np.minimum.reduceat(d2, starts[has])
            out[s:s + chunk] = best
        # exact only when the best candidate lies within one cell; the rest: all triangles
        far = np.flatnonzero(~(out <= h * h))
        if len(far):
            out[far] = self._brute(p[far])
        return np.sqrt(out)

    def _brute(self, p, block=4_000_000):
        a, b, c = (self.v[self.tri[:, i]] for i in range(3))
        m = len(self.tri)
        best = np.full(len(p), np.inf)
        step = max(1, block // m)
        for s in range(0, len(p), step):
            pc = p[s:s + step]
            k = len(pc)
            d2 = point_triangle_dist2(np.repeat(pc, m, axis=0), np.tile(a, (k, 1)),
                                      np.tile(b, (k, 1)), np.tile(c, (k, 1)))
            best[s:s + step] = d2.reshape(k, m).min(axis=1)
        return best


def normal_errors(clean_v, f, out_v):
    """Angle (degrees) between each face's normal in out_v and the same face's in clean_v;
    faces degenerate in either are left out."""
    nc = face_normals(clean_v, f)
    no = face_normals(out_v, f)
    lc, lo = np.linalg.norm(nc, axis=1), np.linalg.norm(no, axis=1)
    ok = (lc > 0) & (lo > 0)
    cosang = np.clip(_dot(nc[ok], no[ok]) / (lc[ok] * lo[ok]), -1.0, 1.0)
    return np.degrees(np.arccos(cosang))


def referenced_vertices(n, f):
    used = np.zeros(n, bool)
    used[f.ravel()] = True
    return used


def surface_metrics(clean_v, f, out_v, sd, scale):
    d = sd.query(out_v[referenced_vertices(len(clean_v), f)]) / scale
    return {
        "rms": float(np.sqrt(np.mean(d * d))),
        "max": float(d.max()),
        "nerr": float(normal_errors(clean_v, f, out_v).mean()),
    }


# --------------------------------------------------------------------------------------------
# runs

def run(cmd):
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{shlex.join(cmd)} failed ({r.returncode}): {r.stderr.strip()[-400:]}")
    return r


def report_volume(rep):
    """Relative volume change from a smooth report (f64 working positions)."""
    vin = rep["input"]["stats"].get("volume")
    its = rep.get("iterations") or []
    vout = None
    for it in reversed(its):
        if it.get("volume") is not None:
            vout = it["volume"]
            break
    if vin and vout is not None:
        return vout / vin - 1.0
    pct = rep.get("summary", {}).get("volume_pct")
    return None if pct is None else pct / 100.0 - 1.0


def report_iterations(rep):
    its = rep.get("iterations") or []
    if its:
        return max(it.get("iteration", 0) for it in its)
    return rep.get("options", {}).get("iterations")


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", default=None,
                    help="folder of clean PLY scans [default: /work/shared/meshes, else tests/data]")
    ap.add_argument("--only", nargs="*", default=None, help="only these scans (file name or stem)")
    ap.add_argument("--binary", default=os.path.join(here, "..", "target", "release", "vcsmooth"))
    ap.add_argument("--sigma", type=float, nargs="+", default=[0.2, 0.5])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--baseline", default="--method taubin --iterations 10")
    ap.add_argument("--candidate", default="--iterations auto")
    ap.add_argument("--extra", action="append", default=[],
                    help="another column: smooth arguments, e.g. '--method vcs --iterations 5'")
    ap.add_argument("--threads", type=int, default=1, help="--threads for the smooth runs")
    ap.add_argument("--workdir", default=None, help="keep the noisy and smoothed meshes here")
    ap.add_argument("--json", default=None, help="write all numbers to this JSON file")
    ap.add_argument("--check", action="store_true", help="exit 1 if any case FAILs")
    args = ap.parse_args()

    folder = args.meshes
    if folder is None:
        folder = "/work/shared/meshes"
        if not os.path.isdir(folder):
            folder = os.path.join(here, "..", "tests", "data")
    scans = sorted(x for x in os.listdir(folder) if x.endswith(".ply"))
    if args.only:
        scans = [s for s in scans if s in args.only or s[:-4] in args.only]
    scans.sort(key=lambda s: os.path.getsize(os.path.join(folder, s)))

    cols = [("baseline", args.baseline), ("candidate", args.candidate)]
    cols += [(f"extra{i + 1}", e) for i, e in enumerate(args.extra)]
    work = args.workdir or tempfile.mkdtemp(prefix="quality-")
    os.makedirs(work, exist_ok=True)

    print("columns (distances in mean edge lengths of the clean scan, nerr in degrees):")
    for name, a in cols:
        print(f"  {name:9s}: vcsmooth smooth NOISY OUT {a}")
    print()
    hdr = f"{'scan':24s} {'sigma':>5s} | {'input rms/max/nerr':>20s}"
    for name, _ in cols:
        hdr += f" | {name + ' it rms max nerr dvol':>39s}"
    print(hdr + " | result")
    results = []
    failed = False
    for scan in scans:
        path = os.path.join(folder, scan)
        cv, f = read_ply(path)
        scale = mean_edge_length(cv, f)
        sd = SurfaceDistance(cv, f, cell=scale)
        for sigma in args.sigma:
            stem = f"{scan[:-4]}-s{sigma:g}"
            noisy = os.path.join(work, stem + "-noisy.ply")
            run([args.binary, "generate", "mesh", noisy, "--from", path, "--subdivide", "0",
                 "--noise", f"{sigma}", "--seed", str(args.seed)])
            nv, nf = read_ply(noisy)
            if nv.shape != cv.shape or not np.array_equal(nf, f):
                raise RuntimeError(f"{noisy}: not the scan's vertices and faces")
            row = {"scan": scan, "sigma": sigma, "input": surface_metrics(cv, f, nv, sd, scale)}
            for name, a in cols:
                out = os.path.join(work, f"{stem}-{name}.ply")
                rep_path = out[:-4] + ".json"
                t0 = time.time()
                try:
                    run([args.binary, "smooth", noisy, out, *shlex.split(a),
                         "--threads", str(args.threads), "--report", rep_path])
                    with open(rep_path) as fh:
                        rep = json.load(fh)
                    ov, of = read_ply(out)
                    m = surface_metrics(cv, f, ov, sd, scale)
                    m["dvol"] = report_volume(rep)
                    m["iterations"] = report_iterations(rep)
                    m["seconds"] = time.time() - t0
                except Exception as e:  # noqa: BLE001 - a failed run is a FAIL, reported
                    m = {"error": str(e)}
                row[name] = m
            b, c = row["baseline"], row["candidate"]

            def verdict(c):
                if "error" in c or "error" in b:
                    return False, "ERROR"
                why = []
                if c["rms"] > b["rms"]:
                    why.append(f"rms {c['rms'] / b['rms'] - 1:+.1%}")
                if c["nerr"] > b["nerr"]:
                    why.append(f"nerr {c['nerr'] / b['nerr'] - 1:+.1%}")
                if c["max"] > 1.1 * b["max"]:
                    why.append(f"max {c['max'] / b['max']:.2f}x")
                if c["dvol"] is None or abs(c["dvol"]) > 1e-9:
                    why.append("volume")
                return not why, ", ".join(why)

            ok, why = verdict(c)
            row["pass"], row["why"] = ok, why
            for name, _ in cols[2:]:
                if "error" not in row[name]:
                    row[name]["pass"] = verdict(row[name])[0]
            failed |= not ok
            results.append(row)
            i = row["input"]
            line = f"{scan:24s} {sigma:5.2f} | {i['rms']:6.3f} {i['max']:6.3f} {i['nerr']:6.2f}"
            for name, _ in cols:
                m = row[name]
                if "error" in m:
                    line += f" | {'ERROR':>39s}"
                    continue
                dv = "  n/a  " if m["dvol"] is None else f"{m['dvol']:+.0e}"
                p = "" if name in ("baseline", "candidate") else ("+" if m["pass"] else "-")
                line += (f" | {str(m['iterations']):>3s} {m['rms']:6.3f} {m['max']:6.3f}"
                         f" {m['nerr']:6.2f} {dv:>8s}{p:1s}")
            line += " | " + ("PASS" if ok else "FAIL " + why)
            print(line, flush=True)
            for name, _ in cols:
                if "error" in row[name]:
                    print(f"    {name}: {row[name]['error']}", file=sys.stderr)
    if args.workdir is None:
        shutil.rmtree(work, ignore_errors=True)
    npass = sum(r["pass"] for r in results)
    print(f"\n{npass}/{len(results)} cases PASS (candidate vs baseline: rms <=, nerr <=, "
          f"max <= 1.1x, |dvol| <= 1e-9); extra columns marked +/- by the same test")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"columns": dict(cols), "results": results}, fh, indent=1)
    if args.check and failed:
        sys.exit(1)


if __name__ == "__main__":
    main()
