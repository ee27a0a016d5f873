"""Shared fixtures. Generated datasets are made once per test session (smoke profile)."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("SIXDPOSE_SHARED", REPO.parent / "shared"))
YCB = Path(os.environ.get("SIXDPOSE_YCB", SHARED / "data" / "ycb"))


def tree_digest(root: Path) -> dict[str, str]:
    """sha256 of every file below ``root``, keyed by relative path."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def pytest_collection_modifyitems(config, items):
    """Mark every test that generates data with Drake (``tiny_dataset`` or any test of
    test_generation.py) as ``drake``: ``make test-fast`` leaves those out."""
    for item in items:
        if "tiny_dataset" in getattr(item, "fixturenames", ()) or item.path.name == "test_generation.py":
            item.add_marker(pytest.mark.drake)


@pytest.fixture(scope="session")
def ycb_dir() -> Path:
    """The YCB asset directory (``$SIXDPOSE_YCB`` or ../shared/data/ycb); skips if absent."""
    if not (YCB / "objects.csv").is_file():
        pytest.skip(f"YCB assets not found at {YCB}")
    return YCB


@pytest.fixture(scope="session")
def smoke_config():
    """The generator config of the tiny datasets (smoke profile: 2 scenes x 3 views, 640x480)."""
    from sixdpose.generation import profile

    return profile("smoke")


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory, ycb_dir, smoke_config) -> Path:
    """Path of a tiny generated synthetic dataset (smoke profile, 1 worker), made once per session."""
    from sixdpose.generation import generate

    out = tmp_path_factory.mktemp("tiny") / "ds"
    res = generate(out, smoke_config, workers=1, assets=ycb_dir, progress=False)
    assert not res["scenes_failed"], res["scenes_failed"]
    return out
