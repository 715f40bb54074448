#!/usr/bin/env python3
"""The disk traffic of `vcsmooth smooth --report` runs, per phase (the report's `disk`, from
/proc/self/io), and issue #33's target: past the page cache, the sweep moves at most 2x the
scratch it holds per iteration (disk bytes read + written in `smoothing` / iterations, against
`memory.scratch_peak_bytes`).

    tools/disk_traffic.py REPORT.json...

A run that fits the page cache reads nothing back; its written bytes are pages dirtied, counted
whether or not the kernel has written them back yet.
"""
import json
import sys

FIGURES = ("disk_read_bytes", "disk_written_bytes", "disk_write_cancelled_bytes",
           "syscall_read_bytes", "syscall_written_bytes")
HEADS = ("disk read", "disk written", "cancelled", "read(2)", "write(2)")


def mib(n):
    return f"{n / 2**20:,.1f}"


def show(path):
    r = json.load(open(path))
    disk = r.get("disk")
    if disk is None:
        sys.exit(f"{path}: no disk figures (no /proc/self/io, or a cluster run)")
    print(f"{path}: {r['memory']['storage']}, {r['iterations_run']} iterations, MiB")
    print(f"{'phase':10s}" + "".join(f"{h:>14s}" for h in HEADS))
    for phase, row in disk.items():
        print(f"{phase:10s}" + "".join(f"{mib(row[f]):>14s}" for f in FIGURES))
    n = r["iterations_run"]
    scratch = r["memory"]["scratch_peak_bytes"]
    if n == 0 or scratch == 0:
        return
    s = disk["smoothing"]
    moved = (s["disk_read_bytes"] + s["disk_written_bytes"]) / n
    print(f"sweep per iteration: {mib(s['disk_read_bytes'] / n)} read + "
          f"{mib(s['disk_written_bytes'] / n)} written = {mib(moved)} MiB; scratch at most "
          f"{mib(scratch)} MiB: {moved / scratch:.2f}x (target: at most 2x)")


for p in sys.argv[1:] or sys.exit(__doc__):
    show(p)
