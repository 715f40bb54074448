#!/usr/bin/env python3
"""Screen first-step parameters of vcs-lowpass against the quality target.

For every scan x sigma x seed: the noisy mesh (`vcsmooth generate mesh ... --seed S`, as
tools/quality_table.py makes it) and the baseline (`--method taubin --iterations 10`, the
binary's defaults) are made once and cached in --workdir; then for every configuration (smooth
arguments, e.g. "--method vcs-lowpass --lambda 0.6 --mu -0.62"):

- `auto`: the configuration with `--iterations auto`: stop iteration, rms / max / nerr / dvol,
  the margins against the baseline (rms %, nerr %, max ratio) and PASS as quality_table.py;
- with --curve K also the whole curve 1..K (the configuration with `--iterations 1`, chained
  through files: vcs-lowpass and taubin iterations depend only on the positions; the f32 files
  round each iterate, which moves no printed digit), and the iterations that PASS (the window
  around the auto stop is the margin of the stopping rule);
- a configuration "lab:METHOD key=value ..." runs examples/lowpass_lab.rs instead (auto: its
  `auto` stop; curve: its f64 iterates), e.g. "lab:lpr r=3" or "lab:lpr r=2 bil=3".

numpy only; distances in mean edge lengths of the clean scan. Writes every number to --json.
Example:
  tools/lowpass_sweep.py --only armadillo-86k demosthenes-17k --seeds 1 2 3 \
      --config "--method vcs-lowpass" --config "--method vcs-lowpass --lambda 0.6 --mu -0.62"
"""

import argparse
import json
import os
import shlex
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare_peers import read_ply  # noqa: E402
from quality_table import (SurfaceDistance, mean_edge_length, report_iterations,  # noqa: E402
                           report_volume, run, surface_metrics)


def verdict(c, b):
    m = {"rms": c["rms"] / b["rms"] - 1, "nerr": c["nerr"] / b["nerr"] - 1,
         "max": c["max"] / b["max"]}
    ok = m["rms"] <= 0 and m["nerr"] <= 0 and m["max"] <= 1.1
    if "dvol" in c:
        ok = ok and c["dvol"] is not None and abs(c["dvol"]) <= 1e-9
    return ok, m


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", default="/work/shared/meshes")
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--binary", default=os.path.join(here, "..", "target", "release", "vcsmooth"))
    ap.add_argument("--sigma", type=float, nargs="+", default=[0.2, 0.5])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--baseline", default="--method taubin --iterations 10")
    ap.add_argument("--config", action="append", default=[])
    ap.add_argument("--curve", type=int, default=0, help="also measure iterations 1..K")
    ap.add_argument("--every", type=int, default=1, help="measure the curve every N iterations")
    ap.add_argument("--no-auto", action="store_true", help="only the curves")
    ap.add_argument("--lab-binary",
                    default=os.path.join(here, "..", "target", "release", "examples", "lowpass_lab"))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--workdir", default="/tmp/lowpass-sweep")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    os.makedirs(args.workdir, exist_ok=True)
    cache_path = os.path.join(args.workdir, "baseline.json")
    cache = json.load(open(cache_path)) if os.path.exists(cache_path) else {}
    scans = sorted(x for x in os.listdir(args.meshes) if x.endswith(".ply"))
    if args.only:
        scans = [s for s in scans if s in args.only or s[:-4] in args.only]
    scans.sort(key=lambda s: os.path.getsize(os.path.join(args.meshes, s)))

    def smooth(noisy, out, a):
        rep_path = out[:-4] + ".json"
        run([args.binary, "smooth", noisy, out, *shlex.split(a), "--threads", str(args.threads),
             "--report", rep_path])
        with open(rep_path) as fh:
            return json.load(fh)

    results = []
    totals = {c: {} for c in args.config}
    for scan in scans:
        path = os.path.join(args.meshes, scan)
        cv, f = read_ply(path)
        scale = mean_edge_length(cv, f)
        sd = SurfaceDistance(cv, f, cell=scale)

        def measure(out):
            ov, _ = read_ply(out)
            return surface_metrics(cv, f, ov, sd, scale)

        for sigma in args.sigma:
            for seed in args.seeds:
                stem = f"{scan[:-4]}-s{sigma:g}-seed{seed}"
                noisy = os.path.join(args.workdir, stem + "-noisy.ply")
                key = f"{stem}|{args.baseline}"
                if not os.path.exists(noisy):
                    run([args.binary, "generate", "mesh", noisy, "--from", path, "--subdivide",
                         "0", "--noise", f"{sigma}", "--seed", str(seed)])
                    cache.pop(key, None)
                if key not in cache:
                    out = os.path.join(args.workdir, stem + "-baseline.ply")
                    smooth(noisy, out, args.baseline)
                    cache[key] = measure(out)
                    json.dump(cache, open(cache_path, "w"), indent=1)
                b = cache[key]
                for ci, cfg in enumerate(args.config):
                    row = {"scan": scan[:-4], "sigma": sigma, "seed": seed, "config": cfg,
                           "baseline": b}
                    out = os.path.join(args.workdir, f"{stem}-c{ci}.ply")
                    line = f"{scan[:-4]:16s} {sigma:4.2f} s{seed} [{cfg}]"
                    if cfg.startswith("lab:"):
                        lm, *kv = shlex.split(cfg[4:])
                        nv = read_ply(noisy)[0].shape[0]

                        def lab(iters):
                            pre = os.path.join(args.workdir, f"{stem}-lab{ci}")
                            for x in os.listdir(args.workdir):
                                if x.startswith(os.path.basename(pre) + "."):
                                    os.remove(os.path.join(args.workdir, x))
                            r = run([args.lab_binary, noisy, pre, lm, iters, *kv])
                            its = [json.loads(x) for x in r.stdout.splitlines() if x.startswith("{")]
                            return pre, its

                        def lab_metrics(pre, k):
                            v = np.fromfile(f"{pre}.{k}.bin", dtype="<f8").reshape(nv, 3)
                            return surface_metrics(cv, f, v, sd, scale)
                        if not args.no_auto:
                            pre, its = lab("auto")
                            m = lab_metrics(pre, len(its))
                            m["dvol"], m["iterations"] = its[-1]["dvol"], len(its)
                            m["R"] = [x["ratio"] for x in its]
                            ok, mg = verdict(m, b)
                            m["pass"], m["margin"] = ok, mg
                            row["auto"] = m
                            totals[cfg].setdefault(seed, [0, 0])
                            totals[cfg][seed][0] += ok
                            totals[cfg][seed][1] += 1
                            line += (f" auto it {m['iterations']:3d}"
                                     f" rms {mg['rms']:+.2%} nerr {mg['nerr']:+.2%}"
                                     f" max {mg['max']:.2f}x dvol {m['dvol']:+.0e}"
                                     f" {'PASS' if ok else 'FAIL'}")
                        if args.curve:
                            pre, its = lab(str(args.curve))
                            curve = []
                            for k in range(args.every, args.curve + 1, args.every):
                                m = lab_metrics(pre, k)
                                ok, mg = verdict(m, b)
                                curve.append({**m, "k": k, "pass": ok, "margin": mg,
                                              "R": its[k - 1]["ratio"]})
                            row["curve"] = curve
                            win = [c["k"] for c in curve if c["pass"]]
                            br = min(curve, key=lambda c: c["rms"])
                            bn = min(curve, key=lambda c: c["nerr"])
                            line += (f" | pass at {win} best rms {br['margin']['rms']:+.2%}"
                                     f"@{br['k']} best nerr {bn['margin']['nerr']:+.2%}@{bn['k']}")
                        print(line, flush=True)
                        results.append(row)
                        continue
                    if not args.no_auto:
                        rep = smooth(noisy, out, cfg + " --iterations auto")
                        m = measure(out)
                        m["dvol"] = report_volume(rep)
                        m["iterations"] = report_iterations(rep)
                        st = rep.get("auto_stop") or {}
                        o, e = st.get("removed", []), st.get("expected", [])
                        m["R"] = [(o[k] - o[k - 1]) / (e[k] - e[k - 1]) for k in range(1, len(o))]
                        m["stopped_by"] = st.get("stopped_by")
                        ok, mg = verdict(m, b)
                        m["pass"], m["margin"] = ok, mg
                        row["auto"] = m
                        totals[cfg].setdefault(seed, [0, 0])
                        totals[cfg][seed][0] += ok
                        totals[cfg][seed][1] += 1
                        line += (f" auto it {m['iterations']:3d} ({m['stopped_by']})"
                                 f" rms {mg['rms']:+.2%} nerr {mg['nerr']:+.2%}"
                                 f" max {mg['max']:.2f}x dvol {m['dvol']:+.0e}"
                                 f" {'PASS' if ok else 'FAIL'}")
                    if args.curve:
                        cur = noisy
                        curve = []
                        for k in range(args.every, args.curve + 1, args.every):
                            nxt = os.path.join(args.workdir, f"{stem}-curve{k % 2}.ply")
                            smooth(cur, nxt, cfg + f" --iterations {args.every}")
                            m = measure(nxt)
                            ok, mg = verdict(m, b)
                            curve.append({**m, "k": k, "pass": ok, "margin": mg})
                            cur = nxt
                        row["curve"] = curve
                        win = [c["k"] for c in curve if c["pass"]]
                        br = min(curve, key=lambda c: c["rms"])
                        bn = min(curve, key=lambda c: c["nerr"])
                        line += (f" | pass at {win} best rms {br['margin']['rms']:+.2%}"
                                 f"@{br['k']} best nerr {bn['margin']['nerr']:+.2%}@{bn['k']}")
                    print(line, flush=True)
                    results.append(row)
    if not args.no_auto:
        print()
        for cfg in args.config:
            s = "  ".join(f"seed {k}: {v[0]}/{v[1]}" for k, v in sorted(totals[cfg].items()))
            print(f"[{cfg}] {s}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main()
