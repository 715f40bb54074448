"""smooth_file against `vcsmooth smooth` (the same bytes), and a round trip through trimesh."""

import json
import subprocess

import numpy as np
import pytest
from conftest import DATA, relative_volume_change

import vcsmooth

# (input, output extension, keyword arguments, the same as flags)
RUNS = [
    ("kitten-25k.ply", "ply", {}, []),
    ("kitten-25k.ply", "obj", dict(method="taubin", iterations=7, threads=1), ["--method", "taubin", "--iterations", "7", "--threads", "1"]),
    ("fertility-9k.ply", "stl", dict(method="vcs-triangle", crease_angle=40.0, patch_size=2048), ["--method", "vcs-triangle", "--crease-angle", "40", "--patch-size", "2048"]),
    ("demosthenes-17k.ply", "ply", dict(method="lem", max_deviation=0.01, reject_energy_increase=True, stats="last"), ["--method", "lem", "--max-deviation", "0.01", "--reject-energy-increase", "--stats", "last"]),
    ("horse.ply", "stl", dict(weld=False, iterations=2), ["--no-weld", "--iterations", "2"]),
    ("fidelity/textured.obj", "obj", dict(iterations=3, lam=0.3, mu=-0.4, method="vcs-lowpass"), ["--iterations", "3", "--lambda", "0.3", "--mu", "-0.4", "--method", "vcs-lowpass"]),
]


@pytest.mark.parametrize("name, ext, kwargs, flags", RUNS)
def test_smooth_file_writes_the_cli_bytes(tmp_path, cli, name, ext, kwargs, flags):
    source = DATA / name
    ours, theirs = tmp_path / f"py.{ext}", tmp_path / f"cli.{ext}"
    report_path = tmp_path / "py.json"
    report = vcsmooth.smooth_file(source, ours, report=report_path, **kwargs)
    subprocess.run(
        [str(cli), "smooth", str(source), str(theirs), "--report", str(tmp_path / "cli.json"), *flags],
        check=True,
        capture_output=True,
    )
    assert ours.read_bytes() == theirs.read_bytes()
    # The report: the CLI's document, with the same figures where they are not timings.
    assert json.loads(report_path.read_text()) == report
    cli_report = json.loads((tmp_path / "cli.json").read_text())
    assert report.keys() == cli_report.keys()
    for key in ("options", "engine", "plan"):
        assert report[key] == cli_report[key], key
    strip = lambda rows: [{k: v for k, v in r.items() if k != "seconds"} for r in rows]
    assert strip(report["iterations"]) == strip(cli_report["iterations"])
    assert report["output"]["stats"] == cli_report["output"]["stats"]


def test_smooth_file_and_smooth_agree(tmp_path, kitten_path):
    out = tmp_path / "out.ply"
    vcsmooth.smooth_file(kitten_path, out, iterations=5, pinned=[1, 2, 3])
    v, f = vcsmooth.read_mesh(kitten_path)
    expected = vcsmooth.smooth(v, f, iterations=5, pinned=[1, 2, 3])
    written, faces = vcsmooth.read_mesh(out)
    # The file stores the input's float32 coordinates.
    assert np.array_equal(written, expected.astype(np.float32).astype(np.float64))
    assert np.array_equal(faces, f)


def test_smooth_file_pins_and_budget(tmp_path, kitten_path):
    pins = tmp_path / "pins.txt"
    pins.write_text("# pinned\n5\n6\n")
    out = tmp_path / "out.ply"
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    report = vcsmooth.smooth_file(kitten_path, out, pin=pins, memory_budget="64M", scratch=scratch)
    assert report["engine"]["pins"] == {"file": str(pins)}
    assert report["memory"]["budget"] == 64 << 20
    v, _ = vcsmooth.read_mesh(kitten_path)
    w, _ = vcsmooth.read_mesh(out)
    assert np.array_equal(w[[5, 6]], v[[5, 6]])
    with pytest.raises(ValueError, match="memory_budget"):
        vcsmooth.smooth_file(kitten_path, out, memory_budget=1000)
    with pytest.raises(ValueError, match=r'^memory_budget must be a number of bytes, a size such as "2G", or None, got -1$'):
        vcsmooth.smooth_file(kitten_path, out, memory_budget=-1)
    with pytest.raises(ValueError, match="cannot both be given"):
        vcsmooth.smooth_file(kitten_path, out, pin=pins, pinned=[1])


def test_smooth_file_errors_leave_no_output(tmp_path, kitten_path):
    out = tmp_path / "out.ply"
    with pytest.raises(FileNotFoundError):
        vcsmooth.smooth_file(tmp_path / "missing.ply", out)
    garbage = tmp_path / "garbage.ply"
    garbage.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99\nend_header\n")
    with pytest.raises(vcsmooth.MeshError, match="garbage.ply"):
        vcsmooth.smooth_file(garbage, out)
    with pytest.raises(vcsmooth.MeshError, match=r"unknown output format '\.xyz'"):
        vcsmooth.smooth_file(kitten_path, tmp_path / "out.xyz")
    with pytest.raises(FileNotFoundError):
        vcsmooth.smooth_file(kitten_path, tmp_path / "no" / "out.ply")
    with pytest.raises(ValueError, match="report names the same file as input"):
        vcsmooth.smooth_file(kitten_path, out, report=kitten_path)
    with pytest.raises(ValueError, match="^lam must be"):
        vcsmooth.smooth_file(kitten_path, out, lam=3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["garbage.ply"]


def test_progress_lines(tmp_path, kitten_path, capsys):
    vcsmooth.smooth_file(kitten_path, tmp_path / "out.ply", iterations=3, progress=True)
    lines = capsys.readouterr().err.splitlines()
    assert [l.split(":")[1].strip() for l in lines] == ["iteration 1/3", "iteration 2/3", "iteration 3/3"]


def test_trimesh_round_trip(tmp_path, kitten):
    trimesh = pytest.importorskip("trimesh")
    v, f = kitten
    mesh = trimesh.Trimesh(vertices=v, faces=f, process=False)
    smoothed = vcsmooth.smooth(mesh.vertices, mesh.faces, iterations=10)
    assert relative_volume_change(v, smoothed, f) <= 1e-9
    result = trimesh.Trimesh(vertices=smoothed, faces=mesh.faces, process=False)
    assert abs(result.volume - mesh.volume) <= 1e-9 * abs(mesh.volume)
    # trimesh writes, vcsmooth reads; vcsmooth writes, trimesh reads.
    path = tmp_path / "trimesh.ply"
    result.export(path)
    v2, f2 = vcsmooth.read_mesh(path)
    # trimesh writes float32 or float64 coordinates, depending on its version.
    assert np.array_equal(v2, smoothed) or np.array_equal(v2, smoothed.astype(np.float32))
    assert np.array_equal(f2, f)
    path = tmp_path / "vcsmooth.ply"
    vcsmooth.write_mesh(path, smoothed, mesh.faces)
    back = trimesh.load(path, process=False)
    assert np.array_equal(back.vertices, smoothed) and np.array_equal(back.faces, f)
