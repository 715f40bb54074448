"""Mesh objects in and out (trimesh, Open3D, PyVista, and an Open3D-shaped stand-in) and
polygons, fan-triangulated as the file readers do."""

import copy
import importlib
import importlib.util

import numpy as np
import pytest
from conftest import DATA, relative_volume_change

import vcsmooth


def optional(name):
    """The library `name`, or a skip when it is not installed. Installed but failing to import
    (a missing system library) is an error, not a skip: CI installs them all."""
    if importlib.util.find_spec(name) is None:
        pytest.skip(f"{name} is not installed")
    return importlib.import_module(name)


@pytest.fixture(scope="module")
def sphere():
    """A closed triangle mesh with noise: every vertex moves."""
    v, f = vcsmooth.read_mesh(DATA / "fertility-9k.ply")
    v = v + np.random.default_rng(5).normal(scale=0.2, size=v.shape)
    return v, f


def quad_box(n=6, noise=0.02, seed=7):
    """A closed box of n x n quads on each side, with noise: (vertices, (m, 4) quads), the quads
    counter-clockwise seen from outside."""
    grid = np.linspace(-1, 1, n + 1)
    index, points, quads = {}, [], []

    def vertex(p):
        key = tuple(np.round(p, 9))
        if key not in index:
            index[key] = len(points)
            points.append(p)
        return index[key]

    for axis in range(3):
        for sign in (-1.0, 1.0):
            u, w = [a for a in range(3) if a != axis]
            for i in range(n):
                for j in range(n):
                    corners = []
                    for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        p = np.zeros(3)
                        p[axis], p[u], p[w] = sign, grid[i + di], grid[j + dj]
                        corners.append(vertex(p))
                    # Outward: the (u, w) frame is right-handed with the axis for these signs.
                    right_handed = (w - u) % 3 == 1 if axis != 1 else (u, w) == (2, 0)
                    if (sign > 0) != right_handed:
                        corners.reverse()
                    quads.append(corners)
    v = np.array(points) + np.random.default_rng(seed).normal(scale=noise, size=(len(points), 3))
    return v, np.array(quads, dtype=np.int64)


def read_as_the_readers_do(tmp_path, v, polygons):
    """(vertices, triangles) of an OBJ file with these polygons, as vcsmooth.read_mesh reads it."""
    path = tmp_path / "polygons.obj"
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in v]
    lines += ["f " + " ".join(str(i + 1) for i in p) for p in polygons]
    path.write_text("\n".join(lines) + "\n")
    return vcsmooth.read_mesh(path)


# Polygons as arrays.

def test_quads_are_fanned_as_the_readers_do(tmp_path):
    v, quads = quad_box()
    rv, triangles = read_as_the_readers_do(tmp_path, v, quads)
    assert np.array_equal(rv, v) and len(triangles) == 2 * len(quads)
    out = vcsmooth.smooth(v, quads, iterations=5)
    assert np.array_equal(out, vcsmooth.smooth(v, triangles, iterations=5))
    assert not np.array_equal(out, v)
    assert relative_volume_change(v, out, triangles) <= 1e-9
    info = vcsmooth.info(v, quads)
    assert info["triangles"] == 2 * len(quads) and info["closed"]
    # Any integer type, as for triangles.
    assert np.array_equal(vcsmooth.smooth(v, quads.astype(np.uint16), iterations=5), out)


def test_polygons_of_mixed_sizes_in_a_list(tmp_path):
    v, quads = quad_box(n=3)
    # Some quads split into their two triangles: rows of different lengths.
    polygons = []
    for i, q in enumerate(quads.tolist()):
        if i % 3 == 0:
            polygons += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
        else:
            polygons.append(q)
    _, triangles = read_as_the_readers_do(tmp_path, v, polygons)
    out = vcsmooth.smooth(v, polygons, iterations=4)
    assert np.array_equal(out, vcsmooth.smooth(v, triangles, iterations=4))
    assert vcsmooth.info(v, polygons)["closed"]


def test_a_pentagon_fans_from_its_first_corner(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [1.5, 1, 0], [0.5, 1.8, 0], [-0.5, 1, 0], [0.4, 0.8, 1]])
    polygons = [[0, 1, 2, 3, 4], [0, 1, 5]]
    _, triangles = read_as_the_readers_do(tmp_path, v, polygons)
    assert triangles[:3].tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4]]
    assert vcsmooth.info(v, polygons)["triangles"] == 4


def test_bad_polygons_are_named(sphere):
    v, quads = quad_box(n=2)
    bad = quads.copy()
    bad[3, 2] = len(v)
    with pytest.raises(ValueError, match=rf"^faces\[3, 2\] = {len(v)} is out of range: vertices has {len(v)} rows$"):
        vcsmooth.smooth(v, bad)
    with pytest.raises(ValueError, match=r"faces must be of an integer type, got float64"):
        vcsmooth.smooth(v, quads.astype(float))
    with pytest.raises(ValueError, match=r"^faces\[1\] has 2 corners"):
        vcsmooth.smooth(v, [[0, 1, 2], [0, 1], [1, 2, 3, 4]])


def test_arrays_or_a_mesh_not_both(sphere):
    v, f = sphere
    with pytest.raises(TypeError, match=r"smooth\(\) takes \(vertices, faces\) arrays or a mesh object"):
        vcsmooth.smooth(v)
    trimesh = optional("trimesh")
    mesh = trimesh.Trimesh(v, f, process=False)
    with pytest.raises(TypeError, match=r"smooth_report\(\) takes faces only with a vertices array"):
        vcsmooth.smooth_report(mesh, f)


# trimesh.

def test_trimesh_in_and_out(sphere):
    trimesh = optional("trimesh")
    v, f = sphere
    uv = np.random.default_rng(2).random((len(v), 2))
    mesh = trimesh.Trimesh(v, f, process=False, visual=trimesh.visual.TextureVisuals(uv=uv))
    volume = mesh.volume
    out = vcsmooth.smooth(mesh, iterations=6, method="vcs")
    assert type(out) is type(mesh) and out is not mesh
    assert np.array_equal(out.vertices, vcsmooth.smooth(v, f, iterations=6, method="vcs"))
    assert np.array_equal(out.faces, f)
    assert np.array_equal(out.visual.uv, uv)
    # Its caches follow: the volume is the new positions' (kept), the normals are new.
    assert abs(out.volume - volume) <= 1e-9 * abs(volume)
    assert not np.allclose(out.vertex_normals, mesh.vertex_normals)
    # The input is untouched.
    assert np.array_equal(mesh.vertices, v) and mesh.volume == volume

    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=np.tile([10, 200, 30, 255], (len(v), 1)))
    result, report = vcsmooth.smooth_report(mesh, iterations=2)
    assert isinstance(result, trimesh.Trimesh)
    assert np.array_equal(result.visual.vertex_colors, mesh.visual.vertex_colors)
    assert report["input"]["stats"]["vertices"] == len(v)
    assert vcsmooth.info(mesh)["vertices"] == len(v)


# Open3D, the real one and a stand-in of the same shape.

class Vectors:
    """Open3D's Vector3dVector / Vector3iVector as far as vcsmooth uses them: made from an
    (n, 3) array, read by numpy.asarray."""

    def __init__(self, array=None):
        self.array = np.zeros((0, 3)) if array is None else np.array(array)

    def __array__(self, dtype=None, copy=None):
        return self.array if dtype is None else self.array.astype(dtype)

    def __len__(self):
        return len(self.array)


class StandInTriangleMesh:
    """The attributes of open3d.geometry.TriangleMesh that vcsmooth reads, and one it must keep."""

    def __init__(self, vertices, triangles, colours):
        self.vertices = Vectors(vertices)
        self.triangles = Vectors(triangles.astype(np.int32))
        self.vertex_colors = Vectors(colours)


def test_open3d_shaped_stand_in(sphere):
    v, f = sphere
    colours = np.random.default_rng(3).random((len(v), 3))
    mesh = StandInTriangleMesh(v, f, colours)
    out = vcsmooth.smooth(mesh, iterations=4)
    assert type(out) is StandInTriangleMesh and out is not mesh
    assert type(out.vertices) is Vectors
    assert np.array_equal(np.asarray(out.vertices), vcsmooth.smooth(v, f, iterations=4))
    assert np.array_equal(np.asarray(out.triangles), f)
    assert np.array_equal(np.asarray(out.vertex_colors), colours)
    # A deep copy: the input's arrays are not the output's.
    assert np.array_equal(np.asarray(mesh.vertices), v)
    assert out.vertex_colors.array is not mesh.vertex_colors.array


def test_open3d_in_and_out(sphere):
    o3d = optional("open3d")
    v, f = sphere
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(f))
    colours = np.random.default_rng(4).random((len(v), 3))
    mesh.vertex_colors = o3d.utility.Vector3dVector(colours)
    out, report = vcsmooth.smooth_report(mesh, iterations=5)
    assert isinstance(out, o3d.geometry.TriangleMesh)
    expected = vcsmooth.smooth(v, f, iterations=5)
    assert np.array_equal(np.asarray(out.vertices), expected)
    assert np.array_equal(np.asarray(out.triangles), f)
    assert np.allclose(np.asarray(out.vertex_colors), colours)
    assert not out.has_vertex_normals() and not out.has_triangle_normals()
    assert np.array_equal(np.asarray(mesh.vertices), v)
    assert abs(report["summary"]["volume_pct"] - 100) < 1e-7

    # Vertex normals it carries are recomputed from the new positions; triangle normals it
    # did not carry are not added.
    mesh.compute_vertex_normals()
    mesh.triangle_normals = o3d.utility.Vector3dVector()
    assert mesh.has_vertex_normals() and not mesh.has_triangle_normals()
    out = vcsmooth.smooth(mesh, iterations=5)
    fresh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(expected), o3d.utility.Vector3iVector(f))
    fresh.compute_vertex_normals()
    assert np.allclose(np.asarray(out.vertex_normals), np.asarray(fresh.vertex_normals), atol=1e-12)
    assert not np.allclose(np.asarray(out.vertex_normals), np.asarray(mesh.vertex_normals))
    assert not out.has_triangle_normals()


# PyVista.

def test_pyvista_triangles_in_and_out(sphere):
    pv = optional("pyvista")
    v, f = sphere
    cells = np.hstack([np.full((len(f), 1), 3), f]).ravel()
    mesh = pv.PolyData(v.astype(np.float32), cells)
    mesh.point_data["weight"] = np.arange(len(v), dtype=float)
    mesh.cell_data["label"] = np.arange(len(f)) % 7
    out = vcsmooth.smooth(mesh, iterations=3)
    assert isinstance(out, pv.PolyData) and out is not mesh
    # Its precision: float32 points stay float32.
    assert out.points.dtype == np.float32
    expected = vcsmooth.smooth(v.astype(np.float32), f, iterations=3)
    assert np.array_equal(out.points, expected.astype(np.float32))
    assert np.array_equal(out.faces, cells)
    assert np.array_equal(out.point_data["weight"], mesh.point_data["weight"])
    assert np.array_equal(out.cell_data["label"], mesh.cell_data["label"])
    assert np.array_equal(mesh.points, v.astype(np.float32))


def test_pyvista_quads_and_normals(tmp_path):
    pv = optional("pyvista")
    v, quads = quad_box()
    mesh = pv.PolyData(v, np.hstack([np.full((len(quads), 1), 4), quads]).ravel())
    assert not mesh.is_all_triangles
    mesh = mesh.compute_normals(point_normals=True, cell_normals=True, split_vertices=False,
                                consistent_normals=False, auto_orient_normals=False)
    assert np.array_equal(mesh.points, v)
    out, report = vcsmooth.smooth_report(mesh, iterations=5)
    _, triangles = read_as_the_readers_do(tmp_path, v, quads)
    expected = vcsmooth.smooth(v, triangles, iterations=5)
    assert np.array_equal(out.points, expected)
    # The quads are kept: only positions change.
    assert np.array_equal(out.faces, mesh.faces) and out.n_cells == len(quads)
    assert report["input"]["stats"]["triangles"] == 2 * len(quads)
    # Normals recomputed from the new positions: unit, outward, and not the input's.
    normals = out.point_data["Normals"]
    assert np.allclose(np.linalg.norm(normals, axis=1), 1)
    assert np.all(np.sum(normals * expected, axis=1) > 0)
    assert not np.allclose(normals, mesh.point_data["Normals"], atol=1e-6)
    cell_normals = out.cell_data["Normals"]
    centres = expected[quads].mean(axis=1)
    assert np.all(np.sum(cell_normals * centres, axis=1) > 0)
    assert not np.allclose(cell_normals, mesh.cell_data["Normals"], atol=1e-6)


def test_pyvista_mixed_cells_and_lines(tmp_path):
    pv = optional("pyvista")
    v, quads = quad_box(n=3)
    polygons = []
    for i, q in enumerate(quads.tolist()):
        polygons += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] if i % 2 else [q]
    cells = np.concatenate([[len(p), *p] for p in polygons])
    mesh = pv.PolyData(v, faces=cells, lines=[2, 0, 1])
    _, triangles = read_as_the_readers_do(tmp_path, v, polygons)
    out = vcsmooth.smooth(mesh, iterations=3)
    assert np.array_equal(out.points, vcsmooth.smooth(v, triangles, iterations=3))
    assert np.array_equal(out.faces, cells) and np.array_equal(out.lines, mesh.lines)
    with pytest.raises(ValueError, match=r"PolyData.faces: cell 0 has 2 corners"):
        vcsmooth.smooth(pv.PolyData(v, faces=[2, 0, 1]))
