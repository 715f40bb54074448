"""Shared fixtures of the Python suite: the repository's scans, a noisy copy, the CLI binary."""

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

import vcsmooth

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data"


def cli_path():
    """The `vcsmooth` binary whose output `smooth_file` must match: $VCSMOOTH_CLI (required to
    exist when set: CI sets it), else the repository's release or debug build, else PATH."""
    given = os.environ.get("VCSMOOTH_CLI")
    if given:
        assert Path(given).is_file(), f"VCSMOOTH_CLI={given} does not exist"
        return Path(given)
    for build in ("release", "debug"):
        p = REPO / "target" / build / "vcsmooth"
        if p.is_file():
            return p
    found = shutil.which("vcsmooth")
    return Path(found) if found else None


@pytest.fixture(scope="session")
def cli():
    path = cli_path()
    if path is None:
        pytest.skip("no vcsmooth binary: cargo build --release, or set VCSMOOTH_CLI")
    return path


@pytest.fixture(scope="session")
def kitten_path():
    return DATA / "kitten-25k.ply"


@pytest.fixture(scope="session")
def kitten(kitten_path):
    """A closed scan (12,623 vertices) with noise added, so that smoothing moves every vertex."""
    v, f = vcsmooth.read_mesh(kitten_path)
    rng = np.random.default_rng(14)
    v = v + rng.normal(scale=0.05, size=v.shape)
    return v, f


def relative_volume_change(before, after, faces):
    v0 = vcsmooth.info(before, faces)["volume"]
    v1 = vcsmooth.info(after, faces)["volume"]
    return abs(v1 - v0) / abs(v0)
