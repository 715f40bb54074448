#!/usr/bin/env python3
"""Throw hostile use at the vcsmooth binary and count what goes wrong.

Every case runs the binary in a fresh folder and is judged by the project's contract, whatever
the case is about:

  * it ends within the time limit, and not by a panic (exit 101, "panicked", a backtrace) or a
    signal it did not ask for;
  * a failure is exactly one line on stderr, `vcsmooth: error: ...`, with a non-zero exit;
  * no file other than the named output changed, and no temporary file (`.NAME.tmp-*`) is left;
  * a mesh it writes reads back with finite coordinates inside the input's bounding box grown by
    its own diagonal; numbers it prints are never NaN, inf or -0.

and by the case's own expectation (must fail, must succeed, or a check of the result: the volume
kept, the radius range of a sphere, a crack counted as boundary).

    python3 tools/hostile_probe.py [--bin target/release/vcsmooth] [--only CLASS] [--list]

prints one line per case that went wrong and, last, `N cases, M went wrong` (exit 1 if M > 0).
The classes: paths, values, readers, geometry, memory, signals, batch, output,
gltf (`.gltf` with external and `data:` buffers, `.glb`: what a glTF input may hold, where a
glTF output's buffers go), and hostile_scripts (the Slurm script against hostile file names, side
files through links and devices, the checkpoint directory, option combinations), hostile_gltf
(glTF geometry shared between primitives and meshes: one surface, smoothed once, kept shared),
multires and properties (levels too coarse to carry the shape; subdivision keeps what it can),
hostile_ratios (ratios against zero volume), hostile_pins (pin files from devices, pipes, binary
data, endless lines), hostile_checkpoints (a checkpoint is its input's by content),
hostile_budgets (the budget holds unreferenced vertices and tiny patches) and hostile_bounds
(`--max-deviation` holds in the file as written).
Only the Python standard library is needed.
"""

from __future__ import annotations

import argparse
import base64
import copy
import gzip
import hashlib
import json
import math
import os
import random
import re
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import urllib.parse

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DATA = os.path.join(REPO, "tests", "data")

BIN = os.path.join(REPO, "target", "release", "vcsmooth")
TIMEOUT = 60.0


# ---------------------------------------------------------------------------------------------
# Meshes


def octahedron():
    v = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    f = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    return v, f


def tetrahedron():
    v = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
    f = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    return v, f


def bipyramid(n):
    """A double cone: two hubs of degree n around an equator of n vertices."""
    v = [(math.cos(2 * math.pi * i / n), math.sin(2 * math.pi * i / n), 0.0) for i in range(n)]
    v += [(0.0, 0.0, 1.0), (0.0, 0.0, -1.0)]
    top, bottom = n, n + 1
    f = []
    for i in range(n):
        j = (i + 1) % n
        f.append((i, j, top))
        f.append((j, i, bottom))
    return v, f


def ply_ascii(v, f):
    lines = ["ply", "format ascii 1.0", f"element vertex {len(v)}", "property float x",
             "property float y", "property float z", f"element face {len(f)}",
             "property list uchar int vertex_indices", "end_header"]
    lines += [" ".join(repr(float(c)) for c in p) for p in v]
    lines += [f"{len(t)} " + " ".join(str(i) for i in t) for t in f]
    return ("\n".join(lines) + "\n").encode()


def ply_binary(v, f, coord="float", fmt="f"):
    head = ("ply\nformat binary_little_endian 1.0\n"
            f"element vertex {len(v)}\nproperty {coord} x\nproperty {coord} y\nproperty {coord} z\n"
            f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    body = b"".join(struct.pack("<3" + fmt, *p) for p in v)
    body += b"".join(struct.pack("<B3i", 3, *t) for t in f)
    return head + body


def obj(v, f):
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in v]
    lines += ["f " + " ".join(str(i + 1) for i in t) for t in f]
    return ("\n".join(lines) + "\n").encode()


def off(v, f):
    lines = ["OFF", f"{len(v)} {len(f)} 0"]
    lines += [f"{x!r} {y!r} {z!r}" for x, y, z in v]
    lines += [f"{len(t)} " + " ".join(str(i) for i in t) for t in f]
    return ("\n".join(lines) + "\n").encode()


def stl_binary(v, f, header=b"binary"):
    out = header.ljust(80, b" ") + struct.pack("<I", len(f))
    for t in f:
        out += struct.pack("<3f", 0, 0, 0)
        for i in t:
            out += struct.pack("<3f", *v[i])
        out += b"\0\0"
    return out


def stl_ascii(v, f, upper=False):
    lines = ["solid probe"]
    for t in f:
        lines += ["facet normal 0 0 0", "outer loop"]
        lines += ["vertex {} {} {}".format(*v[i]) for i in t]
        lines += ["endloop", "endfacet"]
    lines.append("endsolid probe")
    text = "\n".join(lines) + "\n"
    return (text.upper() if upper else text).encode()


def noisy_sphere_flipped(every):
    """A bumpy sphere (an icosphere, subdivided, radius noise) with every `every`-th face flipped."""
    v, f = icosphere(3)
    rng = Lcg(7)
    v = [tuple(c * (1 + 0.1 * (rng.next() - 0.5)) for c in p) for p in v]
    f = [tuple(reversed(t)) if k % every == 0 else t for k, t in enumerate(f)]
    return v, f


class Lcg:
    def __init__(self, seed):
        self.s = seed

    def next(self):
        self.s = (self.s * 6364136223846793005 + 1442695040888963407) % (1 << 64)
        return (self.s >> 11) / float(1 << 53)


def icosphere(k):
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    v = [norm(p) for p in v]
    for _ in range(k):
        mid = {}
        nf = []

        def m(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                pa, pb = v[a], v[b]
                v.append(norm(tuple((x + y) / 2 for x, y in zip(pa, pb))))
                mid[key] = len(v) - 1
            return mid[key]

        for a, b, c in f:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = nf
    return v, f


def norm(p):
    n = math.sqrt(sum(c * c for c in p))
    return tuple(c / n for c in p)


# ---------------------------------------------------------------------------------------------
# Running and judging


class Case:
    def __init__(self, cls, name, setup, argv, expect="either", check=None, signal_after=None,
                 limit_as_kb=None, timeout=None, output=None, replaces=(), new_files=None):
        self.cls = cls
        self.name = name
        self.setup = setup  # fn(dir) -> None: writes the files
        self.argv = argv  # list; "{d}" is the case's folder
        self.expect = expect  # "ok", "error" or "either"
        self.check = check  # fn(dir, proc) -> problem or None
        self.signal_after = signal_after  # (signal, seconds)
        self.limit_as_kb = limit_as_kb
        self.timeout = timeout or TIMEOUT
        self.output = output  # the named output, relative to the folder
        # Files besides the output the command may replace (a .gltf output's own earlier buffer),
        # and, when not None, the only files besides the output that may appear (its new buffers).
        self.replaces = replaces
        self.new_files = new_files


def snapshot(d):
    files = {}
    for root, _, names in os.walk(d):
        for n in names:
            p = os.path.join(root, n)
            if os.path.islink(p):
                files[p] = "link:" + os.readlink(p)
                continue
            if not os.path.isfile(p):
                files[p] = "special"  # a FIFO or device: opening it could block
                continue
            try:
                with open(p, "rb") as fh:
                    files[p] = hashlib.sha256(fh.read()).hexdigest()
            except OSError as e:
                files[p] = f"unreadable:{e.errno}"
    return files


NUMBER_BAD = re.compile(r"(?<![\w.])(-?nan|-?NaN|-?inf(inity)?|-0(\.0+)?(?![\d.eE]))(?![\w.])",
                        re.IGNORECASE)


def run_case(case, base):
    d = tempfile.mkdtemp(prefix="case-", dir=base)
    try:
        case.setup(d)
        before = snapshot(d)
        argv = [BIN] + [a.replace("{d}", d) for a in case.argv]
        kb = case.limit_as_kb

        def preexec():
            # A shell's background job ignores SIGINT, and the binary keeps an ignored signal
            # ignored (as under nohup): give the child the default, as a terminal would.
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            if kb:
                import resource
                resource.setrlimit(resource.RLIMIT_AS, (kb * 1024, kb * 1024))
        env = dict(os.environ, RUST_BACKTRACE="1")
        start = time.monotonic()
        proc = subprocess.Popen(argv, cwd=d, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                preexec_fn=preexec, env=env)
        if case.signal_after:
            sig, after = case.signal_after
            time.sleep(after)
            if proc.poll() is None:
                proc.send_signal(sig)
        try:
            out, err = proc.communicate(timeout=case.timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            return f"did not finish in {case.timeout:.0f} s"
        seconds = time.monotonic() - start
        out = out.decode(errors="replace")
        err = err.decode(errors="replace")
        return judge(case, d, before, proc.returncode, out, err, seconds)
    finally:
        shutil.rmtree(d, ignore_errors=True)


def judge(case, d, before, code, out, err, seconds):
    lines = [l for l in err.splitlines() if l.strip()]
    if "panicked" in err or "stack backtrace" in err or code == 101:
        return "panic: " + (lines[0] if lines else "")
    if code < 0 and not case.signal_after:
        return f"killed by signal {-code}"
    if code != 0:
        if len(lines) != 1 or not lines[0].startswith("vcsmooth: error: "):
            return f"exit {code} without the one-line error: {err.strip()[:200]!r}"
    if case.expect == "error" and code == 0:
        return "succeeded, should have been refused"
    if case.expect == "ok" and code != 0:
        return f"refused: {lines[0] if lines else ''}"
    after = snapshot(d)
    output = os.path.join(d, case.output) if case.output else None
    replaced = {os.path.join(d, r) for r in case.replaces}
    for p, h in before.items():
        # The output is the command's to replace; a stale temporary of it is its to remove.
        if p == output or p in replaced or re.search(r"\.tmp-", os.path.basename(p)):
            continue
        if after.get(p) != h:
            return f"{os.path.relpath(p, d)} was changed or removed"
    if case.new_files is not None:
        allowed = {os.path.join(d, n) for n in case.new_files} | {output}
        new = sorted(os.path.relpath(p, d) for p in after if p not in before and p not in allowed
                     and not re.search(r"\.tmp-", os.path.basename(p)))
        if new:
            return "new files besides the output: " + ", ".join(new)
    for p in after:
        if re.search(r"\.tmp-", os.path.basename(p)):
            return f"temporary file left: {os.path.relpath(p, d)}"
    if NUMBER_BAD.search(out):
        m = NUMBER_BAD.search(out)
        return f"printed {m.group(0)!r}"
    if code == 0 and output and os.path.isfile(output) and output.endswith((".ply", ".obj", ".off", ".stl")):
        problem = check_output(d, output)
        if problem:
            return problem
    if case.check:
        return case.check(d, code, out, err)
    return None


def info(path):
    p = subprocess.run([BIN, "info", "--json", path], capture_output=True, timeout=TIMEOUT)
    if p.returncode != 0:
        return None
    return json.loads(p.stdout)


def find(obj, key):
    """The first value under `key` anywhere in a JSON document."""
    if isinstance(obj, dict):
        if key in obj:
            return obj[key]
        for v in obj.values():
            r = find(v, key)
            if r is not None:
                return r
    if isinstance(obj, list):
        for v in obj:
            r = find(v, key)
            if r is not None:
                return r
    return None


def check_output(d, output):
    j = info(output)
    if j is None:
        return "the output does not read back"
    nums = list(flatten([find(j, "bbox_min"), find(j, "bbox_max")]))
    if any(not isinstance(x, (int, float)) or not math.isfinite(x) for x in nums):
        return "non-finite coordinates in the output"
    return None


def flatten(x):
    if isinstance(x, dict):
        for v in x.values():
            yield from flatten(v)
    elif isinstance(x, list):
        for v in x:
            yield from flatten(v)
    else:
        yield x


def write(name, data):
    def setup(d):
        p = os.path.join(d, name)
        os.makedirs(os.path.dirname(p), exist_ok=True)
        with open(p, "wb") as fh:
            fh.write(data)
    return setup


def both(*setups):
    def setup(d):
        for s in setups:
            s(d)
    return setup


# ---------------------------------------------------------------------------------------------
# The cases

OCTA_PLY = ply_binary(*octahedron())
SPHERE = icosphere(3)
SPHERE_PLY = ply_binary(*SPHERE)


def medium(d, name="in.ply", k=7):
    subprocess.run([BIN, "generate", "sphere", os.path.join(d, name), "--subdivisions", str(k),
                    "--noise", "0.3"], check=True, capture_output=True)


def cases_paths():
    out = []
    mesh = write("scan.ply", SPHERE_PLY)
    for flag in ["--report", "--plot"]:
        for target, extra in [("scan.ply", None), ("out.ply", None), ("./sub/../scan.ply", "sub"),
                              ("link.ply", "link"), ("hard.ply", "hard")]:
            def setup(d, extra=extra):
                mesh(d)
                if extra == "sub":
                    os.mkdir(os.path.join(d, "sub"))
                if extra == "link":
                    os.symlink("scan.ply", os.path.join(d, "link.ply"))
                if extra == "hard":
                    os.link(os.path.join(d, "scan.ply"), os.path.join(d, "hard.ply"))
            out.append(Case("paths", f"smooth {flag} {target}", setup,
                            ["smooth", "scan.ply", "out.ply", "--iterations", "2", flag, target],
                            expect="error", output="out.ply"))
    out.append(Case("paths", "smooth --report = --plot", mesh,
                    ["smooth", "scan.ply", "out.ply", "--report", "x.json", "--plot", "x.json"],
                    expect="error", output="out.ply"))
    out.append(Case("paths", "smooth out = in", mesh, ["smooth", "scan.ply", "scan.ply"],
                    expect="either", output="scan.ply"))
    out.append(Case("paths", "curves --plot = input", mesh,
                    ["curves", "scan.ply", "--plot", "scan.ply", "--iterations", "2"], expect="error"))
    for target in ["a.ply", "b/scan.ply"]:
        def setup(d):
            os.makedirs(os.path.join(d, "in"))
            os.makedirs(os.path.join(d, "out"))
            write("in/a.ply", SPHERE_PLY)(d)
        out.append(Case("paths", f"batch --json into the inputs ({target})", setup,
                        ["batch", "in", "out", "--iterations", "1", "--json", "in/a.ply"],
                        expect="error"))
    # Output locations that cannot be written: found before any work.
    for what in ["readonly", "missing", "isdir"]:
        def setup(d, what=what):
            mesh(d)
            if what == "readonly":
                os.mkdir(os.path.join(d, "ro"))
                os.chmod(os.path.join(d, "ro"), 0o500)
            if what == "isdir":
                os.mkdir(os.path.join(d, "x.ply"))
        target = {"readonly": "ro/out.ply", "missing": "nope/out.ply", "isdir": "x.ply"}[what]
        for cmd in [["smooth", "scan.ply", target], ["subdivide", "scan.ply", target, "--max-edge", "0.1"],
                    ["generate", "sphere", target], ["refine", "scan.ply", target, "--max-edge", "0.2",
                                                         "--rounds", "1"]]:
            if os.geteuid() == 0 and what == "readonly":
                continue  # root writes anywhere
            out.append(Case("paths", f"{cmd[0]} into {what}", setup, cmd, expect="error"))
    return out


FLOAT_FLAGS = {"--lambda", "--mu", "--cell-factor", "--noise", "--max-edge"}


def cases_values():
    out = []
    mesh = write("scan.ply", SPHERE_PLY)
    bad = ["-1", "-inf", "inf", "nan", "NaN", "1e400", "-0.5", "abc", "", "18446744073709551616"]
    flags = {
        "smooth": ["--lambda", "--mu", "--iterations", "--threads", "--patch-size", "--memory-budget",
                   "--levels", "--coarse-iterations", "--cell-factor", "--checkpoint-every"],
        "generate": ["--subdivisions", "--noise", "--seed", "--subdivide"],
        "subdivide": ["--max-edge"],
    }
    for cmd, fl in flags.items():
        for flag in fl:
            for value in bad:
                if cmd == "smooth":
                    argv = ["smooth", "scan.ply", "out.ply", "--iterations", "1", flag, value]
                    if flag in ("--levels", "--coarse-iterations", "--cell-factor"):
                        argv.append("--multires")
                    if flag == "--checkpoint-every":
                        argv += ["--checkpoint", "ck"]
                elif cmd == "generate":
                    argv = ["generate", "sphere", "out.ply", flag, value]
                    if flag == "--subdivide":
                        argv = ["generate", "mesh", "out.ply", "--from", "scan.ply", flag, value]
                else:
                    argv = ["subdivide", "scan.ply", "out.ply", flag, value]
                # --mu is negative by design; a huge finite value is a legal real number.
                legal = (flag == "--mu" and value in ("-1", "-0.5")) or (
                    flag in FLOAT_FLAGS and value == "18446744073709551616")
                expect = "either" if legal else "error"
                out.append(Case("values", f"{cmd} {flag} {value!r}", mesh, argv, expect=expect,
                                output="out.ply", timeout=30))
    for n in ["18446744073709551615", "300000000", "4294967296"]:
        for extra in [[], ["--stats", "every"], ["--multires", "--coarse-iterations", n]]:
            out.append(Case("values", f"smooth --iterations {n} {' '.join(extra)}", mesh,
                            ["smooth", "scan.ply", "out.ply", "--iterations", n] + extra,
                            expect="either", output="out.ply", timeout=15,
                            signal_after=(signal.SIGTERM, 5)))
        out.append(Case("values", f"curves --iterations {n}", mesh,
                        ["curves", "scan.ply", "--plot", "c.svg", "--iterations", n], timeout=15,
                        signal_after=(signal.SIGTERM, 5)))
    for t in ["1000000000", "100000", "0"]:
        out.append(Case("values", f"smooth --threads {t}", mesh,
                        ["smooth", "scan.ply", "out.ply", "--threads", t], timeout=5,
                        output="out.ply"))
    return out


def cases_readers():
    out = []
    v, f = octahedron()
    texts = {
        "prose.obj": b"Dear reader,\nthis is not a mesh at all.\nRegards\n",
        "gzip.obj": gzip.compress(obj(v, f)),
        "gzip.ply": gzip.compress(ply_ascii(v, f)),
        "utf16.obj": obj(v, f).decode().encode("utf-16"),
        "utf16le.obj": obj(v, f).decode().encode("utf-16-le"),
        "empty.obj": b"",
        "empty.ply": b"",
        "empty.off": b"",
        "empty.stl": b"",
        "zeros.obj": b"\0" * 4096,
        "zeros.ply": b"\0" * 4096,
        "zeros.stl": b"\0" * 4096,
        "html.obj": b"<html><body>404 Not Found</body></html>\n",
        "json.off": b'{"vertices": [], "faces": []}\n',
        "comments.obj": b"# only a comment\n# and another\n",
        "nofaces.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\n",
        "zipped.stl": b"PK\x03\x04" + b"\0" * 200,
    }
    for name, data in texts.items():
        out.append(Case("readers", f"refuse {name}", write(name, data),
                        ["smooth", name, "out.ply"], expect="error", output="out.ply"))
        # A point cloud is described by info, but there is nothing to smooth.
        out.append(Case("readers", f"info {name}", write(name, data), ["info", name],
                        expect="either" if name == "nofaces.obj" else "error"))
    # A UTF-8 BOM keeps every vertex.
    for name, data in [("bom.obj", b"\xef\xbb\xbf" + obj(v, f)), ("bom.off", b"\xef\xbb\xbf" + off(v, f)),
                       ("bom.ply", b"\xef\xbb\xbf" + ply_ascii(v, f)),
                       ("bom.stl", b"\xef\xbb\xbf" + stl_ascii(v, f))]:
        out.append(Case("readers", f"BOM {name}", write(name, data), ["info", "--json", name],
                        expect="either", check=expect_counts(6, 8)))
    # Upper-case ASCII STL, and STL corners -0 against 0: one closed surface.
    out.append(Case("readers", "upper-case ASCII STL", write("up.stl", stl_ascii(v, f, upper=True)),
                    ["info", "--json", "up.stl"], expect="ok", check=expect_counts(6, 8)))
    vz = [tuple(-0.0 if c == 0 else c for c in p) for p in v]
    data = b"".join([])
    tris = []
    for k, t in enumerate(f):
        src = vz if k % 2 else v
        tris.append([src[i] for i in t])
    stl = b"binary".ljust(80, b" ") + struct.pack("<I", len(tris))
    for tri in tris:
        stl += struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *p) for p in tri) + b"\0\0"
    out.append(Case("readers", "STL -0 and 0 merge", write("z.stl", stl), ["info", "--json", "z.stl"],
                    expect="ok", check=expect_closed()))
    out.append(Case("readers", "/dev/zero as input", lambda d: None,
                    ["smooth", "/dev/zero", "out.ply"], expect="error", timeout=10))
    out.append(Case("readers", "/dev/zero as .obj", lambda d: os.symlink("/dev/zero", os.path.join(d, "z.obj")),
                    ["info", "z.obj"], expect="error", timeout=10))
    out.append(Case("readers", "/dev/urandom named .stl", lambda d: os.symlink("/dev/urandom", os.path.join(d, "r.stl")),
                    ["info", "r.stl"], expect="error", timeout=10))
    out.append(Case("readers", "/dev/null as input", lambda d: None, ["info", "/dev/null"],
                    expect="error", timeout=10))
    out.append(Case("readers", "a directory as input", lambda d: os.mkdir(os.path.join(d, "dir.ply")),
                    ["info", "dir.ply"], expect="error"))
    out.append(Case("readers", "an endless header line",
                    write("long.ply", b"ply\nformat ascii 1.0\ncomment " + b"x" * (50 << 20)),
                    ["info", "long.ply"], expect="error", timeout=20))
    # Truncations and byte flips of every format.
    sources = {"t.ply": SPHERE_PLY, "a.ply": ply_ascii(*SPHERE), "t.obj": obj(*SPHERE),
               "t.off": off(*SPHERE), "t.stl": stl_binary(*SPHERE), "a.stl": stl_ascii(*SPHERE)}
    rng = Lcg(17)
    for name, data in sources.items():
        for frac in [0.0005, 0.01, 0.3, 0.77, 0.999]:
            cut = max(1, int(len(data) * frac))
            out.append(Case("readers", f"{name} cut at {cut}", write(name, data[:cut]),
                            ["smooth", name, "out.ply", "--iterations", "2"], output="out.ply"))
        for k in range(8):
            b = bytearray(data)
            for _ in range(4):
                b[int(rng.next() * len(b))] = int(rng.next() * 256)
            out.append(Case("readers", f"{name} flipped bytes #{k}", write(name, bytes(b)),
                            ["smooth", name, "out.ply", "--iterations", "2"], output="out.ply"))
    return out


def expect_counts(nv, nf):
    def check(d, code, out, err):
        if code != 0:
            return f"refused: {err.strip()}"
        j = json.loads(out)
        got_v, got_f = find(j, "vertices"), find(j, "triangles")
        if got_v != nv or got_f != nf:
            return f"read {got_v} vertices and {got_f} faces, expected {nv} and {nf}"
        return None
    return check


def expect_closed():
    def check(d, code, out, err):
        j = json.loads(out)
        b = find(j, "boundary_edges")
        if b not in (0, None):
            return f"{b} boundary edges: a crack"
        return None
    return check


def volume_of(path):
    j = info(path)
    return None if j is None else find(j, "volume")


def radius_range(path):
    # Read back through an OFF conversion: simple to parse.
    offp = path + ".probe.off"
    subprocess.run([BIN, "smooth", path, offp, "--iterations", "0"], check=True, capture_output=True)
    with open(offp) as fh:
        lines = [l for l in fh.read().split("\n") if l and not l.startswith("#")]
    os.remove(offp)
    nv = int(lines[1].split()[0])
    r = [math.sqrt(sum(float(c) ** 2 for c in lines[2 + i].split()[:3])) for i in range(nv)]
    return min(r), max(r)


def cases_geometry():
    out = []
    tet = ply_binary(*tetrahedron())
    for method in ["vcs", "vcs-triangle", "lem", "taubin"]:
        out.append(Case("geometry", f"tetrahedron {method}", write("t.ply", tet),
                        ["smooth", "t.ply", "out.ply", "--method", method, "--iterations", "5"],
                        output="out.ply", check=bounded("t.ply", "out.ply")))
    # Debris: a tiny closed tetrahedron beside a sphere.
    sv, sf = SPHERE
    tv, tf = tetrahedron()
    dv = sv + [(2 + 1e-3 * x, 1e-3 * y, 1e-3 * z) for x, y, z in tv]
    df = sf + [tuple(i + len(sv) for i in t) for t in tf]
    for method in ["vcs", "vcs-triangle"]:
        out.append(Case("geometry", f"debris {method}", write("d.ply", ply_binary(dv, df)),
                        ["smooth", "d.ply", "out.ply", "--method", method, "--iterations", "5"],
                        output="out.ply", check=bounded("d.ply", "out.ply")))
    for every in [2, 3, 1280]:
        data = ply_binary(*noisy_sphere_flipped(every))
        for method in ["vcs", "vcs-triangle"]:
            out.append(Case("geometry", f"flipped every {every} {method}", write("s.ply", data),
                            ["smooth", "s.ply", "out.ply", "--method", method, "--iterations", "10"],
                            output="out.ply", check=sphere_kept("s.ply", "out.ply")))
        out.append(Case("geometry", f"flipped every {every} info", write("s.ply", data),
                        ["info", "--json", "s.ply"], check=orientation_counted()))
    for n in [40000, 200000]:
        data = ply_binary(*bipyramid(n))
        out.append(Case("geometry", f"hub of degree {n} vcs", write("b.ply", data),
                        ["smooth", "b.ply", "out.ply", "--iterations", "1"], output="out.ply",
                        timeout=30))
        out.append(Case("geometry", f"hub of degree {n} info", write("b.ply", data),
                        ["info", "b.ply"], timeout=30))
    # Coordinates as uchar/short: the report measures what the file holds.
    for coord, fmt in [("uchar", "B"), ("short", "h")]:
        v, f = icosphere(3)
        v = [tuple(round(50 + 40 * c) for c in p) for p in v]
        data = ply_binary(v, f, coord=coord, fmt=fmt)
        out.append(Case("geometry", f"{coord} coordinates: report = file", write("q.ply", data),
                        ["smooth", "q.ply", "out.ply", "--report", "r.json"], output="out.ply",
                        check=report_matches_file("q.ply", "out.ply", "r.json")))
    return out


def bounded(inp, outp):
    def check(d, code, out, err):
        if code != 0:
            return None
        a, b = info(os.path.join(d, inp)), info(os.path.join(d, outp))
        if a is None or b is None:
            return "info failed"
        la, lb = diag(a), diag(b)
        if la is None or lb is None:
            return None
        if not math.isfinite(lb) or lb > 2 * la:
            return f"bounding box diagonal {la:.3g} -> {lb:.3g}"
        return None
    return check


def diag(j):
    d = find(j, "bbox_diagonal")
    return d if isinstance(d, (int, float)) else None


def sphere_kept(inp, outp):
    def check(d, code, out, err):
        if code != 0:
            return None
        a_lo, a_hi = radius_range(os.path.join(d, inp))
        b_lo, b_hi = radius_range(os.path.join(d, outp))
        if b_lo < a_lo - 1e-9 or b_hi > a_hi + 1e-9:
            return f"radius range {a_lo:.3f}-{a_hi:.3f} widened to {b_lo:.3f}-{b_hi:.3f}"
        va, vb = abs(volume_of(os.path.join(d, inp))), abs(volume_of(os.path.join(d, outp)))
        if abs(vb - va) > 1e-6 * va:
            return f"volume {va:.9g} -> {vb:.9g}"
        return None
    return check


def orientation_counted():
    def check(d, code, out, err):
        if code != 0:
            return f"refused: {err.strip()}"
        if not re.search(r'"[a-z_]*orient[a-z_]*"\s*:\s*[1-9]', out):
            return "inconsistent orientation not reported by info"
        return None
    return check


def report_matches_file(inp, outp, rep):
    def check(d, code, out, err):
        with open(os.path.join(d, rep)) as fh:
            r = json.load(fh)
        reported = find(r["output"], "volume")
        actual = volume_of(os.path.join(d, outp))
        if reported is None or actual is None:
            return "no volume in the report or the output"
        if abs(actual - reported) > 1e-9 * abs(actual):
            return f"report says volume {reported!r}, the file holds {actual!r}"
        return None
    return check


def cases_signals():
    out = []
    for sig in [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]:
        def setup(d):
            medium(d)
            with open(os.path.join(d, "out.ply"), "wb") as fh:
                fh.write(b"previous output")
        out.append(Case("signals", f"{sig.name} during smooth", setup,
                        ["smooth", "in.ply", "out.ply", "--iterations", "100000"],
                        signal_after=(sig, 2.0), output=None, timeout=20,
                        check=lambda d, code, o, e: None if code != 0 else "exit 0 after a signal"))
        out.append(Case("signals", f"{sig.name} during smooth, out-of-core", setup,
                        ["smooth", "in.ply", "out.ply", "--iterations", "100000", "--memory-budget", "8M"],
                        signal_after=(sig, 2.0), output=None, timeout=20,
                        check=lambda d, code, o, e: None if code != 0 else "exit 0 after a signal"))

    def stale(d):
        write("in.ply", OCTA_PLY)(d)
        with open(os.path.join(d, ".out.ply.tmp-999999999-0"), "wb") as fh:
            fh.write(b"x" * 1000)
    out.append(Case("signals", "a stale temporary of a dead run is removed", stale,
                    ["smooth", "in.ply", "out.ply"], expect="ok", output="out.ply",
                    check=lambda d, c, o, e: None))
    return out


def cases_batch():
    out = []

    def folder(d):
        os.makedirs(os.path.join(d, "in"))
        write("in/a.ply", SPHERE_PLY)(d)
        write("in/b.ply", OCTA_PLY)(d)

    def rerun_after(change, expect_rerun=True):
        def check(d, code, o, e):
            first = subprocess.run([BIN, "batch", "in", "out", "--iterations", "2"], cwd=d,
                                   capture_output=True)
            if first.returncode != 0:
                return "first batch run failed: " + first.stderr.decode()[:200]
            change(d)
            before = {n: os.path.getmtime(os.path.join(d, "out", n)) for n in os.listdir(os.path.join(d, "out"))
                      if n.endswith(".ply")}
            time.sleep(0.02)
            second = subprocess.run([BIN, "batch", "in", "out", "--iterations", "3" if change is change_opts else "2"],
                                    cwd=d, capture_output=True)
            out_a = os.path.join(d, "out", "a.ply")
            rerun = os.path.exists(out_a) and os.path.getmtime(out_a) != before.get("a.ply")
            if expect_rerun and not rerun:
                return "not rerun: " + second.stderr.decode()[:200]
            return None
        return check

    def change_input(d):
        # Another valid mesh of the same size: only the content and the time differ.
        v, f = SPHERE
        with open(os.path.join(d, "in", "a.ply"), "wb") as fh:
            fh.write(ply_binary([tuple(1.01 * c for c in p) for p in v], f))

    def delete_output(d):
        os.remove(os.path.join(d, "out", "a.ply"))

    def change_opts(d):
        pass

    def garbage_marker(d):
        for n in os.listdir(os.path.join(d, "out")):
            if "a" in n and n.endswith(".done"):
                open(os.path.join(d, "out", n), "w").write("garbage")
            for sub in ["done", ".done", "markers"]:
                p = os.path.join(d, "out", sub)
                if os.path.isdir(p):
                    for m in os.listdir(p):
                        if m.startswith("a"):
                            open(os.path.join(p, m), "w").write("garbage")

    for name, change in [("changed input", change_input), ("deleted output", delete_output),
                         ("changed options", change_opts), ("garbage marker", garbage_marker)]:
        out.append(Case("batch", f"rerun after {name}", folder, ["info", "in/b.ply"], expect="ok",
                        check=rerun_after(change)))

    def dangling(d):
        folder(d)
        os.symlink("gone.ply", os.path.join(d, "in", "c.ply"))
    out.append(Case("batch", "dangling symlink is reported", dangling,
                    ["batch", "in", "out", "--iterations", "1"],
                    check=lambda d, c, o, e: None if "c.ply" in e else "c.ply vanished silently"))

    def same_folder(d):
        folder(d)
    out.append(Case("batch", "OUTDIR = INDIR twice", same_folder, ["info", "in/a.ply"], expect="ok",
                    check=twice_in_place))
    return out


def twice_in_place(d, code, o, e):
    runs = []
    for _ in range(2):
        p = subprocess.run([BIN, "batch", "in", "in", "--iterations", "1", "--format", "obj"], cwd=d,
                           capture_output=True)
        runs.append(p)
    if runs[1].returncode != 0 and runs[0].returncode == 0:
        return "the second run fails: " + runs[1].stderr.decode()[:200]
    if any(n.count(".") > 1 for n in os.listdir(os.path.join(d, "in")) if not n.startswith(".")):
        return "outputs were taken as inputs: " + ", ".join(sorted(os.listdir(os.path.join(d, "in"))))
    return None


def cases_memory():
    out = []
    mesh = write("scan.ply", SPHERE_PLY)

    def big(d):
        medium(d, k=6)
    for limit in [150_000, 400_000]:
        out.append(Case("memory", f"smooth under ulimit -v {limit}k", big,
                        ["smooth", "in.ply", "out.ply", "--iterations", "2"], limit_as_kb=limit,
                        output="out.ply"))
        out.append(Case("memory", f"subdivide under ulimit -v {limit}k", big,
                        ["subdivide", "in.ply", "out.ply", "--max-edge", "0.0005"], limit_as_kb=limit,
                        output="out.ply"))
        out.append(Case("memory", f"generate under ulimit -v {limit}k", lambda d: None,
                        ["generate", "sphere", "out.ply", "--subdivisions", "12"], limit_as_kb=limit,
                        output="out.ply"))
    out.append(Case("memory", "subdivide to a huge mesh", mesh,
                    ["subdivide", "scan.ply", "out.ply", "--max-edge", "1e-7"], output="out.ply",
                    timeout=30))
    return out


def cases_output():
    out = []
    mesh = write("scan.ply", SPHERE_PLY)
    for cmd in [["info", "scan.ply"], ["compare", "scan.ply", "scan.ply"],
                ["info", "flat.ply"], ["compare", "flat.ply", "flat.ply"],
                ["info", "--json", "flat.ply"], ["compare", "--json", "flat.ply", "flat.ply"]]:
        v = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)]
        f = [(0, 1, 2), (2, 1, 3)]
        out.append(Case("output", " ".join(cmd), both(mesh, write("flat.ply", ply_binary(v, f))), cmd,
                        expect="ok", check=no_undefined_numbers))
    return out


def no_undefined_numbers(d, code, out, err):
    if re.search(r"\bNaN\b|\binf\b|\bInfinity\b", out):
        return "printed NaN/inf"
    return None


# ---------------------------------------------------------------------------------------------
# glTF

GLB_JSON, GLB_BIN = 0x4E4F534A, 0x004E4942


def unit(p):
    n = math.sqrt(sum(c * c for c in p)) or 1.0
    return tuple(c / n for c in p)


def gltf_mesh(v, f, index_type=5125, normals=False):
    """One triangle primitive as a glTF document (buffer 0, no uri yet) and that buffer's bytes:
    accessor 0 the positions (view 0), 1 the indices (view 1), 2 the normals (view 2, if asked)."""
    pos = b"".join(struct.pack("<3f", *p) for p in v)
    code = {5121: "B", 5123: "H", 5125: "I"}[index_type]
    idx = b"".join(struct.pack("<3" + code, *t) for t in f)
    idx += b"\0" * (-len(idx) % 4)
    views = [{"buffer": 0, "byteLength": len(pos), "target": 34962},
             {"buffer": 0, "byteOffset": len(pos), "byteLength": len(idx), "target": 34963}]
    accessors = [{"bufferView": 0, "componentType": 5126, "count": len(v), "type": "VEC3",
                  "min": [min(p[k] for p in v) for k in range(3)],
                  "max": [max(p[k] for p in v) for k in range(3)]},
                 {"bufferView": 1, "componentType": index_type, "count": 3 * len(f), "type": "SCALAR"}]
    data = pos + idx
    prim = {"attributes": {"POSITION": 0}, "indices": 1}
    if normals:
        nrm = b"".join(struct.pack("<3f", *unit(p)) for p in v)
        views.append({"buffer": 0, "byteOffset": len(data), "byteLength": len(nrm), "target": 34962})
        accessors.append({"bufferView": 2, "componentType": 5126, "count": len(v), "type": "VEC3"})
        prim["attributes"]["NORMAL"] = 2
        data += nrm
    doc = {"asset": {"version": "2.0", "generator": "hostile_probe"}, "scene": 0,
           "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}], "meshes": [{"primitives": [prim]}],
           "buffers": [{"byteLength": len(data)}], "bufferViews": views, "accessors": accessors}
    return doc, data


def gltf_text(doc, uri=None):
    """`doc` as `.gltf` JSON, its buffer 0 named `uri`."""
    if uri is not None:
        doc = edited(doc, lambda j: j["buffers"][0].update(uri=uri))
    return json.dumps(doc).encode()


def data_uri(data):
    return "data:application/octet-stream;base64," + base64.b64encode(data).decode()


def glb(doc, data, version=2, pad_json=True):
    """A GLB: header, JSON chunk, BIN chunk (none if `data` is None)."""
    text = json.dumps(doc).encode()
    if pad_json:
        text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), GLB_JSON) + text
    if data is not None:
        data = data + b"\0" * (-len(data) % 4)
        body += struct.pack("<II", len(data), GLB_BIN) + data
    return b"glTF" + struct.pack("<II", version, 12 + len(body)) + body


def edited(doc, fn):
    """A deep copy of `doc` after `fn(copy)`."""
    doc = copy.deepcopy(doc)
    fn(doc)
    return doc


def patched(data, at, fmt, *values):
    b = bytearray(data)
    struct.pack_into(fmt, b, at, *values)
    return bytes(b)


def gltf_files(doc, data, name="m.gltf", uri="m.bin", file=None):
    """Setup: `name`, JSON whose buffer 0 is `uri`, and that buffer as `file` (default: `uri`)."""
    return both(write(name, gltf_text(doc, uri)), write(file or uri, data))


def read_gltf(path):
    """A glTF or GLB file's JSON and its buffers' bytes (None where one cannot be read)."""
    with open(path, "rb") as fh:
        raw = fh.read()
    chunk = None
    if raw[:4] == b"glTF":
        n = struct.unpack_from("<I", raw, 12)[0]
        doc = json.loads(raw[20:20 + n])
        at = 20 + n
        if at + 8 <= len(raw) and struct.unpack_from("<I", raw, at + 4)[0] == GLB_BIN:
            chunk = raw[at + 8:at + 8 + struct.unpack_from("<I", raw, at)[0]]
    else:
        doc = json.loads(raw)
    buffers = []
    for b in doc.get("buffers", []):
        uri = b.get("uri")
        if uri is None:
            buffers.append(chunk)
        elif uri.startswith("data:"):
            buffers.append(base64.b64decode(uri.split(",", 1)[1]))
        else:
            try:
                with open(os.path.join(os.path.dirname(path), urllib.parse.unquote(uri)), "rb") as fh:
                    buffers.append(fh.read())
            except OSError:
                buffers.append(None)
    return doc, buffers


def gltf_written(inp, outp, uris=None, same=False):
    """The output reads back with the input's vertex and triangle counts, finite coordinates inside
    the input's bounding box grown by its diagonal; with `same` (0 iterations), every vertex where
    it was; `uris`: the external buffers a glTF output must name, in order."""
    def check(d, code, out, err):
        if code != 0:
            return None
        i, o = os.path.join(d, inp), os.path.join(d, outp)
        p = subprocess.run([BIN, "info", "--json", o], capture_output=True, timeout=TIMEOUT)
        if p.returncode != 0:
            return "the output does not read back: " + p.stderr.decode(errors="replace").strip()[:300]
        a, b = info(i), json.loads(p.stdout)
        if a is None:
            return "the input (or its copy) no longer reads"
        counts = lambda j: (find(j, "vertices"), find(j, "triangles"))
        if counts(a) != counts(b):
            return f"read back {counts(b)} vertices and triangles, the input has {counts(a)}"
        lo, hi, g = find(a, "bbox_min"), find(a, "bbox_max"), find(a, "bbox_diagonal")
        blo, bhi = find(b, "bbox_min"), find(b, "bbox_max")
        if any(not math.isfinite(x) for x in blo + bhi):
            return "non-finite coordinates in the output"
        if any(blo[k] < lo[k] - g or bhi[k] > hi[k] + g for k in range(3)):
            return f"output box {blo}..{bhi} outside the input's {lo}..{hi} grown by {g:.3g}"
        if same:
            c = subprocess.run([BIN, "compare", "--json", i, o], capture_output=True, timeout=TIMEOUT)
            if c.returncode != 0:
                return "compare with the input failed: " + c.stderr.decode(errors="replace").strip()[:200]
            moved = find(json.loads(c.stdout), "max_distance")
            if moved != 0:
                return f"0 iterations moved a vertex by {moved!r}"
        if uris is not None:
            doc, _ = read_gltf(o)
            got = [b.get("uri") for b in doc.get("buffers", [])
                   if not str(b.get("uri", "data:")).startswith("data:")]
            if got != uris:
                return f"the output names buffers {got}, expected {uris}"
        return None
    return check


def refused_naming(*names):
    """A refusal's line names these (the file, the uri)."""
    def check(d, code, out, err):
        if code != 0 and not all(n in err for n in names):
            return f"the error does not name {', '.join(names)}: {err.strip()[:200]!r}"
        return None
    return check


def all_of(*checks):
    def check(d, code, out, err):
        for c in checks:
            problem = c(d, code, out, err)
            if problem:
                return problem
        return None
    return check


def same_bytes(outp, buffer, start, end, expected):
    """Bytes `start..end` of the output's buffer `buffer` are `expected` (data the writer must not
    touch)."""
    def check(d, code, out, err):
        if code != 0:
            return None
        _, buffers = read_gltf(os.path.join(d, outp))
        got = buffers[buffer] if buffer < len(buffers) else None
        if got is None or got[start:end] != expected:
            return f"bytes {start}..{end} of buffer {buffer} changed"
        return None
    return check


def noisy_icosphere(k, seed=3):
    v, f = icosphere(k)
    rng = Lcg(seed)
    return [tuple(c * (1 + 0.1 * (rng.next() - 0.5)) for c in p) for p in v], f


GLTF_SPHERE = noisy_icosphere(2)


def cases_gltf():
    out = []
    v, f = GLTF_SPHERE
    nv, nf = len(v), len(f)
    doc, data = gltf_mesh(v, f, normals=True)
    npos = 12 * nv  # the positions' bytes, then the indices', then the normals'
    ext = gltf_files(doc, data)
    emb = write("e.gltf", gltf_text(doc, data_uri(data)))
    bin_ = write("m.glb", glb(doc, data))

    def smooth(src, dst, *extra):
        return ["smooth", src, dst, "--iterations", "3", *extra]

    def ok(name, setup, argv, output="out.gltf", new=(), check=None, **kw):
        out.append(Case("gltf", name, setup, argv, expect="ok", output=output,
                        new_files=None if new is None else list(new), check=check, **kw))

    def either(name, setup, argv, output="out.gltf", check=None, **kw):
        out.append(Case("gltf", name, setup, argv, expect="either", output=output, check=check, **kw))

    def bad(name, setup, argv=None, names=("m.gltf",), **kw):
        out.append(Case("gltf", name, setup, argv or smooth("m.gltf", "out.gltf"), expect="error",
                        new_files=[], check=refused_naming(*names), **kw))

    def bad_doc(name, fn, data=data, names=("m.gltf",)):
        bad(name, gltf_files(edited(doc, fn), data), names=names)

    # Round trips, each kind into itself; 0 iterations keeps every vertex.
    for src, setup, new, uris in [("m.gltf", ext, ["out.bin"], ["out.bin"]), ("e.gltf", emb, [], []),
                                  ("m.glb", bin_, [], [])]:
        dst = "out.glb" if src.endswith(".glb") else "out.gltf"
        ok(f"{src} -> {dst}", setup, smooth(src, dst), dst, new,
           gltf_written(src, dst, uris=uris))
        ok(f"{src} -> {dst}, 0 iterations", setup, ["smooth", src, dst, "--iterations", "0"], dst,
           new, gltf_written(src, dst, uris=uris, same=True))
    # glTF only to its own kind, and only from glTF; to the other formats, a plain mesh.
    bad("m.glb -> .gltf refused", bin_, smooth("m.glb", "out.gltf"), names=())
    bad("m.gltf -> .glb refused", ext, smooth("m.gltf", "out.glb"), names=())
    bad("ply -> .gltf refused", write("s.ply", ply_binary(v, f)), smooth("s.ply", "out.gltf"), names=())
    bad("obj -> .glb refused", write("s.obj", obj(v, f)), smooth("s.obj", "out.glb"), names=())
    for src, setup, dst in [("m.gltf", ext, "out.ply"), ("e.gltf", emb, "out.obj"),
                            ("m.glb", bin_, "out.off"), ("m.gltf", ext, "out.stl")]:
        ok(f"{src} -> {dst}", setup, smooth(src, dst), dst, check=gltf_written(src, dst))
    ok("m.glb -> out.ply, 0 iterations", bin_, ["smooth", "m.glb", "out.ply", "--iterations", "0"],
       "out.ply", check=gltf_written("m.glb", "out.ply", same=True))
    for src, setup in [("m.gltf", ext), ("e.gltf", emb), ("m.glb", bin_)]:
        ok(f"info {src}", setup, ["info", "--json", src], None, check=expect_counts(nv, nf))
    ok("compare m.gltf m.glb", both(ext, bin_), ["compare", "--json", "m.gltf", "m.glb"], None,
       check=lambda d, c, o, e: None if find(json.loads(o), "max_distance") == 0 else "not equal")

    # Buffers, views and accessors that lie.
    bad("the .bin shorter than byteLength", gltf_files(doc, data[:len(data) // 2]))
    ok("the .bin longer than byteLength", gltf_files(doc, data + b"\xff" * 1000),
       smooth("m.gltf", "out.gltf"), new=["out.bin"], check=gltf_written("m.gltf", "out.gltf"))
    for value in [2 ** 64 - 1, 2 ** 64, -1, 1.5, "168"]:
        bad_doc(f"byteLength {value!r}", lambda j, x=value: j["buffers"][0].update(byteLength=x))
    bad("byteLength 1e400", both(write("m.gltf", gltf_text(doc, "m.bin").replace(
        b'"byteLength": %d' % len(data), b'"byteLength": 1e400')), write("m.bin", data)))
    bad_doc("bufferView past its buffer", lambda j: j["bufferViews"][0].update(byteOffset=len(data)))
    bad_doc("bufferView offset 2^64-1", lambda j: j["bufferViews"][0].update(byteOffset=2 ** 64 - 1))
    bad_doc("accessor count past its view", lambda j: j["accessors"][0].update(count=nv + 1))
    bad_doc("accessor offset 2^64-1", lambda j: j["accessors"][0].update(byteOffset=2 ** 64 - 1))
    for stride in [4, 2 ** 62, 2 ** 64 - 1]:
        bad_doc(f"byteStride {stride}", lambda j, s=stride: j["bufferViews"][0].update(byteStride=s))
    for value in [2 ** 64 - 1, -1, 1.5, "162", None]:
        bad_doc(f"POSITION count {value!r}", lambda j, x=value: j["accessors"][0].update(count=x))
    bad_doc("POSITION as u16 (quantized)", lambda j: j["accessors"][0].update(componentType=5123))
    bad_doc("POSITION as VEC4", lambda j: j["accessors"][0].update(type="VEC4"))
    attributes = lambda j: j["meshes"][0]["primitives"][0]["attributes"]
    bad_doc("POSITION accessor 99", lambda j: attributes(j).update(POSITION=99))
    bad_doc("POSITION accessor \"0\"", lambda j: attributes(j).update(POSITION="0"))
    bad_doc("no POSITION", lambda j: attributes(j).pop("POSITION"))
    bad_doc("buffer 7 of 1", lambda j: j["bufferViews"][0].update(buffer=7))
    bad_doc("indices as float", lambda j: j["accessors"][1].update(componentType=5126))
    bad_doc("indices as VEC3", lambda j: j["accessors"][1].update(type="VEC3", count=nf))
    bad_doc("indices not a multiple of 3", lambda j: j["accessors"][1].update(count=3 * nf - 1))
    bad("index = vertex count", gltf_files(doc, patched(data, npos + 4, "<I", nv)))
    bad("index 2^32-1", gltf_files(doc, patched(data, npos, "<I", 2 ** 32 - 1)))
    bad("a NaN vertex", gltf_files(doc, patched(data, 12 * 5, "<f", math.nan)))
    bad("an infinite vertex", gltf_files(doc, patched(data, 12 * 5 + 8, "<f", -math.inf)))
    sparse = {"count": 1, "indices": {"bufferView": 1, "componentType": 5125},
              "values": {"bufferView": 0}}
    bad_doc("sparse POSITION", lambda j: j["accessors"][0].update(sparse=sparse))
    bad_doc("sparse indices", lambda j: j["accessors"][1].update(sparse=sparse))
    bad_doc("Draco required", lambda j: j.update(extensionsRequired=["KHR_draco_mesh_compression"]))

    def with_sparse_uv(j):
        j["accessors"].append({"componentType": 5126, "count": nv, "type": "VEC2", "sparse": sparse})
        j["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = len(j["accessors"]) - 1
    ok("sparse TEXCOORD_0 is carried", gltf_files(edited(doc, with_sparse_uv), data),
       smooth("m.gltf", "out.gltf"), new=["out.bin"], check=gltf_written("m.gltf", "out.gltf"))

    # Primitive modes: nothing but points, lines, strips or fans is nothing to smooth; beside
    # triangles, a line's points keep their bytes.
    for mode in [0, 1, 5, 6]:
        bad_doc(f"only a mode {mode} primitive",
                lambda j, m=mode: j["meshes"][0]["primitives"][0].update(mode=m))
    line = struct.pack("<6f", 9, 9, 9, 9, 9, 8)

    def with_line(j):
        j["buffers"][0]["byteLength"] = len(data) + len(line)
        j["bufferViews"].append({"buffer": 0, "byteOffset": len(data), "byteLength": len(line)})
        j["accessors"].append({"bufferView": 3, "componentType": 5126, "count": 2, "type": "VEC3"})
        j["meshes"][0]["primitives"].append({"attributes": {"POSITION": 3}, "mode": 3})
    ok("triangles beside a line strip", gltf_files(edited(doc, with_line), data + line),
       smooth("m.gltf", "out.gltf"), new=["out.bin"],
       check=all_of(gltf_written("m.gltf", "out.gltf"),
                    same_bytes("out.gltf", 0, len(data), len(data) + len(line), line)))

    # Several primitives, meshes and nodes.
    def split(j):
        j["accessors"][1]["count"] = 3 * (nf // 2)
        j["accessors"].append({"bufferView": 1, "byteOffset": 12 * (nf // 2), "componentType": 5125,
                               "count": 3 * (nf - nf // 2), "type": "SCALAR"})
        j["meshes"][0]["primitives"].append({"attributes": {"POSITION": 0}, "indices": 3})
    ok("two primitives share POSITION", gltf_files(edited(doc, split), data),
       ["info", "--json", "m.gltf"], None, check=expect_counts(nv, nf))

    def nodes(j):
        j["nodes"] = [{"mesh": 0, "scale": [(-1) ** k, 1, 1]} for k in range(10000)]
        j["scenes"][0]["nodes"] = list(range(10000))
    ok("10000 nodes, mirrored, one mesh", gltf_files(edited(doc, nodes), data),
       smooth("m.gltf", "out.gltf"), new=["out.bin"], check=gltf_written("m.gltf", "out.gltf"))
    either("one primitive in two meshes",
           gltf_files(edited(doc, lambda j: j["meshes"].append(copy.deepcopy(j["meshes"][0]))), data),
           smooth("m.gltf", "out.gltf"), new_files=["out.bin"],
           check=gltf_written("m.gltf", "out.gltf"))
    bad_doc("no meshes", lambda j: j.update(meshes=[]))
    bad_doc("a mesh without primitives", lambda j: j["meshes"][0].update(primitives=[]))
    bad_doc("0 vertices, 0 indices", lambda j: [j["accessors"][k].update(count=0) for k in range(3)])

    # Buffer files: missing, a folder, a device, outside the folder, escaped names.
    bad("the .bin missing", write("m.gltf", gltf_text(doc, "m.bin")), names=("m.gltf", "m.bin"))
    bad("the .bin a folder", both(write("m.gltf", gltf_text(doc, "m.bin")),
                                  lambda d: os.mkdir(os.path.join(d, "m.bin"))), names=("m.gltf",))
    # An endless device: read no more than byteLength (under a cap here, to spare the machine).
    either("a buffer uri /dev/zero", write("m.gltf", gltf_text(doc, "/dev/zero")),
           smooth("m.gltf", "out.gltf"), new_files=["out.bin"], timeout=20, limit_as_kb=2_000_000,
           check=lambda d, c, o, e: "read the device until memory ran out" if "out of memory" in e
           else None)
    ok("a buffer uri ../shared.bin", gltf_files(doc, data, "sub/m.gltf", "../shared.bin", "shared.bin"),
       ["smooth", "sub/m.gltf", "out.gltf", "--iterations", "0"], new=["out.bin"],
       check=gltf_written("sub/m.gltf", "out.gltf", uris=["out.bin"], same=True))

    def absolute(d):
        write("m.gltf", gltf_text(doc, os.path.join(d, "store", "m.bin")))(d)
        write("store/m.bin", data)(d)
    ok("a buffer uri absolute", absolute, smooth("m.gltf", "out.gltf"), new=["out.bin"],
       check=gltf_written("m.gltf", "out.gltf", uris=["out.bin"]))
    ok("a buffer uri m%20x.bin", gltf_files(doc, data, uri="m%20x.bin", file="m x.bin"),
       smooth("m.gltf", "out.gltf"), new=["out.bin"], check=gltf_written("m.gltf", "out.gltf"))
    for uri in ["m%zz.bin", "m%2", "m%FF.bin"]:
        bad(f"a buffer uri {uri}", both(write("m.gltf", gltf_text(doc, uri)), write("m.bin", data)))
    ok("the input's buffer is out%2Ebin", gltf_files(doc, data, uri="out%2Ebin", file="out.bin"),
       ["smooth", "m.gltf", "out.gltf", "--iterations", "0"], new=["out-1.bin"],
       check=gltf_written("m.gltf", "out.gltf", uris=["out-1.bin"], same=True))

    # The input names the output, or a report: refused before anything is written.
    with_image = lambda name: edited(doc, lambda j: j.update(images=[{"uri": name}]))
    bad("an image uri names the output", both(gltf_files(with_image("out.gltf"), data),
                                              write("out.gltf", b"earlier")), names=("out.gltf",))
    bad("the buffer is the .obj output", gltf_files(doc, data, uri="out.obj"),
        smooth("m.gltf", "out.obj"), names=("out.obj",))
    for flag, target in [("--report", "m.bin"), ("--report", "out.bin"), ("--report", "out-7.bin"),
                         ("--report", "sub/../out.bin")]:
        bad(f"{flag} {target}", both(ext, lambda d: os.makedirs(os.path.join(d, "sub"))),
            smooth("m.gltf", "out.gltf", flag, target), names=())
    ok("an image uri names out.bin (absent)", gltf_files(with_image("out.bin"), data),
       ["smooth", "m.gltf", "out.gltf", "--iterations", "0"], new=["out-1.bin"],
       check=gltf_written("m.gltf", "out.gltf", uris=["out-1.bin"], same=True))

    # The output's buffer beside it: never over a file that is not its own.
    def user(kind):
        def setup(d):
            ext(d)
            p = os.path.join(d, "out.bin")
            if kind == "file":
                write("out.bin", b"the user's")(d)
            elif kind == "dir":
                os.mkdir(p)
            elif kind == "dangling":
                os.symlink("nowhere", p)
            elif kind == "two":
                write("out.bin", b"the user's")(d)
                write("out-1.bin", b"the user's too")(d)
        return setup
    for kind, first in [("file", "out-1.bin"), ("dir", "out-1.bin"), ("dangling", "out-1.bin"),
                        ("two", "out-2.bin")]:
        ok(f"out.bin exists ({kind})", user(kind), ["smooth", "m.gltf", "out.gltf", "--iterations", "0"],
           new=[first], check=gltf_written("m.gltf", "out.gltf", uris=[first], same=True))

    def rerun(d):
        ext(d)
        subprocess.run([BIN, "smooth", "m.gltf", "out.gltf", "--iterations", "1"], cwd=d,
                       check=True, capture_output=True)
    ok("an earlier run's out.bin is replaced", rerun, smooth("m.gltf", "out.gltf"), replaces=["out.bin"],
       check=gltf_written("m.gltf", "out.gltf", uris=["out.bin"]))

    def rerun_link(d):
        rerun(d)
        os.remove(os.path.join(d, "out.bin"))
        os.symlink("m.bin", os.path.join(d, "out.bin"))
    # Written through, the link would overwrite the input's buffer: the output takes another name.
    ok("an earlier run's out.bin, now a link to the input's", rerun_link, smooth("m.gltf", "out.gltf"),
       new=["out-1.bin"], check=gltf_written("m.gltf", "out.gltf", uris=["out-1.bin"]))

    # Two external buffers, each holding a mesh.
    w = [(x + 5, y, z) for x, y, z in v]
    doc2, data2 = gltf_mesh(w, f)

    def two(j):
        j["buffers"].append({"byteLength": len(data2) + 8, "uri": "b.bin"})
        j["bufferViews"] += [{"buffer": 1, "byteLength": npos},
                             {"buffer": 1, "byteOffset": npos, "byteLength": 12 * nf}]
        j["accessors"] += [{"bufferView": 3, "componentType": 5126, "count": nv, "type": "VEC3"},
                           {"bufferView": 4, "componentType": 5125, "count": 3 * nf, "type": "SCALAR"}]
        j["meshes"].append({"primitives": [{"attributes": {"POSITION": 3}, "indices": 4}]})
    two_doc = edited(doc, two)
    two_files = both(gltf_files(two_doc, data, "m.gltf", "a.bin"), write("b.bin", data2 + b"\0" * 8))
    ok("two buffers", two_files, ["smooth", "m.gltf", "out.gltf", "--iterations", "0"],
       new=["out.bin", "out-1.bin"],
       check=gltf_written("m.gltf", "out.gltf", uris=["out.bin", "out-1.bin"], same=True))
    ok("two buffers, out.bin exists", both(two_files, write("out.bin", b"the user's")),
       ["smooth", "m.gltf", "out.gltf", "--iterations", "0"], new=["out-1.bin", "out-2.bin"],
       check=gltf_written("m.gltf", "out.gltf", uris=["out-1.bin", "out-2.bin"], same=True))

    # In place.
    ok("in place", both(gltf_files(doc, data, "a.gltf", "a.bin"),
                        write("orig.gltf", gltf_text(doc, "a.bin"))),
       ["smooth", "a.gltf", "a.gltf", "--iterations", "0"], "a.gltf", new=["a-1.bin"],
       check=gltf_written("orig.gltf", "a.gltf", uris=["a-1.bin"], same=True))
    ok("in place, two buffers",
       both(two_files, lambda d: shutil.copy(os.path.join(d, "m.gltf"), os.path.join(d, "orig.gltf"))),
       ["smooth", "m.gltf", "m.gltf", "--iterations", "0"], "m.gltf", new=["m.bin", "m-1.bin"],
       check=gltf_written("orig.gltf", "m.gltf", uris=["m.bin", "m-1.bin"], same=True))
    a_doc = edited(two_doc, lambda j: j["buffers"][1].update(uri="a-1.bin"))
    ok("in place, the buffers named a.bin and a-1.bin",
       both(gltf_files(a_doc, data, "a.gltf", "a.bin"), write("a-1.bin", data2 + b"\0" * 8),
            write("orig.gltf", gltf_text(a_doc, "a.bin"))),
       ["smooth", "a.gltf", "a.gltf", "--iterations", "0"], "a.gltf", new=["a-2.bin", "a-3.bin"],
       check=gltf_written("orig.gltf", "a.gltf", uris=["a-2.bin", "a-3.bin"], same=True))

    # A GLB whose buffer is an external file: the buffer goes beside the output too.
    glb_ext = both(write("m.glb", glb(edited(doc, lambda j: j["buffers"][0].update(uri="m.bin")), None)),
                   write("m.bin", data))
    ok("a GLB with an external buffer", glb_ext, ["smooth", "m.glb", "out.glb", "--iterations", "0"],
       "out.glb", new=["out.bin"], check=gltf_written("m.glb", "out.glb", uris=["out.bin"], same=True))
    either("a GLB with an external buffer, --report out.bin", glb_ext,
           smooth("m.glb", "out.glb", "--report", "out.bin"), "out.glb",
           check=gltf_written("m.glb", "out.glb"))
    ok("output named 'a b%.gltf'", ext, smooth("m.gltf", "a b%.gltf"), "a b%.gltf", new=["a b%.bin"],
       check=gltf_written("m.gltf", "a b%.gltf", uris=["a%20b%25.bin"]))

    ok("in place, a GLB with an external buffer",
       both(glb_ext, lambda d: shutil.copy(os.path.join(d, "m.glb"), os.path.join(d, "orig.glb"))),
       ["smooth", "m.glb", "m.glb", "--iterations", "0"], "m.glb", new=["m-1.bin"],
       check=gltf_written("orig.glb", "m.glb", uris=["m-1.bin"], same=True))
    bad("--report OUT.bin for OUT.GLTF", ext, smooth("m.gltf", "OUT.GLTF", "--report", "OUT.bin"), names=())

    def linked(d):
        gltf_files(doc, data, uri="out.bin")(d)
        os.symlink(".", os.path.join(d, "link"))
    ok("output through a linked folder, the input's buffer is out.bin", linked,
       ["smooth", "m.gltf", "link/out.gltf", "--iterations", "0"], "out.gltf", new=["out-1.bin"],
       check=gltf_written("m.gltf", "out.gltf", uris=["out-1.bin"], same=True))
    ok("two buffers naming the same file",
       gltf_files(edited(two_doc, lambda j: j["buffers"][1].update(uri="m.bin", byteLength=len(data2))),
                  data), ["smooth", "m.gltf", "out.gltf", "--iterations", "0"], new=["out.bin", "out-1.bin"],
       check=gltf_written("m.gltf", "out.gltf", uris=["out.bin", "out-1.bin"], same=True))
    ok("out of core into .gltf", ext, smooth("m.gltf", "out.gltf", "--memory-budget", "64M"),
       new=["out.bin"], check=gltf_written("m.gltf", "out.gltf", uris=["out.bin"]))
    ok("multires into .glb", bin_, smooth("m.glb", "out.glb", "--multires"), "out.glb",
       check=gltf_written("m.glb", "out.glb"))
    bad("subdivide m.gltf into .gltf is refused", ext,
        ["subdivide", "m.gltf", "out.gltf", "--max-edge", "0.1"], names=("out.gltf",))
    ok("subdivide m.glb into .ply", bin_, ["subdivide", "m.glb", "out.ply", "--max-edge", "0.1"],
       "out.ply")

    # Hostile GLB containers.
    g = glb(doc, data)
    jlen = struct.unpack_from("<I", g, 12)[0]
    for name, blob in [
            ("bad magic", b"gLTF" + g[4:]),
            ("version 1", g[:4] + struct.pack("<I", 1) + g[8:]),
            ("length past the end", g[:8] + struct.pack("<I", len(g) + 4) + g[12:]),
            ("length 0", g[:8] + struct.pack("<I", 0) + g[12:]),
            ("JSON chunk past the end", g[:12] + struct.pack("<I", len(g)) + g[16:]),
            ("JSON chunk 2^32-1", g[:12] + struct.pack("<I", 2 ** 32 - 1) + g[16:]),
            ("BIN chunk first", g[:12] + g[20 + jlen:] + g[12:20 + jlen]),
            ("no BIN chunk", g[:8] + struct.pack("<I", 20 + jlen) + g[12:20 + jlen]),
            ("header only", g[:12]),
            ("unknown first chunk", g[:16] + struct.pack("<I", 0x12345678) + g[20:])]:
        bad(f"GLB {name}", write("m.glb", blob), smooth("m.glb", "out.glb"), names=("m.glb",))
    for frac in [0.001, 0.3, 0.9, 0.999]:
        cut = max(1, int(len(g) * frac))
        bad(f"GLB cut at {cut}", write("m.glb", g[:cut]), smooth("m.glb", "out.glb"), names=("m.glb",))
    unpadded = glb(doc, data, pad_json=False)
    either("GLB JSON unpadded (BIN chunk misaligned)", write("m.glb", unpadded),
           smooth("m.glb", "out.glb"), "out.glb", new_files=[], check=gltf_written("m.glb", "out.glb"))
    extra = g[:8] + struct.pack("<I", len(g) + 12) + g[12:20 + jlen] + struct.pack("<II", 4, 0x58595A) \
        + b"zzzz" + g[20 + jlen:]
    either("GLB unknown chunk before BIN", write("m.glb", extra), smooth("m.glb", "out.glb"), "out.glb",
           new_files=[], check=gltf_written("m.glb", "out.glb"))
    either("GLB named .gltf", write("m.gltf", g), smooth("m.gltf", "out.glb"), "out.glb", new_files=[],
           check=gltf_written("m.gltf", "out.glb"))

    # Hostile JSON.
    text = gltf_text(doc, "m.bin")
    count = b'"count": %d' % nv
    for name, blob in [
            ("NaN count", text.replace(count, b'"count": NaN', 1)),
            ("Infinity count", text.replace(count, b'"count": Infinity', 1)),
            ("a 400-digit count", text.replace(count, b'"count": 1' + b"0" * 400, 1)),
            ("nesting 100000 deep", text[:-1] + b', "extras": ' + b"[" * 100000 + b"]" * 100000 + b"}"),
            ("trailing garbage", text + b"}{"),
            ("invalid UTF-8 in a string", text.replace(b"hostile_probe", b"hostile\xff\xfe", 1)),
            ("UTF-16", text.decode().encode("utf-16")),
            ("empty", b""), ("null", b"null"), ("[]", b"[]"), ("{}", b"{}"),
            ("asset.version 1.0", text.replace(b'"version": "2.0"', b'"version": "1.0"')),
            ("asset.version 2 (a number)", text.replace(b'"version": "2.0"', b'"version": 2'))]:
        bad(f"JSON {name}", both(write("m.gltf", blob), write("m.bin", data)))
    either("JSON duplicate count", both(write("m.gltf", text.replace(count, b'"count": 999999, ' + count, 1)),
                                        write("m.bin", data)),
           smooth("m.gltf", "out.gltf"), new_files=["out.bin"], check=gltf_written("m.gltf", "out.gltf"))
    either("JSON nesting 100 deep", both(write("m.gltf", text[:-1] + b', "extras": ' + b"[" * 100
                                               + b"]" * 100 + b"}"), write("m.bin", data)),
           smooth("m.gltf", "out.gltf"), new_files=["out.bin"], check=gltf_written("m.gltf", "out.gltf"))
    ok("JSON with a BOM", both(write("m.gltf", b"\xef\xbb\xbf" + text), write("m.bin", data)),
       smooth("m.gltf", "out.gltf"), new=["out.bin"], check=gltf_written("m.gltf", "out.gltf"))
    ok("min/max as strings", gltf_files(edited(doc, lambda j: j["accessors"][0].update(
        min=["nan"] * 3, max=["inf"] * 3)), data), smooth("m.gltf", "out.gltf"), new=["out.bin"],
       check=gltf_written("m.gltf", "out.gltf"))

    # data: URIs.
    b64 = base64.b64encode(data).decode()
    for name, uri in [("bad base64", "data:application/octet-stream;base64,!!!!" + b64[4:]),
                      ("not base64", "data:application/octet-stream," + b64),
                      ("no comma", "data:application/octet-stream;base64"),
                      ("a line break", "data:application/octet-stream;base64," + b64[:40] + "\n" + b64[40:]),
                      ("cut short", "data:application/octet-stream;base64," + b64[:len(b64) // 2])]:
        bad(f"data: URI {name}", write("m.gltf", gltf_text(doc, uri)))
    bad("data: URI byteLength 2^63", write("m.gltf", gltf_text(
        edited(doc, lambda j: j["buffers"][0].update(byteLength=2 ** 63)), data_uri(data))))

    # Writer against hostile layouts: the geometry written must read back.
    def normal_over(view):
        return lambda j: j["accessors"][2].update(bufferView=view)
    either("NORMAL over the index bytes", gltf_files(edited(doc, normal_over(1)), data),
           smooth("m.gltf", "out.gltf"), new_files=["out.bin"], check=gltf_written("m.gltf", "out.gltf"))
    far = [(x + 1000, y, z) for x, y, z in v]
    fdoc, fdata = gltf_mesh(far, f, normals=True)
    either("NORMAL is the POSITION accessor",
           gltf_files(edited(fdoc, lambda j: j["meshes"][0]["primitives"][0]["attributes"].update(NORMAL=0)),
                      fdata), smooth("m.gltf", "out.gltf"), new_files=["out.bin"],
           check=gltf_written("m.gltf", "out.gltf"))
    huge = [tuple(3.0e38 * c for c in p) for p in v]
    for method in ["taubin", "vcs"]:
        either(f"coordinates near the float limit, {method}", gltf_files(*gltf_mesh(huge, f)),
               smooth("m.gltf", "out.gltf", "--method", method), new_files=["out.bin"],
               check=gltf_written("m.gltf", "out.gltf"))

    # info and compare on hostile files.
    broken = gltf_files(doc, patched(data, npos + 4, "<I", nv), name="bad.gltf", uri="bad.bin")
    bad("info on an index out of range", broken, ["info", "bad.gltf"], names=("bad.gltf",))
    bad("compare with an index out of range", both(ext, broken), ["compare", "m.gltf", "bad.gltf"],
        names=("bad.gltf",))
    neg = [(x - 2, y - 2, z - 2) for x, y, z in v]
    ok("info --json, coordinates up to -0", gltf_files(*gltf_mesh(
        neg + [(-0.0, -0.0, -0.0)], f + [(0, 1, len(neg))])), ["info", "--json", "m.gltf"], None)

    # batch: glTF inputs (written as PLY), the same stem twice, in place.
    def folder(d):
        gltf_files(doc, data, "in/a.gltf", "a.bin", "in/a.bin")(d)
        write("in/b.glb", g)(d)
        write("orig.gltf", gltf_text(doc, "in/a.bin"))(d)
    # (new=None: batch writes its markers too)
    ok("batch of glTF", folder, ["batch", "in", "out", "--iterations", "0"], None, new=None,
       check=all_of(gltf_written("orig.gltf", "out/a.ply", same=True),
                    gltf_written("in/b.glb", "out/b.ply", same=True)))
    bad("batch: a.gltf and a.glb share a stem", both(folder, write("in/a.glb", g)),
        ["batch", "in", "out", "--iterations", "0"], names=("a.gltf", "a.glb"))
    bad("batch of glTF in place is refused", folder, ["batch", "in", "in", "--iterations", "0"],
        names=("in",))
    return out


# ---------------------------------------------------------------------------------------------
# Scripts, links, checkpoints and option combinations (what a run writes around its output)

# Names that run code if a script takes them as text; non-UTF-8 bytes travel as surrogates.
HOSTILE_NAMES = [
    ("newline", "in\ntouch PWNED #"),
    ("CR", "in\rtouch PWNED\r#"),
    ("$()", "in $(touch PWNED) x"),
    ("backticks", "in `touch PWNED` x"),
    ("quotes", "in'\"; touch PWNED; echo \"'x"),
    ("here-doc end", "in\nVCSMOOTH_EOF\ntouch PWNED\n#"),
    ("non-UTF-8", os.fsdecode(b"in\xff\xfe\n touch PWNED #")),
]


def fake_sbatch(d):
    """A folder with an `sbatch` that records its arguments and answers a job id."""
    bin_dir = os.path.join(d, ".fakebin")
    os.makedirs(bin_dir, exist_ok=True)
    sbatch = os.path.join(bin_dir, "sbatch")
    with open(sbatch, "w") as fh:
        fh.write("#!/bin/sh\necho \"$*\" >> \"$(dirname \"$0\")/log\"\necho 42\n")
    os.chmod(sbatch, 0o755)
    return bin_dir


def pwned(d):
    return [os.path.join(r, n) for r, _, names in os.walk(d) for n in names if n == "PWNED"]


def script_runs_clean(task=True):
    """Check of a `slurm-script` case: the script, run with a fake sbatch, runs no injected
    command, and its array task (run as Slurm would) does the batch."""
    def check(d, code, out, err):
        if code != 0:
            return f"refused: {err.strip()[:200]}"
        script = os.path.join(d, ".submit.sh")
        with open(script, "w") as fh:
            fh.write(out)
        env = dict(os.environ, PATH=fake_sbatch(d) + os.pathsep + os.environ.get("PATH", ""))
        for v in ["SLURM_ARRAY_TASK_ID", "SLURM_ARRAY_TASK_COUNT", "SLURM_ARRAY_TASK_MIN",
                  "SLURM_ARRAY_TASK_MAX"]:
            env.pop(v, None)
        p = subprocess.run(["bash", script], cwd=d, env=env, capture_output=True, timeout=TIMEOUT)
        if pwned(d):
            return "injected code ran when the script was run"
        if p.returncode != 0:
            return "the script fails: " + p.stderr.decode(errors="replace")[:200]
        if not task:
            return None
        p = subprocess.run(["bash", os.path.join(d, "out", ".slurm", "array.sbatch")], cwd=d,
                           env=dict(env, SLURM_ARRAY_TASK_ID="0"), capture_output=True,
                           timeout=TIMEOUT)
        if pwned(d):
            return "injected code ran in the array task"
        if p.returncode != 0:
            return "the array task fails: " + p.stderr.decode(errors="replace")[:200]
        if not any(n.endswith(".ply") for n in os.listdir(os.path.join(d, "out"))):
            return "the array task wrote no output"
        return None
    return check


def is_link_to_json(link, target=None, stdout=False):
    def check(d, code, out, err):
        p = os.path.join(d, link)
        if not os.path.islink(p):
            return f"{link} is no longer a symbolic link"
        try:
            if stdout:
                json.JSONDecoder().raw_decode(out)
            elif target:
                with open(os.path.join(d, target)) as fh:
                    text = fh.read()
                if not text.lstrip().startswith("<"):
                    json.loads(text)
        except (OSError, ValueError) as e:
            return f"no content where {link} leads: {e}"
        return None
    return check


def usage_line(line):
    def check(d, code, out, err):
        if code != 2:
            return f"exit {code}, not the usage error's 2"
        if err.strip() != "vcsmooth: error: " + line:
            return f"not the same line as everywhere: {err.strip()!r}"
        if out:
            return "printed something before refusing"
        return None
    return check


def cases_hostile_scripts():
    out = []
    cls = "hostile_scripts"
    # The Slurm script: file names, list files, the executable's path, flag values.
    for what, name in HOSTILE_NAMES:
        def folder(d, name=name):
            os.makedirs(os.path.join(d, name))
            write(os.path.join(name, "s.ply"), SPHERE_PLY)(d)
        out.append(Case(cls, f"slurm-script over a folder named with {what}", folder,
                        ["slurm-script", name, "out", "--iterations", "1"],
                        expect="ok", check=script_runs_clean()))
        mesh_name = name.replace("/", "_") + ".ply"

        def largest(d, mesh_name=mesh_name):
            os.makedirs(os.path.join(d, "in"))
            write(os.path.join("in", mesh_name), SPHERE_PLY)(d)
        out.append(Case(cls, f"slurm-script whose largest input is named with {what}", largest,
                        ["slurm-script", "in", "out", "--iterations", "1"],
                        expect="ok", check=script_runs_clean()))

        def exe(d, name=name):
            folder(d, name)
            os.symlink(BIN, os.path.join(d, name, "vcsmooth"))
        out.append(Case(cls, f"slurm-script --vcsmooth in a folder named with {what}", exe,
                        ["slurm-script", name, "out", "--iterations", "1", "--vcsmooth",
                         os.path.join(name, "vcsmooth")],
                        expect="ok", check=script_runs_clean()))
        # A flag value is UTF-8 (clap refuses the rest).
        utf8 = name.encode(errors="surrogateescape").decode("utf-8", errors="ignore") == name
        out.append(Case(cls, f"slurm-script --pin-property named with {what}", largest,
                        ["slurm-script", "in", "out", "--pin-property", name],
                        expect="ok" if utf8 else "error",
                        check=script_runs_clean(task=False) if utf8 else None))
    for flag, value in [("--partition", "debug#x"), ("--time", "1:00\n#SBATCH --x"),
                        ("--job-name", "a\\b"), ("--job-name", "a\x1bb")]:
        def setup(d):
            os.makedirs(os.path.join(d, "in"))
            write("in/s.ply", SPHERE_PLY)(d)
        out.append(Case(cls, f"slurm-script {flag} {value!r}", setup,
                        ["slurm-script", "in", "out", flag, value], expect="error"))
    # Side files through links, devices and descriptors: written where they lead.
    mesh = write("scan.ply", SPHERE_PLY)
    for flag, link, target in [("--report", "r.json", "real/r.json"),
                               ("--plot", "p.svg", "real/p.svg")]:
        def setup(d, link=link, target=target):
            mesh(d)
            os.makedirs(os.path.join(d, "real"))
            os.symlink(target, os.path.join(d, link))
        out.append(Case(cls, f"smooth {flag} through a link", setup,
                        ["smooth", "scan.ply", "out.ply", "--iterations", "2", flag, link],
                        expect="ok", output="out.ply", check=is_link_to_json(link, target)))
    for name, to in [("null", "/dev/null"), ("stdout", "/dev/stdout"), ("fd1", "/proc/self/fd/1")]:
        def setup(d, to=to):
            mesh(d)
            os.symlink(to, os.path.join(d, "r.json"))
        out.append(Case(cls, f"smooth --report through a link to {to}", setup,
                        ["smooth", "scan.ply", "out.ply", "--iterations", "2", "--report", "r.json"],
                        expect="ok", output="out.ply",
                        check=is_link_to_json("r.json", stdout=name != "null")))

    def summary(d):
        os.makedirs(os.path.join(d, "in"))
        write("in/a.ply", SPHERE_PLY)(d)
        subprocess.run([BIN, "batch", "in", "out", "--iterations", "1"], cwd=d, check=True,
                       capture_output=True)
        os.symlink("/dev/stdout", os.path.join(d, "s.json"))
    out.append(Case(cls, "batch --summary --json through a link to /dev/stdout", summary,
                    ["batch", "--summary", "out", "--json", "s.json"], expect="ok",
                    check=is_link_to_json("s.json", stdout=True)))

    def linked_output(d):
        mesh(d)
        shutil.copy(os.path.join(d, "scan.ply"), os.path.join(d, "real.ply"))
        os.symlink("real.ply", os.path.join(d, "out.ply"))
    out.append(Case(cls, "smooth into a link to a mesh", linked_output,
                    ["smooth", "scan.ply", "out.ply", "--iterations", "2"], expect="ok",
                    output="out.ply", replaces=("real.ply",),
                    check=lambda d, c, o, e: None if os.path.islink(os.path.join(d, "out.ply"))
                    else "the link was replaced"))

    def output_to_device(d):
        mesh(d)
        os.symlink("/dev/null", os.path.join(d, "out.ply"))
    out.append(Case(cls, "smooth into a link to /dev/null", output_to_device,
                    ["smooth", "scan.ply", "out.ply"], expect="error"))
    # The checkpoint directory against the run's files.
    for ck, extra in [("out.ply", []), ("out.ply/w", []), ("./sub/../out.ply", []),
                      ("scan.ply", []), ("r.json", ["--report", "r.json"]),
                      ("ck", ["--report", "ck/state.json"])]:
        def setup(d, ck=ck):
            mesh(d)
            os.makedirs(os.path.join(d, "sub"))
            if ck == "ck":
                subprocess.run([BIN, "smooth", "scan.ply", "o.ply", "--iterations", "1",
                                "--checkpoint", "ck"], cwd=d, check=True, capture_output=True)
        out.append(Case(cls, f"smooth --checkpoint {ck} {' '.join(extra)}".strip(), setup,
                        ["smooth", "scan.ply", "out.ply", "--iterations", "1", "--checkpoint", ck]
                        + extra, expect="error",
                        check=lambda d, c, o, e: "the output was written"
                        if os.path.exists(os.path.join(d, "out.ply")) else None))
    # Option combinations no run can make: one line, exit 2, for every command.
    # The methods that smooth a boundary, as `smooth` itself names them: the line every other
    # command must print.
    probe = subprocess.run([BIN, "smooth", "-", "-", "--method", "laplacian", "--boundary", "smooth"],
                           capture_output=True, text=True)
    found = re.search(r"--boundary smooth works with .*, not laplacian", probe.stderr)
    line = found.group(0) if found else "--boundary smooth works with …, not laplacian"
    bad = ["--method", "laplacian", "--boundary", "smooth"]

    def inputs(d):
        mesh(d)
        os.makedirs(os.path.join(d, "in"))
        write("in/a.ply", SPHERE_PLY)(d)
        write("in/b.ply", OCTA_PLY)(d)
    for cmd in [["smooth", "scan.ply", "out.ply"], ["smooth", "scan.ply", "out.ply", "--multires"],
                ["smooth", "scan.ply", "out.ply", "--iterations", "auto"],
                ["batch", "in", "out"], ["slurm-script", "in", "out"]]:
        out.append(Case(cls, " ".join(cmd + bad), inputs, cmd + bad, expect="error",
                        check=usage_line(line)))
    out.append(Case(cls, "curves --methods vcs,laplacian --boundary smooth", inputs,
                    ["curves", "scan.ply", "--plot", "p.svg", "--methods", "vcs,laplacian",
                     "--boundary", "smooth"], expect="error", check=usage_line(line)))
    return out


def shared_gltf(v, f, prims, nodes=None, extra=(), positions=()):
    """A sphere's glTF (`gltf_mesh`: accessor 0 the positions, 1 the indices, 2 the normals) with
    more index accessors (`extra`: triangle lists, accessors 3, 4, ... in order), more accessors
    (`positions`: dicts over accessor 0's view, after those) and these meshes' primitives (lists of
    (POSITION, indices) pairs, NORMAL 2 with POSITION 0), placed by `nodes` (one per mesh)."""
    doc, data = gltf_mesh(v, f, normals=True)
    for tris in extra:
        idx = b"".join(struct.pack("<3I", *t) for t in tris)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(data), "byteLength": len(idx),
                                   "target": 34963})
        doc["accessors"].append({"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5125,
                                 "count": 3 * len(tris), "type": "SCALAR"})
        data += idx
    doc["accessors"].extend(copy.deepcopy(list(positions)))
    doc["buffers"][0]["byteLength"] = len(data)

    def prim(pos, ind):
        attributes = {"POSITION": pos}
        if pos == 0:
            attributes["NORMAL"] = 2
        return {"attributes": attributes, "indices": ind}
    doc["meshes"] = [{"primitives": [prim(*x) for x in mesh]} for mesh in prims]
    doc["nodes"] = nodes or [{"mesh": m} for m in range(len(prims))]
    doc["scenes"] = [{"nodes": list(range(len(doc["nodes"])))}]
    return doc, data


def positions_of(doc, buffers, a):
    acc = doc["accessors"][a]
    view = doc["bufferViews"][acc["bufferView"]]
    at = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride", 12)
    return [struct.unpack_from("<3f", buffers[view["buffer"]], at + i * stride)
            for i in range(acc["count"])]


def smooths_as_one_sphere(src, dst, v, order, nf, accessors=((0, 0),)):
    """The input reads as one closed manifold sphere of `nf` triangles; smoothing it gives, bit for
    bit, what smoothing that sphere as one primitive (triangles `order`) gives, in every accessor
    of `accessors` ((accessor, its first vertex)); the output keeps the input's JSON but for
    min/max and buffer uris."""
    def check(d, code, out, err):
        if code != 0:
            return None
        i, o = os.path.join(d, src), os.path.join(d, dst)
        a = info(i)
        if a is None:
            return "the input does not read"
        if find(a, "triangles") != nf or find(a, "non_manifold_edges") != 0:
            return (f"read {find(a, 'triangles')} triangles, {find(a, 'non_manifold_edges')} "
                    f"non-manifold edges; one sphere has {nf} and 0")
        rdoc, rdata = gltf_mesh(v, order)
        ri, ro = os.path.join(d, "probe-ref.glb"), os.path.join(d, "probe-ref-out.glb")
        with open(ri, "wb") as fh:
            fh.write(glb(rdoc, rdata))
        p = subprocess.run([BIN, "smooth", ri, ro, "--iterations", "3"], capture_output=True,
                           timeout=TIMEOUT)
        if p.returncode != 0:
            return "the reference did not smooth: " + p.stderr.decode(errors="replace")[:200]
        want = positions_of(*read_gltf(ro), 0)
        if want == positions_of(rdoc, [rdata], 0):
            return "the reference did not move"
        doc, buffers = read_gltf(o)
        for acc, first in accessors:
            got = positions_of(doc, buffers, acc)
            if got != want[first:first + len(got)]:
                return f"accessor {acc} does not hold the one sphere's smoothed positions"
        indoc, _ = read_gltf(i)
        strip = lambda j: edited(j, lambda x: ([a.pop(k, None) for a in x["accessors"]
                                                for k in ("min", "max")],
                                               [b.pop("uri", None) for b in x["buffers"]]))
        if strip(doc) != strip(indoc):
            return "the output's JSON changed beyond min/max and uris: the sharing was not kept"
        return None
    return check


def cases_hostile_gltf():
    """Geometry shared between primitives and meshes: the same accessors named twice, accessors
    over the same bytes, overlapping index data, a sub-range of the positions, one index accessor
    on two position sets; in each kind of file."""
    out = []
    v, f = GLTF_SPHERE
    nv, nf = len(v), len(f)
    n = nf
    half = [dict(bufferView=0, componentType=5126, count=nv - nv // 3, type="VEC3",
                 byteOffset=12 * (nv // 3))]
    k = nv // 3
    high = [t for t in f if min(t) >= k]
    low = [t for t in f if min(t) < k]
    variants = [
        ("one primitive in two meshes", [[(0, 1)], [(0, 1)]], None, (), (), f, ((0, 0),)),
        ("one primitive twice in a mesh", [[(0, 1), (0, 1)]], None, (), (), f, ((0, 0),)),
        ("one mesh, three nodes with transforms", [[(0, 1)]],
         [{"mesh": 0}, {"mesh": 0, "scale": [2, 2, 2]},
          {"mesh": 0, "scale": [-1, 1, 1], "translation": [0, 4, 0]}], (), (), f, ((0, 0),)),
        ("overlapping index accessors", [[(0, 3)], [(0, 4)]], None,
         (f[:2 * n // 3], f[n // 3:]), (), f, ((0, 0),)),
        ("a back face on the same positions", [[(0, 1), (0, 3)]], None,
         ([(a, c, b) for a, b, c in f],), (), f, ((0, 0),)),
        ("indices within another's", [[(0, 1)], [(0, 3)]], None, (f[n // 4:n // 2],), (), f,
         ((0, 0),)),
        ("a POSITION sub-range", [[(0, 3), (5, 4)]], None,
         (low, [tuple(x - k for x in t) for t in high]), half, low + high, ((0, 0), (5, k))),
    ]
    for name, prims, nodes, extra, positions, order, accessors in variants:
        doc, data = shared_gltf(v, f, prims, nodes, extra, positions)
        for kind, setup, src, dst, new in [
                ("glb", write("m.glb", glb(doc, data)), "m.glb", "out.glb", []),
                ("gltf", gltf_files(doc, data), "m.gltf", "out.gltf", ["out.bin"]),
                ("embedded", write("e.gltf", gltf_text(doc, data_uri(data))), "e.gltf",
                 "out.gltf", [])]:
            out.append(Case("hostile_gltf", f"{name} ({kind})", setup,
                            ["smooth", src, dst, "--iterations", "3"], expect="ok", output=dst,
                            new_files=None,
                            check=smooths_as_one_sphere(src, dst, v, order, nf, accessors)))
    # Accessors over the same bytes (an exporter's copy per mesh): POSITION 3, indices 4, NORMAL 5.
    doc, data = gltf_mesh(v, f, normals=True)
    doc["accessors"] += copy.deepcopy(doc["accessors"][0:3])
    doc["meshes"].append({"primitives": [{"attributes": {"POSITION": 3, "NORMAL": 5}, "indices": 4}]})
    doc["nodes"].append({"mesh": 1})
    doc["scenes"] = [{"nodes": [0, 1]}]
    for kind, setup, src, dst in [("glb", write("m.glb", glb(doc, data)), "m.glb", "out.glb"),
                                  ("embedded", write("e.gltf", gltf_text(doc, data_uri(data))),
                                   "e.gltf", "out.gltf")]:
        out.append(Case("hostile_gltf", f"aliased accessors ({kind})", setup,
                        ["smooth", src, dst, "--iterations", "3"], expect="ok", output=dst,
                        check=smooths_as_one_sphere(src, dst, v, f, nf, ((0, 0), (3, 0)))))

    # One index accessor on two position sets (bytes of their own): two spheres, both move.
    doc, data = gltf_mesh(v, f)
    moved = b"".join(struct.pack("<3f", x + 4, y, z) for x, y, z in v)
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(data), "byteLength": len(moved)})
    doc["accessors"].append({"bufferView": 2, "componentType": 5126, "count": nv, "type": "VEC3"})
    data += moved
    doc["buffers"][0]["byteLength"] = len(data)
    doc["meshes"][0]["primitives"].append({"attributes": {"POSITION": 2}, "indices": 1})

    def two_spheres(d, code, o, e):
        a = info(os.path.join(d, "m.glb"))
        if (find(a, "vertices"), find(a, "triangles"), find(a, "non_manifold_edges")) != (2 * nv, 2 * nf, 0):
            return "not two manifold spheres"
        odoc, buffers = read_gltf(os.path.join(d, "out.glb"))
        for acc in (0, 2):
            if positions_of(odoc, buffers, acc) == positions_of(doc, [data], acc):
                return f"accessor {acc} did not move"
        return None
    out.append(Case("hostile_gltf", "one index accessor on two POSITION accessors",
                    write("m.glb", glb(doc, data)), ["smooth", "m.glb", "out.glb", "--iterations", "3"],
                    expect="ok", output="out.glb", check=two_spheres))

    # Elements overlapping out of step (4 bytes apart) cannot be one vertex each: refused.
    doc, data = shared_gltf(v, f, [[(0, 1), (4, 3)]],
                            extra=([t for t in f if max(t) < nv - 1],),
                            positions=[dict(bufferView=0, componentType=5126, count=nv - 1,
                                            type="VEC3", byteOffset=4)])
    for kind, setup, src in [("glb", write("m.glb", glb(doc, data)), "m.glb"),
                             ("gltf", gltf_files(doc, data), "m.gltf")]:
        out.append(Case("hostile_gltf", f"POSITION overlapping out of step ({kind})", setup,
                        ["smooth", src, "out" + src[1:], "--iterations", "3"], expect="error",
                        new_files=[], check=refused_naming(src, "shares bytes")))
    return out


def coloured_octahedron_ply():
    v, f = octahedron()
    cols = [(255, 0, 0), (0, 255, 0), (0, 0, 255), (10, 20, 31), (200, 201, 3), (7, 7, 7)]
    lines = ["ply", "format ascii 1.0", f"element vertex {len(v)}", "property float x",
             "property float y", "property float z", "property uchar red", "property uchar green",
             "property uchar blue", f"element face {len(f)}",
             "property list uchar int vertex_indices", "property uchar label", "end_header"]
    lines += [" ".join(repr(float(c)) for c in p) + " %d %d %d" % c for p, c in zip(v, cols)]
    lines += [f"3 {t[0]} {t[1]} {t[2]} {k}" for k, t in enumerate(f)]
    return ("\n".join(lines) + "\n").encode(), cols


def colours_kept(d, code, out, err):
    """The ASCII PLY output has the input's colours on its first vertices, a colour on every
    vertex and a label on every face; nothing is dropped (no note)."""
    text = open(os.path.join(d, "out.ply")).read()
    head, body = text.split("end_header\n", 1)
    if "property uchar red" not in head or "property uchar label" not in head:
        return "the colours or face labels were dropped"
    nv = int(re.search(r"element vertex (\d+)", head).group(1))
    rows = body.splitlines()
    cols = [tuple(int(x) for x in r.split()[3:6]) for r in rows[:nv]]
    if cols[:6] != coloured_octahedron_ply()[1]:
        return f"the input's vertices lost their colours: {cols[:6]}"
    if any(len(r.split()) != 5 for r in rows[nv:]):
        return "a face lost its label"
    if "note:" in err:
        return f"a note although nothing was dropped: {err.strip()}"
    return None


def says_dropped(what):
    def check(d, code, out, err):
        lines = [l for l in err.splitlines() if l]
        if len(lines) != 1 or not lines[0].startswith("vcsmooth: note: ") or what not in lines[0]:
            return f"no one-line note naming {what}: {err.strip()!r}"
        return None
    return check


def cases_properties():
    """Subdivision (subdivide, refine) keeps what it can interpolate and says what it drops."""
    out = []
    ply = write("in.ply", coloured_octahedron_ply()[0])
    v, f = octahedron()
    text = "".join(f"v {p[0]} {p[1]} {p[2]} 0.5 0.25 1\n" for p in v)
    text += "".join(f"f {t[0] + 1} {t[1] + 1} {t[2] + 1}\n" for t in f)
    coloured_obj = write("in.obj", text.encode())
    for cmd in [["subdivide"], ["refine", "--rounds", "2"], ["refine", "--rounds", "1", "--iterations", "0"]]:
        for delta in ["0.9", "0.2"]:
            out.append(Case("properties", f"{' '.join(cmd)} --max-edge {delta}: PLY colours", ply,
                            [cmd[0], "in.ply", "out.ply", "--max-edge", delta] + cmd[1:],
                            expect="ok", check=colours_kept, output="out.ply"))
        out.append(Case("properties", f"{' '.join(cmd)}: OBJ colours dropped with a note", coloured_obj,
                        [cmd[0], "in.obj", "out.ply", "--max-edge", "0.5"] + cmd[1:],
                        expect="ok", check=says_dropped("colours"), output="out.ply"))
    return out


def radii_within(lo, hi):
    """The output's vertex radii (about the origin) stay within [lo, hi]: a multiresolution run may
    not wreck a small sphere."""
    def check(d, code, out, err):
        text = open(os.path.join(d, "out.ply"), "rb").read()
        head, body = text.split(b"end_header\n", 1)
        nv = int(re.search(rb"element vertex (\d+)", head).group(1))
        props = re.findall(rb"property (float|double) [xyz]\b", head)
        fmt = "<" + "".join("f" if t == b"float" else "d" for t in props)
        size = struct.calcsize(fmt)
        r = [sum(c * c for c in struct.unpack_from(fmt, body, k * size)) ** 0.5 for k in range(nv)]
        if min(r) < lo or max(r) > hi:
            return f"radii {min(r):.3f}..{max(r):.3f}, outside {lo}..{hi}"
        return None
    return check


def cases_multires():
    """Multiresolution levels too coarse to carry the shape are not built (small meshes, many
    levels, coarse cells): the output stays near the input."""
    out = []
    for k in [3, 4]:
        for levels in ["3", "5", "8"]:
            for cell in ["4", "8"]:
                def setup(d, k=k):
                    medium(d, k=k)
                out.append(Case("multires", f"level-{k} sphere, --levels {levels} --cell-factor {cell}",
                                setup, ["smooth", "in.ply", "out.ply", "--multires", "--levels", levels,
                                        "--cell-factor", cell],
                                expect="either", check=radii_within(0.85, 1.15), output="out.ply"))
    return out


def flat_sheet(n=7, lift=0.0, plane=2):
    """An `n × n` grid sheet (OBJ text), its coordinate `plane` 0 on its border and `lift` inside,
    the interior wobbling in the sheet: flat (volume exactly 0) when `lift` is 0."""
    v, f = [], []
    for j in range(n):
        for i in range(n):
            inside = 0 < i < n - 1 and 0 < j < n - 1
            w = ((i * 7 + j * 3) % 5) * 0.05 if inside else 0.0
            p = [i + w, j - w]
            p.insert(plane, lift if inside else 0.0)
            v.append(tuple(p))
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            f += [(a, a + 1, a + n + 1), (a, a + n + 1, a + n)]
    return obj(v, f)


def ratios_undefined(report=None, lines=()):
    """Nothing prints a percentage of a zero volume: no `100.000000` volume, no NaN; the lines
    matching `lines` say `undefined`; the report's volume percentages are null."""
    def check(d, code, out, err):
        if re.search(r"\bNaN\b|\binf\b", out):
            return "printed NaN/inf"
        if any(re.search(r"volume 100\.0+ %", l) for l in out.splitlines() if "raised" not in l):
            return "a volume ratio against 0 printed as a number"
        for pattern in lines:
            hit = [l for l in out.splitlines() if re.search(pattern, l)]
            if not hit or any("undefined" not in l for l in hit):
                return f"lines /{pattern}/ do not say undefined: {hit}"
        if report:
            with open(os.path.join(d, report)) as fh:
                r = json.load(fh)
            pcts = [r["summary"]["volume_pct"]] + [i["volume_pct"] for i in r.get("iterations", [])]
            if any(x is not None for x in pcts):
                return f"report volume_pct not null: {pcts}"
        return None
    return check


def cases_hostile_ratios():
    """A ratio against zero (issue round three, item 12): a flat open sheet has a volume of
    exactly 0, and every volume percentage of it is undefined (`null` in JSON), on every path
    that prints one."""
    out = []
    cls = "hostile_ratios"
    for plane in (0, 2):
        sheet = write("flat.obj", flat_sheet(plane=plane))
        for method in ("vcs", "laplacian", "taubin", "vcs-lowpass"):
            for extra in ([], ["--checkpoint", "ck"], ["--stats", "last"]):
                argv = ["smooth", "flat.obj", "out.obj", "--iterations", "3", "--method", method,
                        "--report", "r.json"] + extra
                out.append(Case(cls, f"flat sheet (plane {plane}) {method} {' '.join(extra)}".strip(),
                                sheet, argv, expect="ok", output="out.obj",
                                check=ratios_undefined("r.json", [r"; volume "])))
        out.append(Case(cls, f"flat sheet (plane {plane}) multires", sheet,
                        ["smooth", "flat.obj", "out.obj", "--multires", "--iterations", "2"],
                        expect="ok", output="out.obj",
                        check=ratios_undefined(None, [r"; volume ", r"before the final correction"])))
        out.append(Case(cls, f"flat sheet (plane {plane}) curves", sheet,
                        ["curves", "flat.obj", "--iterations", "2", "--plot", "c.svg"],
                        expect="ok", check=ratios_undefined(None, [r"^\s+[0-9]+\s"])))
    both_sheets = both(write("in/flat.obj", flat_sheet()), write("in/raised.obj", flat_sheet(lift=2.0)))
    out.append(Case(cls, "batch of a flat and a raised sheet", both_sheets,
                    ["batch", "in", "o", "--iterations", "2"], expect="ok",
                    check=ratios_undefined(None, [r"flat\.ply: "])))
    return out


def cases_hostile_pins():
    """Pin files read without bounds (issue round three, item 6): devices, pipes, directories,
    binary data, endless lines, indices no mesh has, a file of 20 million lines under an
    address-space limit. Each is refused in one line naming the pin file, nothing written."""
    out = []
    cls = "hostile_pins"
    mesh = write("scan.ply", SPHERE_PLY)

    def fifo(d):
        os.mkfifo(os.path.join(d, "pins.fifo"))

    def big(d):
        with open(os.path.join(d, "big.txt"), "w") as fh:
            for start in range(0, 20_000_000, 1_000_000):
                fh.write("\n".join(map(str, range(start, start + 1_000_000))) + "\n")

    long_line = b"1\n" + b"7" * 100_000 + b"\n"
    binary = b"1\n2\n" + bytes((i * 2654435761 >> 24) & 255 for i in range(4096))
    variants = [
        ("/dev/zero", "/dev/zero", None, None),
        ("/dev/urandom", "/dev/urandom", None, None),
        ("/dev/null", "/dev/null", None, None),
        ("a directory", "sub", write("sub/x", b""), None),
        ("a FIFO", "pins.fifo", fifo, None),
        ("1 MiB of zero bytes", "zeros.txt", write("zeros.txt", bytes(1 << 20)), None),
        ("binary after two lines", "bin.txt", write("bin.txt", binary), None),
        ("a 100 kB line", "long.txt", write("long.txt", long_line), None),
        ("1 MiB of digits, no newline", "digits.txt", write("digits.txt", b"5" * (1 << 20)), None),
        ("an index from 2^32", "huge.txt", write("huge.txt", b"3\n4294967296\n"), None),
        ("20 million lines under ulimit -v 600000", "big.txt", big, 600000),
    ]
    for name, pins, setup, limit in variants:
        argv = ["smooth", "scan.ply", "out.ply", "--pin", pins]
        out.append(Case(cls, f"--pin {name}", both(mesh, setup) if setup else mesh, argv,
                        expect="error", limit_as_kb=limit, timeout=60, output="out.ply",
                        new_files=[], check=refused_naming(pins)))
    return out


def jittered_sphere(seed):
    """SPHERE with every vertex moved a little, differently for each seed: the same file size."""
    v, f = SPHERE
    rnd = random.Random(seed)
    return ply_binary([tuple(c * (1 + 0.05 * rnd.uniform(-1, 1)) for c in p) for p in v], f)


def files_equal(a, b):
    def check(d, code, out, err):
        if code != 0:
            return None
        with open(os.path.join(d, a), "rb") as fa, open(os.path.join(d, b), "rb") as fb:
            if fa.read() != fb.read():
                return f"{a} differs from {b}"
        return None
    return check


def report_says(path, key, want):
    def check(d, code, out, err):
        if code != 0:
            return None
        with open(os.path.join(d, path)) as fh:
            value = json.load(fh)
        for k in key:
            value = value[k]
        if value != want:
            return f"{'.'.join(key)} is {value!r}, should be {want!r}"
        return None
    return check


def cases_hostile_checkpoints():
    """A checkpoint is its input's by content (issue round three, item 3): a mesh of the same
    name, size and modification time in another folder is smoothed afresh, not given the first
    mesh's result; the same bytes under another name resume."""
    out = []
    cls = "hostile_checkpoints"
    smooth = ["--iterations", "3", "--checkpoint", "ck"]

    def twins(d):
        for folder, seed in (("a", 1), ("b", 2)):
            write(f"{folder}/scan.ply", jittered_sphere(seed))(d)
        stamp = os.stat(os.path.join(d, "a/scan.ply")).st_mtime_ns
        for folder in ("a", "b"):
            os.utime(os.path.join(d, folder, "scan.ply"), ns=(stamp, stamp))
        shutil.copy(os.path.join(d, "a/scan.ply"), os.path.join(d, "renamed.ply"))
        for argv in (["a/scan.ply", "a.ply"] + smooth, ["b/scan.ply", "b-plain.ply", "--iterations", "3"]):
            subprocess.run([BIN, "smooth"] + argv, cwd=d, check=True, capture_output=True)

    plan = ["ck/" + f for f in ("plan.json", "state.json", "order.u32", "triangles.u32",
                                "vv_offsets.u64", "vv.u32", "vf_offsets.u64", "vf.u32", "fixed.u8",
                                "positions-0.f64", "positions-1.f64")]
    out.append(Case(cls, "same name, size and time in another folder", twins,
                     ["smooth", "b/scan.ply", "b.ply", "--report", "r.json"] + smooth,
                     expect="ok", output="b.ply", replaces=plan + ["r.json"],
                     check=all_of(files_equal("b.ply", "b-plain.ply"),
                                  report_says("r.json", ["cluster", "resumed_after"], 0))))
    out.append(Case(cls, "the same bytes under another name resume", twins,
                     ["smooth", "renamed.ply", "r.ply", "--report", "r.json"] + smooth,
                     expect="ok", output="r.ply", replaces=["r.json"],
                     check=all_of(files_equal("r.ply", "a.ply"),
                                  report_says("r.json", ["cluster", "resumed_after"], 3))))
    return out


def float_ply_vertices(path):
    """The vertices of a binary little-endian PLY whose vertex element is `float x y z` only."""
    with open(path, "rb") as fh:
        data = fh.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    n = int(re.search(r"element vertex (\d+)", header).group(1))
    return [struct.unpack_from("<3f", data, end + 12 * i) for i in range(n)]


def within_deviation(inp, outp, bound):
    def check(d, code, out, err):
        if code != 0:
            return None
        a = float_ply_vertices(os.path.join(d, inp))
        b = float_ply_vertices(os.path.join(d, outp))
        worst = max(math.dist(p, q) for p, q in zip(a, b))
        if worst > bound:
            return f"a vertex of the file as written is {worst:.3e} from its input, beyond {bound}"
        return None
    return check


def cases_hostile_bounds():
    """`--max-deviation D` holds in the file as written (issue round three, item 10): with a
    float output, rounding on write left about half the clamped vertices beyond D."""
    out = []
    cls = "hostile_bounds"
    mesh = write("scan.ply", jittered_sphere(3))
    for method in ("laplacian", "taubin", "hc", "vcs"):
        for bound in ("5e-4", "2e-3", "1e-2"):
            out.append(Case(cls, f"{method} --max-deviation {bound}, float output", mesh,
                            ["smooth", "scan.ply", "out.ply", "--method", method, "--iterations", "10",
                             "--max-deviation", bound],
                            expect="ok", output="out.ply",
                            check=within_deviation("scan.ply", "out.ply", float(bound))))
    return out


def peak_within(path, budget):
    def check(d, code, out, err):
        if code != 0:
            return None
        with open(os.path.join(d, path)) as fh:
            peak = json.load(fh)["memory"]["peak_anon"]
        if peak > budget:
            return f"peak anonymous memory {peak / 2**20:.1f} MiB over the budget of {budget / 2**20:.0f} MiB"
        return None
    return check


def cases_hostile_budgets():
    """The memory budget counts what the tool adds (issue round three, item 7): a file of many
    unreferenced vertices, whose size says it fits in core, and the schedule of tiny patches,
    which is on the heap whatever the storage. Each run stays within its budget or is refused
    before any work."""
    out = []
    cls = "hostile_budgets"

    def crowded(d):
        v, f = SPHERE
        extra = [(5 + i % 97, i // 97 * 0.01, 7.0) for i in range(920_000)]
        write("crowded.ply", ply_binary(list(v) + extra, f))(d)

    for budget in ("64M", "80M", "128M"):
        for method in ("vcs", "taubin"):
            out.append(Case(cls, f"920k unreferenced vertices, {method}, --memory-budget {budget}",
                             crowded, ["smooth", "crowded.ply", "out.ply", "--method", method,
                                       "--iterations", "2", "--memory-budget", budget,
                                       "--report", "r.json"],
                             output="out.ply", check=peak_within("r.json", int(budget[:-1]) << 20)))
    for k, sizes in ((6, (1, 2, 4, 8)), (8, (1, 16, 64))):
        for size in sizes:
            for method in ("vcs", "taubin"):
                out.append(Case(cls, f"--patch-size {size}, {method}, 64M, {20 * 4**k} triangles",
                                 lambda d, k=k: medium(d, k=k),
                                 ["smooth", "in.ply", "out.ply", "--patch-size", str(size),
                                  "--method", method, "--iterations", "1", "--memory-budget", "64M",
                                  "--report", "r.json"],
                                 output="out.ply", timeout=60, check=all_of(
                                     peak_within("r.json", 64 << 20),
                                     refused_naming("--patch-size"))))
    return out


CLASSES = {
    "paths": cases_paths,
    "values": cases_values,
    "readers": cases_readers,
    "geometry": cases_geometry,
    "memory": cases_memory,
    "signals": cases_signals,
    "batch": cases_batch,
    "output": cases_output,
    "properties": cases_properties,
    "multires": cases_multires,
    "gltf": cases_gltf,
    "hostile_scripts": cases_hostile_scripts,
    "hostile_gltf": cases_hostile_gltf,
    "hostile_ratios": cases_hostile_ratios,
    "hostile_pins": cases_hostile_pins,
    "hostile_checkpoints": cases_hostile_checkpoints,
    "hostile_budgets": cases_hostile_budgets,
    "hostile_bounds": cases_hostile_bounds,
}


def main():
    global BIN
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default=BIN, help="the vcsmooth binary [%(default)s]")
    ap.add_argument("--only", action="append", choices=sorted(CLASSES), help="run only these classes")
    ap.add_argument("--list", action="store_true", help="list the cases and stop")
    ap.add_argument("--workdir", help="where the case folders go [a temporary folder]")
    args = ap.parse_args()
    BIN = os.path.abspath(args.bin)
    if not os.access(BIN, os.X_OK):
        sys.exit(f"hostile_probe: {BIN} is not an executable: build it (cargo build --release)")
    cases = [c for name in (args.only or CLASSES) for c in CLASSES[name]()]
    if args.list:
        for c in cases:
            print(f"{c.cls:9} {c.name}")
        return 0
    if args.workdir:
        os.makedirs(args.workdir, exist_ok=True)
    base = tempfile.mkdtemp(prefix="vcsmooth-probe-", dir=args.workdir)
    wrong = {}
    try:
        for c in cases:
            problem = run_case(c, base)
            if problem:
                wrong.setdefault(c.cls, []).append(c.name)
                print(f"WRONG {c.cls:9} {c.name}: {problem}", flush=True)
    finally:
        shutil.rmtree(base, ignore_errors=True)
    by_class = ", ".join(f"{k} {len(v)}" for k, v in sorted(wrong.items()))
    n_wrong = sum(len(v) for v in wrong.values())
    print(f"{len(cases)} cases, {n_wrong} went wrong" + (f" ({by_class})" if by_class else ""))
    return 1 if n_wrong else 0


if __name__ == "__main__":
    sys.exit(main())
