"""tools/denoise_table.py: its metrics on cases with known answers, its targets, and one run
through the binary ($VCSMOOTH_CLI, else the repository's release build; skipped without one)."""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

TOOLS = Path(__file__).resolve().parents[1]
REPO = TOOLS.parent
sys.path.insert(0, str(TOOLS))
import denoise_table as dt  # noqa: E402
from compare_peers import write_ply  # noqa: E402
from quality_table import SurfaceDistance, normal_errors  # noqa: E402

SCRIPT = TOOLS / "denoise_table.py"


def rot_x(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def octahedron():
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                  [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return v, f


def test_a_face_turned_about_its_edge_has_that_angle():
    # Two faces sharing the x axis; the second one's free vertex turns 30 degrees about it.
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]], float)
    f = np.array([[0, 1, 2], [1, 0, 3]])
    out = v.copy()
    out[3] = rot_x(30) @ v[3]
    err = normal_errors(v, f, out)
    assert err == pytest.approx([0.0, 30.0], abs=1e-9)
    # The whole mesh turned: every face by the same angle.
    assert normal_errors(v, f, v @ rot_x(50).T) == pytest.approx([50.0, 50.0], abs=1e-9)


def test_a_flipped_face_is_180_degrees_and_a_degenerate_one_is_left_out():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    f = np.array([[0, 1, 2], [1, 3, 2]])
    out = v.copy()
    out[3] = [0.5, 0.5, 0]  # face 1 collapses onto the hypotenuse: no normal
    assert normal_errors(v, f, out) == pytest.approx([0.0])
    out = v.copy()
    out[3] = [0, 0, 0]  # face 1 now winds the other way
    assert normal_errors(v, f, out) == pytest.approx([0.0, 180.0])


@pytest.mark.parametrize("cell", [0.05, 10.0])  # far points searched over all triangles / the grid
def test_distance_to_a_triangle_in_each_region(cell):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2]])
    p = np.array([
        [0.2, 0.2, 0.7],   # over the interior: its height
        [0.2, 0.2, -0.3],  # under it
        [0.5, -1.0, 0.0],  # beyond edge AB
        [1.0, 1.0, 0.0],   # beyond the hypotenuse, at (0.5, 0.5)
        [2.0, 0.0, 0.0],   # beyond vertex B
        [-3.0, -4.0, 0.0],  # beyond vertex A
        [0.1, 0.1, 0.0],   # on it
    ])
    d = SurfaceDistance(v, f, cell=cell).query(p)
    assert d == pytest.approx([0.7, 0.3, 1.0, math.sqrt(0.5), 1.0, 5.0, 0.0], abs=1e-12)


def test_a_pair_measures_its_clean_mesh_as_exact_and_a_shifted_copy_by_the_shift(tmp_path):
    v, f = octahedron()
    write_ply(tmp_path / "o-clean.ply", v, f)
    write_ply(tmp_path / "o-noisy.ply", v * 1.1, f)
    pair = dt.Pair("o", str(tmp_path / "o-clean.ply"), str(tmp_path / "o-noisy.ply"), False)
    assert pair.closed and pair.kind == "organic"
    assert pair.diag == pytest.approx(2 * math.sqrt(3))
    m = pair.measure(v)
    assert m["nerr"] == pytest.approx(0.0, abs=1e-6)
    assert m["dist"] == pytest.approx(0.0, abs=1e-12)
    assert m["dvol"] == pytest.approx(1 / 1.1 ** 3 - 1)  # against the noisy volume
    # Every vertex 0.25 above the clean surface (a vertex of the octahedron is nearest to itself).
    m = pair.measure(v * 1.25)
    assert m["dist"] == pytest.approx(0.25 / pair.diag)
    assert m["maxdist"] == pytest.approx(0.25 / pair.diag)
    assert m["nerr"] == pytest.approx(0.0, abs=1e-6)
    with pytest.raises(dt.ToolError):
        pair.measure(v, f[::-1])  # not the same triangles
    bad = v.copy()
    bad[0, 0] = np.nan
    with pytest.raises(dt.ToolError):
        pair.measure(bad)


def test_an_open_mesh_is_open():
    v, f = octahedron()
    assert dt.is_closed(f)
    assert not dt.is_closed(f[1:])


def rows():
    def row(name, kind, closed, new, base, dvol=1e-12):
        return {"pair": name, "kind": kind, "closed": closed, "cells": {
            "new": {"nerr": new, "dist": 1.0, "dvol": -dvol},
            "taubin": {"nerr": base, "dist": 2.0, "dvol": 1e-3},
            "peer": {"error": "not installed"}}}
    return [row("A", "machined", True, 5.0, 10.0), row("B", "machined", True, 7.0, 10.0),
            row("C", "organic", False, 20.0, 10.0, dvol=1e-3)]


LABELS = ["noisy", "new", "taubin", "peer"]


def check(text):
    t = dt.parse_target(text, LABELS, ["A", "B", "C"])
    return dt.check_target(t, rows())


def test_targets_compare_columns_on_the_pairs_of_their_scope():
    res = check("machined:new<=0.6*taubin")
    assert [(r["pair"], r["pass"]) for r in res] == [("A", True), ("B", False)]
    assert res[1]["lhs"] == 7.0 and res[1]["rhs"] == pytest.approx(6.0)
    assert all(r["pass"] for r in check("machined:new<=0.7*taubin"))
    assert [r["pass"] for r in check("new.dist<taubin")] == [True, True, True]
    assert [r["pass"] for r in check("new.dist<taubin.nerr")] == [True, True, True]
    assert [r["pair"] for r in check("B,C:new>=taubin")] == ["B", "C"]
    # dvol is compared as |dV|/V
    assert [r["pass"] for r in check("closed:new.dvol<=1e-9")] == [True, True]
    assert [r["pass"] for r in check("new.dvol<=1e-9")] == [True, True, False]
    assert [r["pass"] for r in check("open:new.dvol>1e-9")] == [True]


def test_a_target_on_a_missing_cell_fails_and_says_why():
    res = check("new<=peer")
    assert not any(r["pass"] for r in res)
    assert res[0]["missing"] == "not installed"


@pytest.mark.parametrize("bad", ["new", "new<=", "nosuch<=1", "new.nosuch<=1", "moulded:new<=1",
                                 "new<=x*taubin", "new<=0.5*nosuch"])
def test_a_malformed_target_is_an_error(bad):
    with pytest.raises(dt.ToolError):
        dt.parse_target(bad, LABELS, ["A", "B", "C"])


# --------------------------------------------------------------------------------------------
# through the binary

def binary():
    given = os.environ.get("VCSMOOTH_CLI")
    if given:
        return Path(given)
    p = REPO / "target" / "release" / "vcsmooth"
    if not p.is_file():
        pytest.skip("no vcsmooth binary: cargo build --release, or set VCSMOOTH_CLI")
    return p


@pytest.fixture(scope="module")
def pairs(tmp_path_factory):
    d = tmp_path_factory.mktemp("pairs")
    for extra, name in (([], "s-clean.ply"), (["--noise", "0.4", "--seed", "3"], "s-noisy.ply")):
        subprocess.run([binary(), "generate", "sphere", d / name, "--subdivisions", "3", *extra],
                       check=True, capture_output=True)
    return d


def tool(*args):
    return subprocess.run([sys.executable, SCRIPT, *map(str, args)], capture_output=True, text=True)


def test_the_table_through_the_binary(pairs, tmp_path):
    out = tmp_path / "t.json"
    r = tool("--dir", pairs, "--binary", binary(), "--no-peers", "--json", out, "--check",
             "--column", "lowpass10=--method vcs-lowpass --iterations 10",
             "--peer", "gone=trimesh:taubin", "--peers-python", "/bin/false",
             "--target", "closed:vcs.dvol<=1e-9", "--target", "taubin<0.5*noisy",
             "--target", "lowpass10.iterations<=10")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "| s | " in r.stdout and "PASS closed:vcs.dvol<=1e-9" in r.stdout
    doc = json.loads(out.read_text())
    (row,) = doc["pairs"]
    assert row["closed"] and row["vertices"] == 642
    cells = row["cells"]
    assert cells["noisy"]["nerr"] > 2 * cells["taubin"]["nerr"] > 0
    assert abs(cells["vcs"]["dvol"]) <= 1e-9 and abs(cells["taubin"]["dvol"]) > 1e-9
    assert cells["auto"]["iterations"] >= 1 and cells["auto"]["stopped_by"]
    assert cells["lowpass10"]["iterations"] == 10
    assert "error" in cells["gone"]  # a peer that cannot run is a note, not a crash
    assert [t["pass"] for t in doc["targets"]] == [True, True, True]

    # A target that cannot hold: exit 1 with --check, 0 without.
    args = ["--dir", pairs, "--binary", binary(), "--no-peers", "--no-default-columns",
            "--column", "t=--method taubin --iterations 2", "--target", "t<=0.01*noisy"]
    r = tool(*args, "--check")
    assert r.returncode == 1 and "FAIL t<=0.01*noisy" in r.stdout
    assert tool(*args).returncode == 0


def test_bad_input_is_one_line(pairs, tmp_path):
    for args in (["--pairs", "nosuch"], ["--target", "nosuch<=1"]):
        r = tool("--dir", pairs, "--binary", binary(), "--no-peers", *args)
        assert r.returncode != 0 and r.stderr.count("\n") == 1, r.stderr
        assert r.stderr.startswith("denoise_table: error: ")
    # a run that fails is an ERROR cell and a failed --check, the other columns still run
    r = tool("--dir", pairs, "--binary", binary(), "--no-peers", "--no-default-columns",
             "--column", "bad=--method nosuch", "--column", "ok=--iterations 1", "--check")
    assert r.returncode == 1 and "ERROR s bad" in r.stdout
    assert "n/a" in r.stdout
