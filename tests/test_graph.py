"""sixdpose.graph: a notebook's missing input names the make target that writes it."""

from __future__ import annotations

import pytest

from sixdpose.errors import SixdposeError
from sixdpose.graph import (
    MissingInputError,
    make_target,
    repo_root,
    require,
    require_dataset,
    require_run,
    training_data,
)


def test_missing_inputs_name_their_make_target(tmp_path, monkeypatch):
    (tmp_path / "mk").mkdir()
    (tmp_path / "mk" / "reproduce.mk").write_text("")
    (tmp_path / "notebooks").mkdir()
    monkeypatch.chdir(tmp_path / "notebooks")  # where papermill runs the notebooks
    assert repo_root() == tmp_path.resolve()
    assert make_target("../runs/cpu/pose/model.pt") == "runs/cpu/pose/model.pt"
    with pytest.raises(MissingInputError, match=r"`make runs/cpu/pose/model\.pt PROFILE=cpu` makes it") as e:
        require_run("../runs/cpu/pose", "cpu", "the pose network")
    assert isinstance(e.value, SixdposeError) and "the pose network ../runs/cpu/pose/model.pt" in str(e.value)
    with pytest.raises(MissingInputError, match=r"`make data/test/manifest\.json`"):
        require_dataset("../data/test")
    (tmp_path / "data" / "test").mkdir(parents=True)
    (tmp_path / "data" / "test" / "manifest.json").write_text("{}")
    assert require_dataset("../data/test", "cpu").name == "test"
    assert require("../data/test/manifest.json", "x").is_file()
    outside = tmp_path.parent / "elsewhere.json"
    assert make_target(outside) == str(outside)


def test_training_data_defaults(monkeypatch):
    monkeypatch.delenv("SIXDPOSE_DATA", raising=False)
    assert training_data("smoke") == ("../data/smoke", "../data/smoke")
    assert training_data("demo", test_data="t") == ("../data/demo", "t")
    assert training_data("cpu") == ("../data/train", "../data/test")
    assert training_data("paper", "d") == ("d", "../data/test")
    monkeypatch.setenv("SIXDPOSE_DATA", "/x")
    assert training_data("smoke") == ("/x", "/x")
    assert training_data("cpu", "d") == ("d", "../data/test")
