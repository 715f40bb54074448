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
The classes follow issue #17: paths, values, readers, geometry, memory, signals, batch, output.
Only the Python standard library is needed.
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import math
import os
import re
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time

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
                 limit_as_kb=None, timeout=None, output=None):
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
    for p, h in before.items():
        # The output is the command's to replace; a stale temporary of it is its to remove.
        if p == output or re.search(r"\.tmp-", os.path.basename(p)):
            continue
        if after.get(p) != h:
            return f"{os.path.relpath(p, d)} was changed or removed"
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


CLASSES = {
    "paths": cases_paths,
    "values": cases_values,
    "readers": cases_readers,
    "geometry": cases_geometry,
    "memory": cases_memory,
    "signals": cases_signals,
    "batch": cases_batch,
    "output": cases_output,
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
