"""smooth, smooth_report, info, read_mesh and write_mesh on arrays: the engine's results, any
layout, and every bad input as a Python exception."""

import numpy as np
import pytest
from conftest import DATA, relative_volume_change

import vcsmooth

STENCIL_METHODS = ["vcs", "vcs-triangle", "vcs-lowpass", "vcs-guided"]
ALL_METHODS = list(vcsmooth.METHODS)


@pytest.mark.parametrize("method", STENCIL_METHODS)
@pytest.mark.parametrize("scan", ["kitten-25k.ply", "fertility-9k.ply"])
def test_volume_kept_on_closed_scans(method, scan):
    v, f = vcsmooth.read_mesh(DATA / scan)
    out = vcsmooth.smooth(v, f, method=method, iterations=20)
    assert relative_volume_change(v, out, f) <= 1e-9
    assert not np.array_equal(out, v)


def test_laplacian_shrinks(kitten):
    v, f = kitten
    out = vcsmooth.smooth(v, f, method="laplacian", iterations=20)
    assert relative_volume_change(v, out, f) > 1e-3


def test_inputs_are_not_modified(kitten):
    v, f = kitten
    v0, f0 = v.copy(), f.copy()
    vcsmooth.smooth(v, f, iterations=2)
    assert np.array_equal(v, v0) and np.array_equal(f, f0)


@pytest.mark.parametrize("method", ALL_METHODS)
def test_any_thread_count_gives_the_same_bits(kitten, method):
    v, f = kitten
    # Small patches: many of them run in parallel.
    runs = [
        vcsmooth.smooth(v, f, method=method, iterations=3, threads=t, patch_size=1024)
        for t in (1, 2, 3, None)
    ]
    for r in runs[1:]:
        assert np.array_equal(r, runs[0])


def test_report_and_smooth_agree(kitten):
    v, f = kitten
    plain = vcsmooth.smooth(v, f, iterations=4)
    out, report = vcsmooth.smooth_report(v, f, iterations=4, threads=1)
    assert np.array_equal(out, plain)
    assert report["command"] == "smooth"
    assert report["options"]["method"] == vcsmooth.DEFAULT_METHOD
    assert [r["iteration"] for r in report["iterations"]] == [1, 2, 3, 4]
    assert abs(report["summary"]["volume_pct"] - 100) < 1e-7
    assert report["iterations"][-1]["stencils"]["applied"] > 0
    assert report["input"]["path"] == "<memory>"
    assert report["input"]["stats"]["vertices"] == len(v)
    assert report["engine"]["threads"] == 1


def test_report_statistics_of_the_last_iteration_only(kitten):
    v, f = kitten
    out, report = vcsmooth.smooth_report(v, f, iterations=3, stats="last")
    rows = report["iterations"]
    assert rows[0]["volume_pct"] is None and rows[-1]["volume_pct"] is not None
    assert np.array_equal(out, vcsmooth.smooth(v, f, iterations=3, stats="every"))


def test_pinned_vertices_do_not_move(kitten):
    v, f = kitten
    rng = np.random.default_rng(1)
    pinned = rng.choice(len(v), size=500, replace=False)
    by_index = vcsmooth.smooth(v, f, pinned=pinned)
    assert np.array_equal(by_index[pinned], v[pinned])
    free = np.setdiff1d(np.arange(len(v)), pinned)
    assert np.all(np.any(by_index[free] != v[free], axis=1).mean() > 0.9)
    mask = np.zeros(len(v), dtype=bool)
    mask[pinned] = True
    assert np.array_equal(vcsmooth.smooth(v, f, pinned=mask), by_index)
    # Any integer type, duplicates allowed; the volume stays exact.
    again = vcsmooth.smooth(v, f, pinned=np.concatenate([pinned, pinned]).astype(np.uint32))
    assert np.array_equal(again, by_index)
    assert relative_volume_change(v, by_index, f) <= 1e-9


def test_boundary_vertices_do_not_move():
    v, f = vcsmooth.read_mesh(DATA / "demosthenes-17k.ply")
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    boundary = np.unique(unique[count == 1])
    assert len(boundary) > 0
    out = vcsmooth.smooth(v, f, iterations=5)
    assert np.array_equal(out[boundary], v[boundary])


def test_split_corners_are_welded_unless_asked_not_to(kitten):
    v, f = kitten
    # Every corner its own vertex, as an unmerged STL or a seamed texture layout gives it.
    soup_v, soup_f = v[f.reshape(-1)], np.arange(3 * len(f)).reshape(-1, 3)
    indexed = vcsmooth.smooth(v, f, method="taubin", iterations=3)
    welded = vcsmooth.smooth(soup_v, soup_f, method="taubin", iterations=3)
    assert np.allclose(welded, indexed[f.reshape(-1)], rtol=0, atol=1e-12)
    default = vcsmooth.smooth(soup_v, soup_f, iterations=3)
    assert relative_volume_change(soup_v, default, soup_f) <= 1e-9
    assert np.all(np.any(default != soup_v, axis=1))
    apart = vcsmooth.smooth(soup_v, soup_f, iterations=3, weld=False)
    assert np.array_equal(apart, soup_v)
    # Corners rounded apart (kitten's edges are about 0.5 long): welded within a tolerance only.
    rounded = soup_v + (np.arange(len(soup_v)) % 3)[:, None] * np.array([1e-6, -1e-6, 5e-7])
    assert np.array_equal(vcsmooth.smooth(rounded, soup_f, iterations=3), rounded)
    within = vcsmooth.smooth(rounded, soup_f, iterations=3, weld_tolerance=1e-4)
    assert np.all(np.any(within != rounded, axis=1))
    with pytest.raises(ValueError, match="weld_tolerance"):
        vcsmooth.smooth(rounded, soup_f, weld_tolerance=-1.0)
    with pytest.raises(ValueError, match="weld_tolerance"):
        vcsmooth.smooth(rounded, soup_f, weld_tolerance=1e-4, weld=False)


def test_crease_angle_and_max_deviation(kitten):
    v, f = kitten
    out = vcsmooth.smooth(v, f, max_deviation=0.01)
    assert np.linalg.norm(out - v, axis=1).max() <= 0.01 + 1e-12
    assert relative_volume_change(v, out, f) <= 1e-9
    creased = vcsmooth.smooth(v, f, crease_angle=20)
    assert not np.array_equal(creased, vcsmooth.smooth(v, f))


def test_float32_fortran_and_strided_inputs(kitten):
    v, f = kitten
    v32 = v.astype(np.float32)
    expected = vcsmooth.smooth(v32.astype(np.float64), f, iterations=3)
    assert np.array_equal(vcsmooth.smooth(v32, f, iterations=3), expected)
    assert np.array_equal(vcsmooth.smooth(np.asfortranarray(v32), f, iterations=3), expected)
    wide = np.zeros((len(v), 6), dtype=np.float32)
    wide[:, ::2] = v32
    assert np.array_equal(vcsmooth.smooth(wide[:, ::2], f, iterations=3), expected)
    for faces in (
        f.astype(np.int32),
        f.astype(np.uint16),
        f.astype(np.uint64),
        np.asfortranarray(f),
        f[::-1][::-1],
        f.tolist(),
    ):
        assert np.array_equal(vcsmooth.smooth(v32, faces, iterations=3), expected)


def test_info_matches_the_mesh(kitten_path):
    v, f = vcsmooth.read_mesh(kitten_path)
    info = vcsmooth.info(v, f)
    assert info["path"] == "<memory>"
    assert (info["vertices"], info["triangles"], info["closed"]) == (len(v), len(f), True)
    assert info["boundary_edges"] == 0 and info["volume"] > 0
    empty = vcsmooth.info(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    assert empty["vertices"] == 0 and empty["bbox_diagonal"] is None


@pytest.mark.parametrize("ext", ["ply", "obj", "off", "stl"])
def test_write_then_read(tmp_path, kitten, ext):
    v, f = kitten
    path = tmp_path / f"mesh.{ext}"
    vcsmooth.write_mesh(path, v, f)
    v2, f2 = vcsmooth.read_mesh(str(path))
    assert v2.dtype == np.float64 and f2.dtype == np.int64
    if ext == "stl":
        # STL stores float32 corners; the reader merges equal ones.
        assert len(f2) == len(f)
        return
    # Double precision where float32 would round: the same float64 values back.
    assert np.array_equal(f2, f) and np.array_equal(v2, v)
    v32 = v.astype(np.float32)
    vcsmooth.write_mesh(path, v32, f)
    back = vcsmooth.read_mesh(path)[0]
    # Text holds the shortest decimals that read back to the same float32.
    assert np.array_equal(back if ext == "ply" else back.astype(np.float32), v32)


# Bad inputs: each raises, names what is wrong, and never crashes.

def bad(kind, match, *args, **kwargs):
    with pytest.raises(kind, match=match):
        vcsmooth.smooth(*args, **kwargs)


def test_bad_shapes_and_dtypes(kitten):
    v, f = kitten
    bad(ValueError, r"vertices must have shape \(n, 3\), got \(12623, 2\)", v[:, :2], f)
    bad(ValueError, r"vertices must have shape", v.ravel(), f)
    bad(ValueError, r"vertices must have shape", v[:, :, None], f)
    bad(ValueError, r"faces must have shape \(m, 3\), or \(m, k\) for polygons of k > 3 corners, got \(25246, 2\)", v, f[:, :2])
    bad(ValueError, r"faces must have shape \(n, 3\), got \(25246,\)", v, f[:, 0])
    bad(ValueError, r"vertices must be float32 or float64.*int64", v.astype(np.int64), f)
    bad(ValueError, r"vertices must be float32 or float64.*complex", v.astype(complex), f)
    bad(ValueError, r"vertices must be float32 or float64", v.astype(">f8"), f)
    bad(ValueError, r"faces must be of an integer type, got float64", v, f.astype(float))
    bad(ValueError, r"faces must be of an integer type, got bool", v, f > 5)


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_coordinates_that_are_not_finite(kitten, value):
    v, f = kitten
    w = v.copy()
    w[77, 2] = value
    bad(ValueError, r"vertices\[77\] is not finite", w, f)
    bad(ValueError, r"vertices\[77\] is not finite", w.astype(np.float32), f)


def test_indices_out_of_range(kitten):
    v, f = kitten
    g = f.copy()
    g[10, 1] = len(v)
    bad(ValueError, rf"faces\[10, 1\] = {len(v)} is out of range", v, g)
    g[10, 1] = -1
    bad(ValueError, r"faces\[10, 1\] = -1 is out of range", v, g)
    bad(ValueError, rf"pinned vertex index {len(v)} is out of range", v, f, pinned=[3, len(v)])
    bad(ValueError, r"pinned vertex index -2 is out of range", v, f, pinned=[-2])
    bad(ValueError, r"pinned has 5 flags for a mesh of 12623 vertices", v, f, pinned=np.ones(5, bool))
    bad(ValueError, r"pinned must be vertex indices", v, f, pinned=[0.5])
    with pytest.raises(ValueError, match=r"faces\[0, 0\]"):
        vcsmooth.info(v, f + len(v))
    with pytest.raises(ValueError, match=r"faces\[0, 0\]"):
        vcsmooth.write_mesh("never.ply", v, f + len(v))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(lam=0), r"^lam must be in \(0, 1\]"),
        (dict(lam=1.5), r"^lam must be in"),
        (dict(mu=0.1), r"^mu must be in \[-1, 0\)"),
        (dict(crease_angle=200), r"^crease_angle must be in \(0, 180\)"),
        (dict(max_deviation=-1), r"^max_deviation must be"),
        (dict(max_deviation=float("nan")), r"^max_deviation must be"),
        (dict(threads=0), r"^threads must be in 1..=4096"),
        (dict(threads=5000), r"^threads must be in 1..=4096"),
        (dict(patch_size=0), r"^patch_size must be in"),
        (dict(iterations=-1), r'^iterations must be a non-negative integer or "auto", got -1$'),
        (dict(iterations=10**30), r'^iterations must be a non-negative integer or "auto", got 1000000000000000000000000000000$'),
        (dict(threads=-2), r"^threads must be a positive integer or None, got -2$"),
        (dict(patch_size=-5), r"^patch_size must be a positive integer, got -5$"),
        (dict(method="smoothest"), r"unknown method 'smoothest'"),
        (dict(stats="some"), r"stats must be 'every' or 'last'"),
    ],
)
def test_options_out_of_range(kitten, kwargs, match):
    v, f = kitten
    bad(ValueError, match, v, f, **kwargs)


def test_wrong_keywords_and_types(kitten):
    v, f = kitten
    bad(TypeError, r"smooth\(\) got an unexpected keyword argument 'lambda'", v, f, **{"lambda": 0.5})
    bad(TypeError, r"unexpected keyword argument 'memory_budget'", v, f, memory_budget="1G")
    bad(TypeError, r'^iterations must be a non-negative integer or "auto", got 2.5$', v, f, iterations=2.5)
    # A bool is an int to Python, but never a count.
    bad(TypeError, r'^iterations must be a non-negative integer or "auto", got True$', v, f, iterations=True)
    bad(ValueError, r'^iterations must be a non-negative integer or "auto", got \'ten\'$', v, f, iterations="ten")
    bad(TypeError, r"^method must be one of vcsmooth.METHODS, got 3$", v, f, method=3)
    bad(TypeError, r"^lam must be a number, got 'x'$", v, f, lam="x")
    bad(TypeError, r"^weld must be True or False, got 'no'$", v, f, weld="no")
    bad(TypeError, r'^stats must be "every" or "last", got 1$', v, f, stats=1)
    # NumPy's integers are counts.
    assert np.array_equal(vcsmooth.smooth(v, f, iterations=np.int64(2)), vcsmooth.smooth(v, f, iterations=2))
    with pytest.raises(TypeError, match=r"smooth_report\(\) got an unexpected keyword argument 'report'"):
        vcsmooth.smooth_report(v, f, report="r.json")


def test_mesh_error_is_a_value_error():
    assert issubclass(vcsmooth.MeshError, ValueError)
    assert vcsmooth.MeshError.__module__ == "vcsmooth"


def test_unreadable_files(tmp_path, kitten_path):
    with pytest.raises(FileNotFoundError):
        vcsmooth.read_mesh(tmp_path / "missing.ply")
    with pytest.raises(IsADirectoryError):
        vcsmooth.read_mesh(tmp_path)
    garbage = tmp_path / "garbage.ply"
    garbage.write_bytes(b"this is not a mesh\n" * 10)
    with pytest.raises(vcsmooth.MeshError, match="garbage.ply"):
        vcsmooth.read_mesh(garbage)
    truncated = tmp_path / "truncated.ply"
    truncated.write_bytes(kitten_path.read_bytes()[:100_000])
    with pytest.raises(vcsmooth.MeshError, match="truncated.ply"):
        vcsmooth.read_mesh(truncated)


def test_unwritable_outputs(tmp_path, kitten):
    v, f = kitten
    with pytest.raises(FileNotFoundError):
        vcsmooth.write_mesh(tmp_path / "no" / "dir.ply", v, f)
    with pytest.raises(vcsmooth.MeshError, match="unknown output format '.xyz'"):
        vcsmooth.write_mesh(tmp_path / "mesh.xyz", v, f)
    assert list(tmp_path.iterdir()) == []


def test_iterations_auto_stops_when_the_noise_is_gone(kitten):
    v, f = kitten
    rng = np.random.default_rng(3)
    noisy = v + rng.normal(scale=0.3, size=v.shape)
    out, report = vcsmooth.smooth_report(noisy, f, iterations="auto")
    ran = report["iterations_run"]
    assert 1 <= ran < 100 and len(report["iterations"]) == ran
    assert report["auto_stop"]["cap"] == 100
    assert report["auto_stop"]["stopped_by"] in ("detail", "noise-removed")
    # The same run as a count gives the same positions.
    assert np.array_equal(out, vcsmooth.smooth(noisy, f, iterations=ran))
    assert relative_volume_change(noisy, out, f) <= 1e-9


def test_boundary_smooth_moves_the_rims_and_refuses_the_jacobi_methods():
    v, f = vcsmooth.read_mesh(DATA / "demosthenes-17k.ply")
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    rim = np.unique(unique[count == 1])
    out = vcsmooth.smooth(v, f, method="vcs", iterations=3, boundary="smooth")
    assert np.any(out[rim] != v[rim])
    fixed = vcsmooth.smooth(v, f, method="vcs", iterations=3, boundary="fixed")
    assert np.array_equal(fixed[rim], v[rim])
    default = vcsmooth.smooth(v, f, iterations=3, boundary="smooth")
    assert np.any(default[rim] != v[rim])
    with pytest.raises(ValueError, match="boundary"):
        vcsmooth.smooth(v, f, method="taubin", boundary="smooth")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(iterations="sometimes"), r'iterations must be a non-negative integer or "auto"'),
        (dict(boundary="wavy"), r"boundary: unknown boundary mode 'wavy'"),
    ],
)
def test_new_options_out_of_range(kitten, kwargs, match):
    v, f = kitten
    bad(ValueError, match, v, f, **kwargs)
