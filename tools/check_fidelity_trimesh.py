#!/usr/bin/env python3
"""Checks with an independent reader (trimesh) that `vcsmooth smooth` keeps what a file carries.

Usage: tools/check_fidelity_trimesh.py BIN

BIN is the vcsmooth binary. The script writes its own small inputs (PLYs with vertex colours,
face colours and texture coordinates; an OFF with vertex and face colours), smooths each with
`BIN smooth`, loads input and output with trimesh and asserts that the vertex and face counts are
equal, the colours and texture coordinates are intact and the positions moved. It also checks
tests/data/fidelity/textured.obj when that file exists (texture coordinates through trimesh), and
GLBs that trimesh writes itself (vertex colours; texture coordinates).
trimesh reads no colour from OFF, so OFF colours are compared on the text's own columns.
Exits non-zero with a message on the first failure.
"""

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parent.parent


def sphere():
    """A noisy icosphere (trimesh's own), so that smoothing moves every vertex."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(16)
    vertices = mesh.vertices * (1 + 0.05 * rng.standard_normal((len(mesh.vertices), 1)))
    return vertices, mesh.faces


def smooth(binary, src, dst):
    subprocess.run([binary, "smooth", str(src), str(dst), "--iterations", "3"], check=True,
                   stdout=subprocess.DEVNULL)


def load(path):
    # Not `force="mesh"`: its scene round trip converts face colours to vertex colours (needing
    # scipy). A file with several materials is a scene: its meshes, concatenated.
    loaded = trimesh.load(str(path), process=False)
    return loaded.to_mesh() if isinstance(loaded, trimesh.Scene) else loaded


def same_counts(a, b, what):
    assert len(a.vertices) == len(b.vertices), f"{what}: {len(a.vertices)} -> {len(b.vertices)} vertices"
    assert len(a.faces) == len(b.faces), f"{what}: {len(a.faces)} -> {len(b.faces)} faces"
    assert not np.allclose(a.vertices, b.vertices), f"{what}: the positions did not move"


def write_ply(path, vertices, faces, vertex_props, vertex_cols, face_props, face_cols):
    """An ASCII PLY with extra vertex and face properties (`property TYPE NAME` lines) and their
    columns."""
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}",
             "property float x", "property float y", "property float z", *vertex_props,
             f"element face {len(faces)}", "property list uchar int vertex_indices", *face_props,
             "end_header"]
    for p, c in zip(vertices, vertex_cols):
        lines.append(" ".join([*(f"{x:.7g}" for x in p), *(f"{x:.7g}" for x in c)]))
    for f, c in zip(faces, face_cols):
        lines.append(" ".join(["3", *map(str, f), *map(str, c)]))
    path.write_text("\n".join(lines) + "\n")


def check_ply(binary, work):
    vertices, faces = sphere()
    n, m = len(vertices), len(faces)
    rgba = [f"property uchar {c}" for c in ("red", "green", "blue", "alpha")]
    colours = np.column_stack([np.arange(n) % 256, (7 * np.arange(n)) % 256,
                               255 - np.arange(n) % 256, np.full(n, 255)])
    face_colours = np.column_stack([np.arange(m) % 256, np.full(m, 9), np.full(m, 99),
                                    np.full(m, 255)])
    src, dst = work / "coloured.ply", work / "coloured-smoothed.ply"
    write_ply(src, vertices, faces, rgba, colours, rgba, face_colours)
    smooth(binary, src, dst)
    a, b = load(src), load(dst)
    same_counts(a, b, "PLY")
    assert np.array_equal(a.visual.vertex_colors, colours), "trimesh read other vertex colours"
    assert np.array_equal(a.visual.vertex_colors, b.visual.vertex_colors), "PLY vertex colours changed"
    print(f"ok: PLY, {n} vertices: vertex colours intact")

    # Face colours alone (trimesh reads vertex colours in preference to face colours).
    src, dst = work / "face-coloured.ply", work / "face-coloured-smoothed.ply"
    write_ply(src, vertices, faces, [], [[]] * n, rgba, face_colours)
    smooth(binary, src, dst)
    a, b = load(src), load(dst)
    same_counts(a, b, "PLY")
    assert np.array_equal(a.visual.face_colors, face_colours), "trimesh read other face colours"
    assert np.array_equal(a.visual.face_colors, b.visual.face_colors), "PLY face colours changed"
    print(f"ok: PLY, {m} faces: face colours intact")

    src, dst = work / "textured.ply", work / "textured-smoothed.ply"
    uv = np.column_stack([np.linspace(0, 1, n), np.linspace(1, 0, n)])
    write_ply(src, vertices, faces, ["property float s", "property float t"], uv, [], [[]] * m)
    smooth(binary, src, dst)
    a, b = load(src), load(dst)
    same_counts(a, b, "PLY")
    assert getattr(a.visual, "uv", None) is not None, "PLY input: trimesh read no uv"
    assert getattr(b.visual, "uv", None) is not None, "PLY output: no texture coordinates"
    assert np.array_equal(a.visual.uv, b.visual.uv), "PLY texture coordinates changed"
    print(f"ok: PLY, {n} vertices: texture coordinates intact")


def off_columns(path):
    """The vertex lines' columns after x y z, and the face lines' after the indices."""
    rows = [line.split("#")[0].split() for line in Path(path).read_text().splitlines()]
    rows = [r for r in rows if r]
    nv, nf = int(rows[1][0]), int(rows[1][1])
    vertex = [r[3:] for r in rows[2:2 + nv]]
    face = [r[1 + int(r[0]):] for r in rows[2 + nv:2 + nv + nf]]
    return vertex, face


def check_off(binary, work):
    vertices, faces = sphere()
    lines = ["COFF", f"{len(vertices)} {len(faces)} 0"]
    lines += [f"{p[0]:.7g} {p[1]:.7g} {p[2]:.7g} {i % 256} 20 30 255" for i, p in enumerate(vertices)]
    lines += [f"3 {f[0]} {f[1]} {f[2]} 0.{i} 0.5 1" for i, f in enumerate(faces)]
    src, dst = work / "coloured.off", work / "coloured-smoothed.off"
    src.write_text("\n".join(lines) + "\n")
    smooth(binary, src, dst)

    same_counts(load(src), load(dst), "OFF")
    assert off_columns(src) == off_columns(dst), "OFF colours changed"
    print(f"ok: OFF, {len(vertices)} vertices: vertex and face colours intact")


def check_textured_obj(binary, work):
    src = ROOT / "tests/data/fidelity/textured.obj"
    if not src.exists():
        print(f"skip: {src.relative_to(ROOT)} not present")
        return
    # trimesh cannot read a comment after a statement's numbers: give it the fixture without them.
    lines = src.read_text().splitlines()
    text = "\n".join(l if l.startswith("#") else l.split("#")[0].rstrip() for l in lines) + "\n"
    src = work / "textured.obj"
    src.write_text(text)
    dst = work / "textured-smoothed.obj"
    smooth(binary, src, dst)
    # The material library and texture are looked up beside the output.
    for sibling in (ROOT / "tests/data/fidelity").iterdir():
        if sibling.is_file() and sibling.suffix.lower() != ".obj":
            (work / sibling.name).write_bytes(sibling.read_bytes())
    a, b = load(src), load(dst)
    same_counts(a, b, "OBJ")
    # A mesh without texture coordinates has colour visuals, which have no `uv`.
    assert getattr(a.visual, "uv", None) is not None, "OBJ input: trimesh read no texture coordinates"
    assert getattr(b.visual, "uv", None) is not None, "OBJ output: no texture coordinates"
    assert np.allclose(a.visual.uv, b.visual.uv, atol=1e-6), "OBJ texture coordinates changed"
    print(f"ok: OBJ, {len(a.vertices)} vertices: texture coordinates intact")


def check_glb(binary, work):
    """GLBs written by trimesh itself: one with vertex colours (COLOR_0), one with texture
    coordinates (TEXCOORD_0); smoothed to GLB, read back by trimesh."""
    vertices, faces = sphere()
    coloured = trimesh.Trimesh(vertices, faces, process=False)
    rng = np.random.default_rng(7)
    coloured.visual.vertex_colors = rng.integers(0, 256, (len(vertices), 4), dtype=np.uint8)
    uv = np.column_stack([np.arctan2(vertices[:, 1], vertices[:, 0]) / (2 * np.pi) + 0.5,
                          0.5 + 0.5 * vertices[:, 2] / np.linalg.norm(vertices, axis=1)])
    textured = trimesh.Trimesh(vertices, faces, process=False,
                               visual=trimesh.visual.TextureVisuals(uv=uv))
    for name, mesh, attribute in [("coloured", coloured, "vertex_colors"), ("textured", textured, "uv")]:
        src, dst = work / f"{name}.glb", work / f"{name}-smoothed.glb"
        src.write_bytes(mesh.export(file_type="glb"))
        smooth(binary, src, dst)
        a, b = load(src), load(dst)
        same_counts(a, b, f"GLB {name}")
        before, after = getattr(a.visual, attribute, None), getattr(b.visual, attribute, None)
        assert before is not None and after is not None, f"GLB {name}: trimesh read no {attribute}"
        assert np.array_equal(before, after), f"GLB {name}: {attribute} changed"
        print(f"ok: GLB {name}, {len(a.vertices)} vertices: {attribute} intact")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__.split("\n\n")[1])
    binary = sys.argv[1]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        check_ply(binary, work)
        check_off(binary, work)
        check_textured_obj(binary, work)
        check_glb(binary, work)


if __name__ == "__main__":
    main()
