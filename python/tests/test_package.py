"""The package's typing surface: docstrings, py.typed, and stubs whose keywords and defaults are
the ones the functions take."""

import ast
import inspect
from pathlib import Path

import numpy as np

import vcsmooth
from vcsmooth import _vcsmooth as native

FUNCTIONS = {"smooth", "smooth_report", "smooth_file", "read_mesh", "write_mesh", "info"}


def stub_functions():
    stub = Path(vcsmooth.__file__).with_name("_vcsmooth.pyi")
    tree = ast.parse(stub.read_text())
    return {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}


def stub_defaults(fn):
    """The keyword-only defaults a stub states (`...`: the library's, not written down)."""
    out = {}
    for arg, default in zip(fn.args.kwonlyargs, fn.args.kw_defaults):
        value = ast.literal_eval(default)
        if value is not Ellipsis:
            out[arg.arg] = value
    return out


def test_docstrings_and_markers():
    assert Path(vcsmooth.__file__).with_name("py.typed").is_file()
    assert set(vcsmooth.__all__) >= FUNCTIONS | {"MeshError", "DEFAULT_METHOD"}
    for name in FUNCTIONS:
        doc = getattr(vcsmooth, name).__doc__
        assert doc and len(doc) > 200, name
    assert vcsmooth.DEFAULT_METHOD == "vcs-lowpass"
    assert vcsmooth.DEFAULT_METHOD in vcsmooth.METHODS


def test_the_stub_lists_the_methods_of_the_registry():
    stub = Path(vcsmooth.__file__).with_name("_vcsmooth.pyi")
    tree = ast.parse(stub.read_text())
    [literal] = [n.value for n in tree.body
                 if isinstance(n, ast.Assign) and n.targets[0].id == "_Method"]
    assert tuple(ast.literal_eval(e) for e in literal.slice.elts) == vcsmooth.METHODS


def test_stubs_state_the_defaults(tmp_path, kitten, kitten_path):
    stubs = stub_functions()
    assert set(stubs) == FUNCTIONS
    v, f = kitten
    # Every keyword of the stubs is taken, and its stated default is the default.
    smooth = stub_defaults(stubs["smooth"])
    assert np.array_equal(vcsmooth.smooth(v, f, **smooth), vcsmooth.smooth(v, f))
    report = stub_defaults(stubs["smooth_report"])
    a, ra = vcsmooth.smooth_report(v, f, **report)
    b, rb = vcsmooth.smooth_report(v, f)
    assert np.array_equal(a, b) and ra["options"] == rb["options"] and ra["engine"] == rb["engine"]
    assert ra["results_version"] == vcsmooth.RESULTS_VERSION >= 2
    files = stub_defaults(stubs["smooth_file"])
    ra = vcsmooth.smooth_file(kitten_path, tmp_path / "a.ply", **files)
    rb = vcsmooth.smooth_file(kitten_path, tmp_path / "b.ply")
    assert (tmp_path / "a.ply").read_bytes() == (tmp_path / "b.ply").read_bytes()
    assert ra["options"] == rb["options"] and ra["engine"] == rb["engine"]


def test_signatures_are_the_stubs(kitten):
    """help() and inspect.signature show every keyword with its default, the stubs' (the native
    functions') keywords and defaults."""
    stubs = stub_functions()
    for name in ("smooth", "smooth_report", "smooth_file"):
        signature = inspect.signature(getattr(vcsmooth, name))
        keywords = {p.name: p.default for p in signature.parameters.values()
                    if p.kind is inspect.Parameter.KEYWORD_ONLY}
        assert list(keywords) == [a.arg for a in stubs[name].args.kwonlyargs], name
        for keyword, default in stub_defaults(stubs[name]).items():
            assert keywords[keyword] == default, (name, keyword)
        assert keywords["method"] == vcsmooth.DEFAULT_METHOD
        assert "weld" in keywords and keywords["iterations"] == 10
        assert "**" not in str(signature)
    assert list(inspect.signature(vcsmooth.smooth).parameters)[:2] == ["vertices", "faces"]
    assert keywords["stats"] == "every"
    assert inspect.signature(vcsmooth.smooth).parameters["stats"].default == "last"
    assert "lam: 'float' = 0.5" in str(inspect.signature(vcsmooth.smooth))
    assert "iterations" in vcsmooth.smooth.__doc__ and "PolyData" in vcsmooth.smooth.__doc__


def test_the_signatures_defaults_are_the_librarys(tmp_path, kitten, kitten_path):
    """A call with no keyword (the native function: the library's defaults) and one through the
    package's function (its written defaults, all passed on) run the same options."""
    v, f = kitten
    a, ra = native.smooth_report(v, f, iterations=3)
    b, rb = vcsmooth.smooth_report(v, f, iterations=3)
    assert np.array_equal(a, b) and ra["options"] == rb["options"] and ra["engine"] == rb["engine"]
    assert np.array_equal(native.smooth(v, f, iterations=3), vcsmooth.smooth(v, f, iterations=3))
    ra = native.smooth_file(kitten_path, tmp_path / "a.ply", iterations=2)
    rb = vcsmooth.smooth_file(kitten_path, tmp_path / "b.ply", iterations=2)
    assert (tmp_path / "a.ply").read_bytes() == (tmp_path / "b.ply").read_bytes()
    assert ra["options"] == rb["options"] and ra["engine"] == rb["engine"]
    assert ra.get("deviation") == rb.get("deviation")
