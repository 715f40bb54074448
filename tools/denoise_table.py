#!/usr/bin/env python3
"""Denoising table: vcsmooth's methods and peer smoothers on noisy/clean mesh pairs.

For every pair NAME-noisy.ply / NAME-clean.ply in a folder (default ../shared/denoising beside
the repository: the pairs of Zhang et al. 2015, same vertices and triangles in both files):

1. smooth the noisy mesh with each vcsmooth column's settings
   (`vcsmooth smooth NOISY OUT <args> --report R.json`) and with each peer column (the peer
   runners of tools/compare_peers.py, each library in its own child process, so a library that is
   missing or crashes is a column of n/a with a note);
2. measure every result, and the noisy input, against the clean mesh as the denoising literature
   does:
   - nerr: mean angle (degrees) between each face's normal and the same face's clean normal;
   - dist: mean distance of the (referenced) vertices to the clean SURFACE (exact closest point on
     the clean triangles, tools/quality_table.py's SurfaceDistance), over the clean mesh's
     bounding-box diagonal; maxdist: the largest such distance;
   - dvol: relative volume change out/noisy - 1; for vcsmooth from its report (f64 working
     positions, so a volume-keeping method shows ~1e-15, not the float32 file's rounding), for a
     peer from its float64 result; both about the noisy vertices' mean (an open pair's volume
     depends on that origin, its change under fixed boundaries does not);
   - iterations: what a vcsmooth run did (`iterations_run`, and `auto_stop.stopped_by` with
     --iterations auto).
3. print one markdown table per metric (normal error first), then the targets.

Columns are named by a LABEL (used in tables, JSON and targets): noisy, the default vcsmooth
columns auto, taubin, vcs, crease (see --help), any --column LABEL=ARGS, and the peers
(--peer LABEL=LIBRARY:METHOD; default trimesh-hc and trimesh-taubin at --peer-iterations 10).

Targets (--target, repeatable) are checked on every pair of their scope; with --check the exit
status is 1 when one fails, when a cell it needs is missing, or when a vcsmooth run fails:

    [SCOPE:]LABEL[.METRIC] OP RHS     OP: <= < >= >     RHS: NUMBER | [FACTOR*]LABEL[.METRIC]

SCOPE: all (default), machined, organic, closed, open, or pair names joined by commas. METRIC:
nerr (default), dist, maxdist, dvol (compared as |dV|/V), iterations; an RHS label without a
metric takes the left side's. Examples:

    --target "machined:vcs-feature<=0.6*taubin" --target "machined:vcs-feature.dist<=taubin"
    --target "closed:vcs-feature.dvol<=1e-9"    --target "auto<=1.05*default10"

numpy only (the peers need their libraries: tools/requirements-peers.txt). See
tools/README-peers.md.
"""

import argparse
import json
import os
import re
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import compare_peers  # noqa: E402
from compare_peers import find_vcsmooth, read_ply, signed_volume  # noqa: E402
from quality_table import (SurfaceDistance, mean_edge_length, normal_errors,  # noqa: E402
                           referenced_vertices, report_iterations, report_volume)

DEFAULT_COLUMNS = [
    ("auto", "--iterations auto"),
    ("taubin", "--method taubin --iterations 10"),
    ("vcs", "--method vcs --iterations 10"),
    ("crease", "--crease-angle 40"),
]
# trimesh's filter_humphrey is the HC Laplacian (Vollmer et al. 1999) under its author's name.
DEFAULT_PEERS = [("trimesh-hc", "trimesh:humphrey"), ("trimesh-taubin", "trimesh:taubin")]
MACHINED = ["Block0.4", "Fandisk0.3", "Fandisk0.7", "SharpSphere0.3", "Twelve0.5Impulsive"]
METRICS = ["nerr", "dist", "maxdist", "dvol", "iterations"]
SCOPES = ["all", "machined", "organic", "closed", "open"]
EPILOG = """\
metrics, against the clean mesh:
  nerr        mean angle between each face's normal and the clean one's (degrees)
  dist        mean distance of the vertices to the clean surface / bounding-box diagonal
  maxdist     the largest such distance
  dvol        volume change against the noisy mesh, out/noisy - 1 (a target takes |dvol|)
  iterations  iterations a vcsmooth run did, and why --iterations auto stopped

targets:  [SCOPE:]LABEL[.METRIC] OP RHS
  SCOPE   all (default), machined, organic, closed, open, or pair names joined by commas
  LABEL   a column: noisy, a default or --column / --peer label
  METRIC  nerr (default), dist, maxdist, dvol, iterations
  OP      <=  <  >=  >
  RHS     NUMBER, or [FACTOR*]LABEL[.METRIC] (the left side's metric unless given)
examples:
  --target "machined:vcs-feature<=0.6*taubin"  --target "closed:vcs-feature.dvol<=1e-9"
  --target "auto<=1.05*default10"

more: tools/README-peers.md"""
LABEL = re.compile(r"^[A-Za-z][A-Za-z0-9_+-]*$")


class ToolError(Exception):
    """A problem with the tool's input: reported as one line, no traceback."""


# --------------------------------------------------------------------------------------------
# metrics

def is_closed(f):
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, count = np.unique(e, axis=0, return_counts=True)
    return bool(np.all(count == 2))


class Pair:
    """A clean mesh and its noisy copy, with what every result is measured against."""

    def __init__(self, name, clean_path, noisy_path, machined):
        self.name = name
        self.clean_v, self.f = read_ply(clean_path)
        self.noisy_v, nf = read_ply(noisy_path)
        self.noisy_path = noisy_path
        if self.clean_v.shape != self.noisy_v.shape or not np.array_equal(self.f, nf):
            raise ToolError(f"{noisy_path}: not the vertices and triangles of {clean_path}")
        self.used = referenced_vertices(len(self.clean_v), self.f)
        cu = self.clean_v[self.used]
        self.diag = float(np.linalg.norm(cu.max(axis=0) - cu.min(axis=0)))
        self.edge = mean_edge_length(self.clean_v, self.f)
        self.closed = is_closed(self.f)
        self.kind = "machined" if machined else "organic"
        self.origin = self.noisy_v[self.used].mean(axis=0)
        self.noisy_volume = signed_volume(self.noisy_v, self.f, self.origin)
        self.sd = SurfaceDistance(self.clean_v, self.f, cell=self.edge)

    def measure(self, v, f=None):
        """Metrics of a result with positions v (float64) against the clean mesh."""
        if v.shape != self.clean_v.shape or (f is not None and not np.array_equal(f, self.f)):
            raise ToolError("the result does not keep the input's vertices and triangles")
        if not np.isfinite(v[self.used]).all():
            raise ToolError("the result has non-finite coordinates")
        d = self.sd.query(v[self.used]) / self.diag
        return {
            "nerr": float(normal_errors(self.clean_v, self.f, v).mean()),
            "dist": float(d.mean()),
            "maxdist": float(d.max()),
            "dvol": signed_volume(v, self.f, self.origin) / self.noisy_volume - 1.0,
        }

    def info(self):
        return {"pair": self.name, "kind": self.kind, "closed": self.closed,
                "vertices": int(len(self.clean_v)), "triangles": int(len(self.f)),
                "bbox_diagonal": self.diag, "mean_edge_length": self.edge}


def find_pairs(folder, names):
    if not os.path.isdir(folder):
        raise ToolError(f"{folder}: no such folder (give the pairs' folder with --dir)")
    found = {}
    for x in sorted(os.listdir(folder)):
        if x.endswith("-noisy.ply") and os.path.isfile(os.path.join(folder, x[:-10] + "-clean.ply")):
            found[x[:-10]] = (os.path.join(folder, x[:-10] + "-clean.ply"), os.path.join(folder, x))
    if names:
        missing = [n for n in names if n not in found]
        if missing:
            raise ToolError(f"{folder}: no pair {', '.join(missing)} (NAME-noisy.ply with "
                            f"NAME-clean.ply; found {', '.join(found) or 'none'})")
        return [(n, *found[n]) for n in names]
    if not found:
        raise ToolError(f"{folder}: no NAME-noisy.ply with a NAME-clean.ply")
    return [(n, *v) for n, v in found.items()]


# --------------------------------------------------------------------------------------------
# runs

def run_vcsmooth(binary, pair, args, out, threads):
    rep_path = out[:-4] + ".json"
    cmd = [binary, "smooth", pair.noisy_path, out, *shlex.split(args), "--report", rep_path]
    if threads:
        cmd += ["--threads", str(threads)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if p.returncode != 0:
        raise ToolError(f"vcsmooth exited {p.returncode}: {p.stderr.strip()[-300:]}")
    with open(rep_path) as fh:
        rep = json.load(fh)
    ov, of = read_ply(out)
    cell = pair.measure(ov, of)
    cell["dvol_file"] = cell["dvol"]  # the float32 file's rounding included
    dvol = report_volume(rep)
    if dvol is not None:
        cell["dvol"] = dvol
    cell["iterations"] = rep.get("iterations_run", report_iterations(rep))
    stop = rep.get("auto_stop")
    if stop:
        cell["stopped_by"] = stop.get("stopped_by")
    cell["seconds"] = seconds
    return cell


class _AllBut:
    """compare_peers' worker skips the methods `in` its skip set: this one holds all others."""

    def __init__(self, keep):
        self.keep = set(keep)

    def __contains__(self, method):
        return method not in self.keep and method.split(":")[-1] not in self.keep


def peer_worker(a):
    """Child process: compare_peers' runner for one library on workdir/noisy.npz, only the
    methods asked for; it writes workdir/<library>.json and one .npz per method."""
    ns = argparse.Namespace(worker=a.peer_worker, workdir=a.workdir, iterations=a.peer_iterations,
                            repeats=1, threads=1, lam=0.5, mu=-0.53, passband=1 / 0.5 + 1 / -0.53,
                            skip=_AllBut(a.peer_methods.split(",")))
    compare_peers.run_worker(ns)


def run_peers(pair, peers, a, workdir):
    """Cells of every peer column on one pair (a missing library or method: a note)."""
    np.savez(os.path.join(workdir, "noisy.npz"), v=pair.noisy_v, t=pair.f)
    cells, versions = {}, {}
    libs = {}
    for label, (lib, method) in peers:
        libs.setdefault(lib, []).append((label, method))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    for lib, cols in libs.items():
        cmd = [a.peers_python, os.path.abspath(__file__), "--peer-worker", lib, "--workdir", workdir,
               "--peer-methods", ",".join(m for _, m in cols), "--peer-iterations", str(a.peer_iterations)]
        path = os.path.join(workdir, f"{lib}.json")
        if os.path.exists(path):
            os.remove(path)
        try:
            p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=a.timeout)
            crash = None if p.returncode == 0 else f"worker exited {p.returncode}: {p.stderr.strip()[-200:]}"
        except subprocess.TimeoutExpired:
            crash = f"timed out after {a.timeout:g} s"
        rep = {"status": crash or "no report", "methods": []}
        if os.path.exists(path):
            with open(path) as fh:
                rep = json.load(fh)
        status = crash or rep["status"]
        versions[lib] = rep.get("version")
        done = {m["method"]: m for m in rep["methods"]}
        for label, method in cols:
            m = done.get(method)
            if m is None:
                note = status if status != "ok" else f"{lib} has no method {method!r}"
                cells[label] = {"error": note}
            elif "error" in m:
                cells[label] = {"error": m["error"]}
            else:
                d = np.load(m["output"])
                try:
                    cell = pair.measure(np.asarray(d["v"], np.float64),
                                        d["t"] if m.get("faces_returned") else None)
                except ToolError as e:
                    cell = {"error": str(e)}
                cell["call"] = m["call"]
                cell["seconds"] = statistics.median(m["times"])
                cells[label] = cell
    return cells, versions


# --------------------------------------------------------------------------------------------
# targets

_TARGET = re.compile(r"^\s*(?:(?P<scope>[^:<>=]+):)?\s*(?P<lhs>[^<>=\s]+)\s*(?P<op><=|>=|<|>)\s*"
                     r"(?P<rhs>\S+)\s*$")
_OPS = {"<=": lambda x, y: x <= y, "<": lambda x, y: x < y,
        ">=": lambda x, y: x >= y, ">": lambda x, y: x > y}


def _ref(text, metric, labels, target):
    label, _, m = text.partition(".")
    m = m or metric
    if label not in labels:
        raise ToolError(f"--target {target!r}: no column {label!r} (columns: {', '.join(labels)})")
    if m not in METRICS:
        raise ToolError(f"--target {target!r}: no metric {m!r} (metrics: {', '.join(METRICS)})")
    return label, m


def parse_target(text, labels, pair_names):
    """A target as a dict: scope, op, lhs (label, metric), rhs (factor, label or None, metric)."""
    g = _TARGET.match(text)
    if not g:
        raise ToolError(f"--target {text!r}: not [SCOPE:]LABEL[.METRIC] OP RHS")
    scope = (g["scope"] or "all").strip()
    if scope not in SCOPES:
        unknown = [n for n in scope.split(",") if n not in pair_names]
        if unknown:
            raise ToolError(f"--target {text!r}: scope {', '.join(unknown)} is neither "
                            f"{', '.join(SCOPES)} nor a pair")
    lhs = _ref(g["lhs"], "nerr", labels, text)
    t = {"text": text, "scope": scope, "op": g["op"], "lhs": lhs}
    factor, star, ref = g["rhs"].rpartition("*")
    if not star:
        try:
            return {**t, "rhs": (float(ref), None, None)}
        except ValueError:
            factor = "1"
    try:
        factor = float(factor)
    except ValueError:
        raise ToolError(f"--target {text!r}: {factor!r} is not a number") from None
    return {**t, "rhs": (factor, *_ref(ref, lhs[1], labels, text))}


def in_scope(scope, row):
    if scope == "all":
        return True
    if scope in ("machined", "organic"):
        return row["kind"] == scope
    if scope in ("closed", "open"):
        return row["closed"] == (scope == "closed")
    return row["pair"] in scope.split(",")


def _value(row, label, metric):
    cell = row["cells"].get(label, {})
    x = cell.get(metric)
    if x is None:
        return None, cell.get("error", f"no {metric}")
    return (abs(x) if metric == "dvol" else x), None


def check_target(t, rows):
    """Per pair of the target's scope: the two sides and whether it holds (missing: fails)."""
    out = []
    for row in rows:
        if not in_scope(t["scope"], row):
            continue
        x, why = _value(row, *t["lhs"])
        factor, label, metric = t["rhs"]
        if label is None:
            y = factor
        else:
            y, why2 = _value(row, label, metric)
            why = why or why2
            y = None if y is None else factor * y
        ok = x is not None and y is not None and _OPS[t["op"]](x, y)
        out.append({"pair": row["pair"], "lhs": x, "rhs": y, "pass": bool(ok),
                    **({"missing": why} if why and not ok and (x is None or y is None) else {})})
    return out


# --------------------------------------------------------------------------------------------
# output

def _fmt(metric, cell):
    if "error" in cell:
        return "n/a"
    x = cell.get(metric)
    if x is None:
        return "—"
    if metric == "nerr":
        return f"{x:.2f}"
    if metric in ("dist", "maxdist"):
        return f"{x * 1e3:.3f}"
    if metric == "dvol":
        return "0" if x == 0 else f"{x:+.1e}"
    s = str(x)
    if cell.get("stopped_by"):
        s += f" ({cell['stopped_by']})"
    return s


TITLES = {
    "nerr": "Mean face-normal error against the clean mesh (degrees)",
    "dist": "Mean vertex distance to the clean surface (10⁻³ × bounding-box diagonal)",
    "maxdist": "Largest vertex distance to the clean surface (10⁻³ × bounding-box diagonal)",
    "dvol": "Relative volume change against the noisy mesh (dV/V)",
    "iterations": "Iterations run (why the automatic stop stopped)",
}


def _show(x):
    return f"{x:.4g}"


def markdown(rows, labels, metric):
    if metric == "iterations":
        labels = [x for x in labels if any("iterations" in r["cells"].get(x, {}) for r in rows)]
    lines = [f"### {TITLES[metric]}", "",
             "| pair | " + " | ".join(labels) + " |",
             "|---|" + "---:|" * len(labels)]
    for r in rows:
        name = r["pair"] + ("" if r["closed"] else " (open)")
        lines.append(f"| {name} | " + " | ".join(_fmt(metric, r["cells"].get(x, {})) for x in labels) + " |")
    return "\n".join(lines)


def write_json(path, doc):
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "w") as fh:
        json.dump(doc, fh, indent=1)
    os.replace(tmp, path)


# --------------------------------------------------------------------------------------------

def parse_columns(p, a):
    cols = [] if a.no_default_columns else list(DEFAULT_COLUMNS)
    for c in a.column:
        label, eq, args = c.partition("=")
        if not eq or not args.strip():
            p.error(f"--column {c!r}: not LABEL=ARGS")
        cols.append((label.strip(), args.strip()))
    peers = [] if a.no_peers else list(DEFAULT_PEERS)
    for c in a.peer:
        label, eq, spec = c.partition("=")
        if not eq or spec.count(":") != 1:
            p.error(f"--peer {c!r}: not LABEL=LIBRARY:METHOD")
        peers.append((label.strip(), spec.strip()))
    seen = {"noisy"}
    for label, _ in cols + peers:
        if not LABEL.match(label):
            p.error(f"column label {label!r}: letters, digits, '_', '+', '-' only, a letter first")
        if label in seen:
            p.error(f"column label {label!r} given twice (--no-default-columns / --no-peers "
                    "drop the defaults)")
        seen.add(label)
    for label, spec in peers:
        if spec.split(":")[0] not in compare_peers.PEERS:
            p.error(f"--peer {label}={spec}: unknown library (known: {', '.join(compare_peers.PEERS)})")
    return cols, [(label, tuple(spec.split(":"))) for label, spec in peers]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog=EPILOG)
    p.add_argument("--dir", default=os.path.join(REPO, "..", "shared", "denoising"),
                   help="folder of NAME-noisy.ply / NAME-clean.ply pairs [default: ../shared/denoising "
                        "beside the repository]")
    p.add_argument("--pairs", nargs="+", default=None, metavar="NAME", help="only these pairs")
    p.add_argument("--machined", default=",".join(MACHINED), metavar="LIST",
                   help="pairs that are machined parts (scope 'machined'; the rest are 'organic') "
                        "[default: %(default)s]")
    p.add_argument("--binary", default=None, metavar="PATH",
                   help="vcsmooth binary [default: $VCSMOOTH, target/release/vcsmooth, PATH]")
    p.add_argument("--column", action="append", default=[], metavar="LABEL=ARGS",
                   help="another vcsmooth column: its label and smooth arguments, e.g. "
                        "'vcs-feature=--method vcs-feature'")
    p.add_argument("--no-default-columns", action="store_true",
                   help="drop the default vcsmooth columns: " +
                        "; ".join(f"{k}={v}" for k, v in DEFAULT_COLUMNS))
    p.add_argument("--peer", action="append", default=[], metavar="LABEL=LIBRARY:METHOD",
                   help="another peer column, a runner of tools/compare_peers.py, e.g. "
                        "'meshlab-hc=pymeshlab:hc', 'vtk-sinc=vtk:windowed-sinc'")
    p.add_argument("--no-peers", action="store_true",
                   help="drop the default peers: " + "; ".join(f"{k}={v}" for k, v in DEFAULT_PEERS))
    p.add_argument("--peer-iterations", type=int, default=10, metavar="N",
                   help="iterations of every peer (compare_peers.py's mapping) [default: 10]")
    p.add_argument("--peers-python", default=sys.executable, metavar="PYTHON",
                   help="Python that runs the peers (where their libraries are installed) "
                        "[default: this one]")
    p.add_argument("--timeout", type=float, default=600, metavar="SECONDS",
                   help="seconds allowed per peer library and pair [default: 600]")
    p.add_argument("--threads", type=int, default=None, metavar="N",
                   help="vcsmooth --threads (the output does not depend on it) [default: vcsmooth's]")
    p.add_argument("--target", action="append", default=[], metavar="TARGET",
                   help="a target to check on every pair of its scope (repeatable; see below)")
    p.add_argument("--check", action="store_true",
                   help="exit 1 if a target fails or a vcsmooth run fails")
    p.add_argument("--json", default=None, metavar="FILE", help="write every number to FILE")
    p.add_argument("--workdir", default=None, metavar="DIR",
                   help="keep the smoothed meshes and reports here")
    p.add_argument("--peer-worker", help=argparse.SUPPRESS)
    p.add_argument("--peer-methods", help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.peer_worker:
        return peer_worker(a)
    if a.peer_iterations < 1:
        p.error("--peer-iterations must be at least 1")
    cols, peers = parse_columns(p, a)
    try:
        return table(a, cols, peers)
    except ToolError as e:
        sys.exit(f"denoise_table: error: {e}")
    except OSError as e:
        sys.exit(f"denoise_table: error: {e.filename or ''}: {e.strerror or e}")


def table(a, cols, peers):
    t_start = time.perf_counter()
    if a.json and not os.path.isdir(os.path.dirname(os.path.abspath(a.json))):
        raise ToolError(f"{a.json}: its folder does not exist")
    if a.binary and not (os.path.isfile(a.binary) and os.access(a.binary, os.X_OK)):
        raise ToolError(f"{a.binary}: not an executable file (--binary)")
    binary = find_vcsmooth(a.binary) if cols else None
    if cols and binary is None:
        raise ToolError("no vcsmooth binary (cargo build --release, or --binary PATH)")
    pairs = find_pairs(a.dir, a.pairs)
    machined = {x for x in a.machined.split(",") if x}
    labels = ["noisy"] + [x for x, _ in cols] + [x for x, _ in peers]
    targets = [parse_target(t, labels, [n for n, _, _ in pairs]) for t in a.target]
    work = a.workdir or tempfile.mkdtemp(prefix="denoise-table-")
    os.makedirs(work, exist_ok=True)
    version = None
    if binary:
        version = subprocess.run([binary, "--version"], capture_output=True, text=True).stdout.strip()
    rows, run_errors, peer_versions = [], [], {}
    try:
        for name, clean, noisy in pairs:
            print(f"-- {name}", file=sys.stderr, flush=True)
            pair = Pair(name, clean, noisy, name in machined)
            row = {**pair.info(), "cells": {"noisy": pair.measure(pair.noisy_v)}}
            row["cells"]["noisy"]["dvol"] = 0.0
            for label, args in cols:
                try:
                    row["cells"][label] = run_vcsmooth(binary, pair, args,
                                                       os.path.join(work, f"{name}-{label}.ply"), a.threads)
                except (ToolError, OSError, ValueError) as e:
                    row["cells"][label] = {"error": str(e)}
                    run_errors.append(f"{name} {label}: {e}")
            if peers:
                pdir = os.path.join(work, f"{name}-peers")
                os.makedirs(pdir, exist_ok=True)
                cells, versions = run_peers(pair, peers, a, pdir)
                row["cells"].update(cells)
                peer_versions.update({k: v for k, v in versions.items() if v})
            rows.append(row)
    finally:
        if a.workdir is None:
            shutil.rmtree(work, ignore_errors=True)

    print(f"{len(rows)} pairs from {os.path.normpath(a.dir)}; vcsmooth: {version or 'not run'}\n")
    for metric in METRICS:
        print(markdown(rows, labels, metric) + "\n")
    print("Columns:")
    print("- noisy: the noisy input")
    for label, args in cols:
        print(f"- {label}: vcsmooth smooth NOISY OUT {args}")
    for label, (lib, method) in peers:
        calls = [r["cells"][label].get("call") for r in rows if r["cells"][label].get("call")]
        notes = sorted({r["cells"][label]["error"] for r in rows if "error" in r["cells"][label]})
        what = calls[0] if calls else method
        ver = peer_versions.get(lib)
        print(f"- {label}: {lib}{' ' + ver if ver else ''} {what}"
              + (f" — n/a: {'; '.join(notes)}" if notes else ""))
    for e in run_errors:
        print(f"- ERROR {e}")

    checked, failed = [], bool(run_errors)
    if targets:
        print("\nTargets:")
    for t in targets:
        res = check_target(t, rows)
        ok = bool(res) and all(r["pass"] for r in res)
        failed |= not ok
        checked.append({"target": t["text"], "pass": ok, "pairs": res})
        bad = [r for r in res if not r["pass"]]
        detail = "no pair in scope" if not res else ", ".join(
            f"{r['pair']} " + (r.get("missing") or f"{_show(r['lhs'])} vs {_show(r['rhs'])}")
            for r in bad)
        print(f"- {'PASS' if ok else 'FAIL'} {t['text']} ({len(res) - len(bad)}/{len(res)} pairs"
              + (f"; failing: {detail}" if not ok else "") + ")")
    seconds = time.perf_counter() - t_start
    print(f"\n{seconds:.1f} s in all")
    if a.json:
        write_json(a.json, {
            "tool": "tools/denoise_table.py", "argv": sys.argv, "vcsmooth": version,
            "binary": binary, "peer_versions": peer_versions, "seconds": seconds,
            "columns": [{"label": "noisy", "kind": "input"}]
            + [{"label": x, "kind": "vcsmooth", "args": y} for x, y in cols]
            + [{"label": x, "kind": "peer", "library": lib, "method": m,
                "iterations": a.peer_iterations} for x, (lib, m) in peers],
            "units": {"nerr": "degrees", "dist": "bounding-box diagonal", "maxdist": "bounding-box diagonal",
                      "dvol": "relative (out / noisy - 1)"},
            "pairs": rows, "targets": checked, "run_errors": run_errors,
        })
    if a.check and failed:
        sys.exit(1)


if __name__ == "__main__":
    main()
