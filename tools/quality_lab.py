#!/usr/bin/env python3
"""The quality table for the research prototype (examples/lowpass_lab.rs), before it is in the tool.

Same cases, noise and measures as tools/quality_table.py (which it imports); the baseline is the
real binary's `--method taubin --iterations 10`, the candidate a run of the lab binary:
  lowpass_lab NOISY PREFIX METHOD ITERS [key=value ...]   (ITERS may be `auto`)
whose last written iterate (PREFIX.K.bin, f64) is measured. Build it with
  cargo build --release --example lowpass_lab
Example (the proposed variant with the automatic stop):
  tools/quality_lab.py --lab "lpr auto r=2"
"""

import argparse
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from quality_table import (SurfaceDistance, mean_edge_length, read_ply, report_volume,  # noqa: E402
                           run, surface_metrics)


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", default="/work/shared/meshes")
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--binary", default=os.path.join(here, "..", "target", "release", "vcsmooth"))
    ap.add_argument("--lab-binary",
                    default=os.path.join(here, "..", "target", "release", "examples", "lowpass_lab"))
    ap.add_argument("--lab", action="append", required=True,
                    help="a lab column: 'METHOD ITERS [key=value ...]'")
    ap.add_argument("--sigma", type=float, nargs="+", default=[0.2, 0.5])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    if not os.path.isdir(args.meshes):
        args.meshes = os.path.join(here, "..", "tests", "data")
    scans = sorted((x for x in os.listdir(args.meshes) if x.endswith(".ply")),
                   key=lambda s: os.path.getsize(os.path.join(args.meshes, s)))
    if args.only:
        scans = [s for s in scans if s in args.only or s[:-4] in args.only]
    work = tempfile.mkdtemp(prefix="quality-lab-")
    results, npass = [], 0
    print(f"{'scan':22s} {'sigma':>5s} | {'taubin 10: rms max nerr dvol':>30s}", end="")
    for c in args.lab:
        print(f" | {c + ': it rms max nerr dvol':>38s}", end="")
    print(" | first lab column vs taubin 10")
    for scan in scans:
        path = os.path.join(args.meshes, scan)
        cv, f = read_ply(path)
        s = mean_edge_length(cv, f)
        sd = SurfaceDistance(cv, f, cell=s)
        for sigma in args.sigma:
            noisy = os.path.join(work, "noisy.ply")
            run([args.binary, "generate", "mesh", noisy, "--from", path, "--subdivide", "0",
                 "--noise", f"{sigma}", "--seed", str(args.seed)])
            out = os.path.join(work, "taubin.ply")
            run([args.binary, "smooth", noisy, out, "--method", "taubin", "--iterations", "10",
                 "--threads", "1", "--report", out + ".json"])
            b = surface_metrics(cv, f, read_ply(out)[0], sd, s)
            with open(out + ".json") as fh:
                b["dvol"] = report_volume(json.load(fh))
            row = {"scan": scan, "sigma": sigma, "taubin10": b, "lab": []}
            line = (f"{scan[:22]:22s} {sigma:5.2f} | {b['rms']:7.4f} {b['max']:6.3f} "
                    f"{b['nerr']:6.2f} {b['dvol']:+.0e}")
            for c in args.lab:
                method, iters, *params = shlex.split(c)
                prefix = os.path.join(work, "lab")
                r = run([args.lab_binary, noisy, prefix, method, iters, *params])
                steps = [json.loads(x) for x in r.stdout.splitlines() if x.strip()]
                k = steps[-1]["iteration"]
                p = np.fromfile(f"{prefix}.{k}.bin", "<f8").reshape(-1, 3)
                for j in range(1, k + 1):
                    os.remove(f"{prefix}.{j}.bin")
                m = surface_metrics(cv, f, p, sd, s)
                m.update(iterations=k, dvol=steps[-1]["dvol"])
                m["pass"] = bool(m["rms"] <= b["rms"] and m["nerr"] <= b["nerr"]
                                 and m["max"] <= 1.1 * b["max"] and abs(m["dvol"]) <= 1e-9)
                row["lab"].append(m)
                line += (f" | {k:3d} {m['rms']:7.4f} {m['max']:6.3f} {m['nerr']:6.2f} "
                         f"{m['dvol']:+.0e} {'PASS' if m['pass'] else 'FAIL'}")
            m = row["lab"][0]
            npass += m["pass"]
            line += (f" | rms {m['rms'] / b['rms'] - 1:+.1%} max {m['max'] / b['max']:.2f}x "
                     f"nerr {m['nerr'] / b['nerr'] - 1:+.1%}")
            print(line, flush=True)
            results.append(row)
    shutil.rmtree(work, ignore_errors=True)
    print(f"\nfirst lab column: {npass}/{len(results)} cases PASS")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main()
