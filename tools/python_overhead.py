#!/usr/bin/env python3
"""The overhead of `vcsmooth.smooth` (arrays in memory) against the CLI's `vcsmooth smooth` (file
to file), for the Python binding's figures. Interleaved rounds; wall and CPU seconds (CPU of all
threads; for the CLI, the child's), medians.

    vcsmooth generate torus /dev/shm/t6.ply --subdivisions 6 --noise 0.3 --seed 7   # 1,048,576 triangles
    python tools/python_overhead.py target/release/vcsmooth /dev/shm/t6.ply /dev/shm/out.ply 7

Needs the Python package installed (`pip install .`).
"""
import os, resource, statistics, subprocess, sys, time
import vcsmooth

cli, mesh, out = sys.argv[1], sys.argv[2], sys.argv[3]
rounds = int(sys.argv[4]) if len(sys.argv) > 4 else 7
v, f = vcsmooth.read_mesh(mesh)

def child_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime

def own_cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime

rows = {
    "CLI: vcsmooth smooth IN OUT": (lambda: subprocess.run([cli, "smooth", mesh, out], check=True, capture_output=True), child_cpu),
    "CLI: ... --report r.json": (lambda: subprocess.run([cli, "smooth", mesh, out, "--report", out + ".json"], check=True, capture_output=True), child_cpu),
    "smooth_file(IN, OUT)": (lambda: vcsmooth.smooth_file(mesh, out), own_cpu),
    "smooth(v, f)  [stats last]": (lambda: vcsmooth.smooth(v, f), own_cpu),
    "smooth(v, f, stats='every')": (lambda: vcsmooth.smooth(v, f, stats="every"), own_cpu),
    "smooth(v, f, iterations=0)": (lambda: vcsmooth.smooth(v, f, iterations=0), own_cpu),
}
wall = {k: [] for k in rows}; cpu = {k: [] for k in rows}; loads = []
for _ in range(rounds):
    loads.append(os.getloadavg()[0])
    for name, (fn, clock) in rows.items():
        c, t = clock(), time.perf_counter()
        fn()
        wall[name].append(time.perf_counter() - t); cpu[name].append(clock() - c)
print(f"{len(v)} vertices, {len(f)} triangles; {vcsmooth.DEFAULT_METHOD} (the default), 10 iterations, all cores; {rounds} interleaved rounds; 1-min load {min(loads):.1f}-{max(loads):.1f}")
for name in rows:
    print(f"{name:30s} wall median {statistics.median(wall[name]):6.3f} s (min {min(wall[name]):.3f})   CPU median {statistics.median(cpu[name]):6.3f} s (min {min(cpu[name]):.3f})")
