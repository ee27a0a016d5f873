"""Project-level checks: dependency lists agree, CLI lists its stages, notebooks have no outputs."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tomllib

import yaml

from conftest import REPO


def _name(req: str) -> str:
    return re.split(r"[<>=!~;\[ ]", req.strip(), maxsplit=1)[0].lower().replace("_", "-")


def test_environment_yml_matches_pyproject():
    pp = tomllib.loads((REPO / "pyproject.toml").read_text())
    reqs = pp["project"]["dependencies"] + pp["project"]["optional-dependencies"]["test"]
    env = yaml.safe_load((REPO / "environment.yml").read_text())
    pip = next(d["pip"] for d in env["dependencies"] if isinstance(d, dict) and "pip" in d)
    assert {_name(r): r.replace(" ", "") for r in reqs} == {_name(r): r.replace(" ", "") for r in pip}
    assert "python=3.11" in env["dependencies"]


def test_lock_is_committed_and_pins_torchvision_pair():
    lock = (REPO / "uv.lock").read_text()
    assert 'name = "torch"' in lock and 'name = "torchvision"' in lock and 'name = "drake"' in lock


def test_cli_lists_commands():
    r = subprocess.run([sys.executable, "-m", "sixdpose", "--help"], capture_output=True, text=True)
    assert r.returncode == 0
    for cmd in ("generate", "fetch-ycb"):
        assert cmd in r.stdout
    r = subprocess.run([sys.executable, "-m", "sixdpose", "generate", "--out", "x", "--bogus"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "unrecognized arguments" in r.stderr


def test_notebooks_committed_without_outputs_and_have_parameters():
    nbs = sorted((REPO / "notebooks").glob("[0-9][0-9]_*.ipynb"))
    assert [p.name[:2] for p in nbs][:2] == ["01", "02"]
    for p in nbs:
        nb = json.loads(p.read_text())
        code = [c for c in nb["cells"] if c["cell_type"] == "code"]
        assert all(not c.get("outputs") and c.get("execution_count") is None for c in code), p.name
        params = [c for c in code if "parameters" in c.get("metadata", {}).get("tags", [])]
        assert params and "SIXDPOSE_PROFILE" in "".join(params[0]["source"]), p.name
