"""The option layer (sixdpose.options) and typed ``--set`` (sixdpose.config): every option of every
command refuses bad values in one line (exit 2) before anything is written; one spelling per concept."""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import re
import typing

import pytest

from sixdpose import options as O
from sixdpose.cli import build_parser, main
from sixdpose.errors import ConfigError


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


COMMANDS = _commands()


def _optionals(p: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in p._actions if a.option_strings and not isinstance(a, argparse._HelpAction)]


def _base_argv(name: str, p: argparse.ArgumentParser, tmp_path) -> list[str]:
    """The command with every required option filled (``--out`` in ``tmp_path``, which must stay absent)."""
    argv = [name]
    for a in _optionals(p):
        if a.required:
            flag = a.option_strings[0]
            value = a.choices[0] if a.choices else str(tmp_path / ("out" if flag == "--out" else flag.strip("-")))
            argv += [flag, str(value)]
    return argv


def _bad_values(t) -> list[str]:
    """A deterministic table of bad values for an option-layer type: wrong type, NaN, inf, negative,
    zero and absurdly large, whichever of these the type refuses."""
    if isinstance(t, O.Int):
        bad = ["abc", "2.5", "nan", "inf", ""]
        if t.lo is not None:
            bad += [str(t.lo - 1), str(-(10**30))]
        if t.hi is not None:
            bad += [str(t.hi + 1), str(10**30)]
        return bad
    if isinstance(t, O.Float):
        bad = ["abc", "nan", "NaN", "inf", "-inf", "1e999"]
        if t.lo is not None:
            bad += [repr(t.lo) if t.lo_open else repr(t.lo - 1.0), "-1e30"]
        if t.hi is not None:
            bad += [repr(t.hi) if t.hi_open else repr(t.hi + 1.0), "1e30"]
        return bad
    if isinstance(t, O.Name):
        return ["../x", "a/b", "/abs", "..", "a\\b"] + ([] if t.allow_empty else [""])
    if isinstance(t, O.Device):
        import torch

        absent = ["cuda", "cuda:0"] if not torch.cuda.is_available() else ["cuda:999"]
        return ["gpu", "cuda:x", "cpu:0", "tpu", *absent]
    raise AssertionError(f"no bad values for {t!r}")


TYPED = [(name, a.option_strings[0], a.type) for name, p in COMMANDS.items() for a in _optionals(p)
         if a.type is not None]


def test_every_typed_option_uses_the_option_layer():
    """No bare int/float/str: every typed option of every command is one of the option layer's checks."""
    for name, p in COMMANDS.items():
        for a in _optionals(p):
            if a.type is not None:
                assert isinstance(a.type, (O.Int, O.Float, O.Name, O.Device)), (name, a.option_strings, a.type)
    kinds = {type(t) for _, _, t in TYPED}
    assert kinds == {O.Int, O.Float, O.Name, O.Device}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_bad_values_give_one_line_naming_the_option(command, tmp_path, capsys):
    """Every typed option of the command, every bad value: exit 2, one line naming the option, no traceback,
    nothing written. Parsing is the real command's (main())."""
    p = COMMANDS[command]
    base = _base_argv(command, p, tmp_path)
    n = 0
    for name, flag, t in TYPED:
        if name != command:
            continue
        for bad in _bad_values(t):
            # --flag=VALUE: a value starting with '-' is not taken for an option
            rc = main([*base, f"{flag}={bad}"])
            err = capsys.readouterr().err.strip().splitlines()
            assert rc == 2, (flag, bad)
            assert len(err) == 1 and f"argument {flag}:" in err[0] and "Traceback" not in err[0], (flag, bad, err)
            assert not (tmp_path / "out").exists()
            n += 1
    assert n > 0 or command in ("eval-seg", "merge-results")  # no typed option


def _set_cases(cls, prefix: str = "") -> list[tuple[str, str]]:
    """``(key=value, field)`` overrides every field of config class ``cls`` must refuse: wrong type,
    zero / negative / out of range by its declared bounds, NaN and inf."""
    from sixdpose.config import Config

    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        hint, key, md = hints[f.name], prefix + f.name, f.metadata
        if isinstance(hint, type) and issubclass(hint, Config):
            out += _set_cases(hint, key + ".")
            continue
        base = [a for a in typing.get_args(hint) if a is not type(None)] or [hint]
        h = base[0]
        if h is int:
            vals = ["2.5", "fast", "true"]
        elif h is float:
            vals = ["fast", ".nan", ".inf", "-.inf", "true"]
        elif h is bool:
            vals = ["1", "maybe"]
        elif h is str:
            vals = ["[1, 2]", "{a: 1}"]
        else:  # tuples
            vals = ["{a: 1}", "[[1, 2]]"]
        if h in (int, float) or typing.get_origin(h) is tuple:
            if "min" in md:
                lo = md["min"]
                vals.append(str(lo if md.get("min_open") else lo - 1))
            if "max" in md:
                hi = md["max"]
                vals.append(str(hi if md.get("max_open") else hi + 1))
        out += [(f"{key}={v}", f.name) for v in vals]
    return out


def _set_argv(command: str, tmp_path) -> list[str]:
    out = str(tmp_path / "out")
    data = str(tmp_path / "data")
    return {
        "generate": ["generate", "--out", out, "--profile", "smoke"],
        "train-seg": ["train-seg", "--data", data, "--out", out],
        "train-pose": ["train-pose", "--data", data, "--out", out, "--no-progress"],
        "train-refiner": ["train-refiner", "--pose", str(tmp_path / "run"), "--data", data, "--out", out],
        "register": ["register", "--data", data, "--method", "ransac", "--out", out],
        "pose-ablation": ["pose-ablation", "--data", data, "--val", data, "--out", out, "--epochs", "1"],
    }[command]


def _config_class(command: str):
    from sixdpose.generation.config import GenerationConfig
    from sixdpose.pose.config import PoseConfig, RefinerConfig
    from sixdpose.registration.presets import RegistrationConfig
    from sixdpose.segmentation.config import SegConfig

    return {"generate": GenerationConfig, "train-seg": SegConfig, "train-pose": PoseConfig,
            "train-refiner": RefinerConfig, "register": RegistrationConfig, "pose-ablation": PoseConfig}[command]


def test_every_command_with_a_config_has_set():
    with_set = {name for name, p in COMMANDS.items() if any(a.dest == "overrides" for a in p._actions)}
    assert with_set == {"generate", "train-seg", "train-pose", "train-refiner", "register", "pose-ablation", "segment",
                        "predict-pose"}


def test_segment_set_inference_fields(tmp_path, capsys):
    """segment --set: only the run config's inference fields, typed and bounded, checked before any work."""
    from sixdpose.segmentation.config import SegConfig
    from sixdpose.segmentation.infer import INFERENCE_FIELDS, check_inference_overrides

    base = ["segment", "--data", str(tmp_path / "d"), "--seg", str(tmp_path / "run"), "--out", str(tmp_path / "out")]
    cases = [c for c in _set_cases(SegConfig) if c[1] in INFERENCE_FIELDS]
    cases += [("lr=0.1", "lr"), ("backbone=resnet18", "backbone")]  # training fields: not at inference
    assert len(cases) > 20
    for kv, field in cases:
        assert main([*base, "--set", kv]) == 2, kv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and field in err[0], (kv, err)
        assert not (tmp_path / "out").exists()
    assert check_inference_overrides({"detections_per_img": 10, "min_size": 320}) == {"detections_per_img": 10,
                                                                                        "min_size": 320}


def test_predict_pose_set_inference_fields(tmp_path, capsys):
    """predict-pose --set: only the pose run's inference fields (points per instance), checked before any work."""
    from sixdpose.pose.config import PoseConfig
    from sixdpose.pose.infer import INFERENCE_FIELDS, check_inference_overrides

    out = tmp_path / "out.csv"
    base = ["predict-pose", "--data", str(tmp_path / "d"), "--pose", str(tmp_path / "run"), "--out", str(out)]
    cases = [c for c in _set_cases(PoseConfig) if c[1] in INFERENCE_FIELDS] + [("lr=0.1", "lr"), ("crop=64", "crop")]
    assert len(cases) > 8
    for kv, field in cases:
        assert main([*base, "--set", kv]) == 2, kv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and field in err[0], (kv, err)
        assert not out.exists()
    assert check_inference_overrides({"num_points": 1000}) == {"num_points": 1000}
    # and the verification's settings (registration config, verify_* fields), typed the same way
    from sixdpose.registration.presets import RegistrationConfig

    assert check_inference_overrides({"num_points": 1000, "verify_near_symmetries": 6}) == {
        "num_points": 1000, "verify_near_symmetries": 6}
    vcases = [c for c in _set_cases(RegistrationConfig) if c[1].startswith("verify_")]
    assert len(vcases) > 10
    for kv, field in vcases:
        assert main([*base, "--verify", "--set", kv]) == 2, kv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and field in err[0], (kv, err)
        assert not out.exists()


@pytest.mark.parametrize("command", ["generate", "train-seg", "train-pose", "train-refiner", "register",
                                     "pose-ablation"])
def test_typed_set_fields(command, tmp_path, capsys):
    """``--set`` of every field of the command's config with a wrong type, zero / negative / out-of-range
    value, NaN or inf: exit 2, one line naming the field; nothing left in --out."""
    cases = _set_cases(_config_class(command))
    if command == "pose-ablation":  # the ablation sets the budget itself
        cases = [c for c in cases if c[1] not in ("epochs", "time_budget")]
    assert len(cases) > 40
    for kv, field in cases:
        rc = main([*_set_argv(command, tmp_path), "--set", kv])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2, kv
        assert len(err) == 1 and re.search(rf"\b{re.escape(field)}\b", err[0]) and "Traceback" not in err[0], (kv, err)
        assert not (tmp_path / "out").exists(), kv


def test_train_pose_negative_workers_leaves_no_run_dir(tmp_path, capsys):
    from sixdpose.segmentation.toydata import make_toy_dataset

    data = make_toy_dataset(tmp_path / "toy", n_scenes=1, views=2, size=(64, 80))
    for argv in (["--set", "num_workers=-1"], ["--set", "num_workers=2.5"]):
        assert main(["train-pose", "--data", str(data), "--out", str(tmp_path / "run"), "--no-progress", *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "num_workers" in err[0]
        assert not (tmp_path / "run").exists()
    for argv in (["--workers", "-1"], ["--num-workers", "-1"]):
        assert main(["train-seg", "--data", str(data), "--out", str(tmp_path / "run"), *argv]) == 2
        assert "argument --workers" in capsys.readouterr().err
        assert not (tmp_path / "run").exists()


def test_configs_built_in_code_are_checked_the_same_way():
    from sixdpose.generation.config import GenerationConfig
    from sixdpose.pose.config import PoseConfig
    from sixdpose.registration.presets import RegistrationConfig, get_preset

    for make, field in ((lambda: PoseConfig(lr="fast"), "lr"), (lambda: PoseConfig(num_workers=-1), "num_workers"),
                        (lambda: GenerationConfig(views=2.5), "views"), (lambda: GenerationConfig(model_points=0),
                                                                         "model_points"),
                        (lambda: GenerationConfig(views=100_000_000), "views"),
                        (lambda: RegistrationConfig(normal_knn=2.5), "normal_knn"),
                        (lambda: get_preset("default", gate_rel=float("nan")), "gate_rel"),
                        (lambda: GenerationConfig().replace(**{"camera.fov_y_deg": "wide"}), "fov_y_deg"),
                        (lambda: PoseConfig(amp=1), "amp")):
        with pytest.raises(ConfigError, match=field):
            make()
    # what is allowed: null for Optional fields, ints for float fields, lists for tuples, nested dicts
    assert get_preset("default", gate_rel=None, s4pcs_bases=3).gate_rel is None
    assert PoseConfig(lr=1).lr == 1
    assert GenerationConfig(targets=[1, 2]).targets == (1, 2)
    assert GenerationConfig(target_objects=[1, "obj_000005"]).target_objects == ("1", "obj_000005")
    assert GenerationConfig.from_dict({"camera": {"width": 64, "height": 48}}).camera.width == 64


def test_every_numeric_config_field_declares_bounds():
    from sixdpose.generation.config import CameraConfig, GenerationConfig
    from sixdpose.pose.config import PoseConfig, RefinerConfig
    from sixdpose.registration.presets import RegistrationConfig
    from sixdpose.segmentation.config import SegConfig

    missing = []
    for cls in (CameraConfig, GenerationConfig, PoseConfig, RefinerConfig, RegistrationConfig, SegConfig):
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            text = str(hints[f.name])
            if ("int" in text or "float" in text) and "min" not in f.metadata and f.name != "intrinsics":
                missing.append(f"{cls.__name__}.{f.name}")
    assert missing == []


def test_flags_of_config_fields_have_the_config_bounds():
    from sixdpose.generation.config import GenerationConfig

    views = next(a for a in _optionals(COMMANDS["generate"]) if a.dest == "views")
    f = {x.name: x for x in dataclasses.fields(GenerationConfig)}["views"]
    assert (views.type.lo, views.type.hi) == (f.metadata["min"], f.metadata["max"])


# ---------------------------------------------------------------------------------------- spellings

#: Long-running commands: each has --no-progress.
LONG = {"generate", "fetch-ycb", "fetch-weights", "export-bop", "train-seg", "segment", "eval-seg", "register",
        "train-pose", "train-refiner", "predict-pose", "pose-ablation", "evaluate"}


def test_one_spelling_and_one_default_per_concept():
    for name, p in COMMANDS.items():
        visible = {s for a in _optionals(p) for s in a.option_strings}
        assert not visible & set(O.ALIASES), (name, visible & set(O.ALIASES))  # old spellings are hidden
        for a in _optionals(p):
            for s in a.option_strings:
                if s in O.OPTIONS:  # a shared concept: its one dest, type and default, from the option layer
                    spec = O.spec(name, s)
                    assert a.dest == spec.dest, (name, s)
                    assert getattr(a, "default", None) == (None if a.required else spec.default), (name, s)
                    if spec.type is not None:
                        assert a.type == spec.type, (name, s)
                    assert set(getattr(a, "aliases", ())) == set(spec.aliases), (name, s)
        for alias, canonical in O.ALIASES.items():  # every old spelling reaches the canonical option's action
            if canonical in p._option_string_actions:
                assert p._option_string_actions.get(alias) is p._option_string_actions[canonical], (name, alias)
        help_text = p.format_help()
        for alias in O.ALIASES:
            assert not re.search(rf"(?<![\w-]){re.escape(alias)}(?![\w-])", help_text), (name, alias)
    # concepts without a declared per-command difference have the same default everywhere
    for flag in O.OPTIONS:
        defaults = {O.spec(name, flag).default for name, p in COMMANDS.items()
                    if any(flag in a.option_strings for a in p._actions) and (name, flag) not in O.PER_COMMAND}
        assert len(defaults) <= 1, (flag, defaults)
    # concepts spelt once: none of the old spellings is a canonical flag anywhere
    assert {"--min-score", "--preset", "--num-workers", "--ckpt", "--pred", "--to", "--train", "--val-images"} <= set(
        O.ALIASES)
    for name in LONG:
        assert any("--no-progress" in a.option_strings for a in COMMANDS[name]._actions), name


@pytest.mark.parametrize("argv, dest, value", [
    (["register", "--data", "d", "--method", "fgr", "--out", "o.csv", "--min-score", "0.3"], "score_thresh", 0.3),
    (["register", "--data", "d", "--method", "fgr", "--out", "o.csv", "--preset", "paper"], "profile", "paper"),
    (["register", "--data", "d", "--method", "fgr", "--out", "o.csv", "--limit", "3"], "limit", 3),
    (["register", "--data", "d", "--method", "fgr", "--out", "o.csv"], "limit", 0),
    (["segment", "--data", "d", "--ckpt", "run", "--out", "p"], "ckpt", "run"),
    (["segment", "--data", "d", "--seg", "run", "--out", "p", "--num-workers", "2"], "workers", 2),
    (["eval-seg", "--data", "d", "--pred", "p"], "masks", "p"),
    (["fetch-ycb", "--to", "assets"], "out", "assets"),
    (["pose-ablation", "--train", "t", "--val", "v", "--out", "o", "--val-images", "5"], "limit", 5),
    (["pose-ablation", "--train", "t", "--val", "v", "--out", "o"], "data", "t"),
    (["train-seg", "--data", "d", "--out", "o", "--num-workers", "1"], "workers", 1),
    (["train-pose", "--data", "d", "--out", "o", "-v"], "verbose", True),
    (["predict-pose", "--data", "d", "--pose", "r", "--out", "o.csv", "--min-score", "0.7"], "score_thresh", 0.7),
])
def test_old_spellings_still_parse(argv, dest, value):
    assert getattr(build_parser().parse_args(argv), dest) == value


def test_profile_choices_come_from_the_config_registries():
    from sixdpose.generation.config import PROFILES as GEN
    from sixdpose.pose.config import PROFILES as POSE
    from sixdpose.pose.config import REFINER_PROFILES
    from sixdpose.registration.presets import PRESETS
    from sixdpose.segmentation.config import PROFILES as SEG

    expected = {"generate": GEN, "train-seg": SEG, "train-pose": POSE, "train-refiner": REFINER_PROFILES,
                "register": PRESETS, "pose-ablation": POSE}
    for name, p in COMMANDS.items():
        a = next((a for a in p._actions if "--profile" in a.option_strings), None)
        if name in expected:
            assert a is not None and set(a.choices) == set(expected[name]), name
            assert a.default is None or a.default in expected[name]
        else:
            assert a is None, name


# ------------------------------------------------------------------------------- specific checks


@pytest.mark.parametrize("argv", [
    ["register", "--data", "d", "--method", "fgr", "--limit", "-1"],
    ["predict-pose", "--data", "d", "--pose", "r", "--limit", "-5"],
    ["evaluate", "--data", "d", "--results", "r.csv", "--limit", "-1"],
    ["pose-ablation", "--data", "d", "--val", "v", "--epochs", "1", "--limit", "-1"],
    ["segment", "--data", "d", "--seg", "r", "--device", "gpu"],
    ["train-seg", "--data", "d", "--device", "cuda:x"],
    ["export-bop", "--data", "d", "--split", "../x"],
    ["evaluate", "--data", "d", "--results", "r.csv", "--result-name", "a/b"],
    ["eval-seg", "--data", "d", "--masks", "p", "--tag", "/abs"],
    ["train-seg", "--data", "d", "--train-split", ".."],
    ["evaluate", "--data", "d", "--results", "r.csv", "--threshold", "nan"],
    ["evaluate", "--data", "d", "--results", "r.csv", "--threshold", "-0.1"],
    ["segment", "--data", "d", "--seg", "r", "--batch-size", "0"],
    ["predict-pose", "--data", "d", "--pose", "r", "--score-thresh", "2"],
    ["fetch-ycb", "--timeout", "nan"],
    ["generate", "--views", "100000000"],
])
def test_specific_bad_options(argv, tmp_path, capsys):
    rc = main([*argv, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "error: argument --" in err[0], err
    assert not (tmp_path / "out").exists()


def test_device_cuda_without_cuda(capsys):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    for cmd in (["predict-pose", "--data", "d", "--pose", "r", "--out", "o.csv"],
                ["train-seg", "--data", "d", "--out", "o"],
                ["segment", "--data", "d", "--seg", "r", "--out", "p"], ["train-pose", "--data", "d", "--out", "o"]):
        assert main([*cmd, "--device", "cuda"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "argument --device" in err[0] and "CUDA is not available" in err[0]


def test_figures_and_results_dir_that_are_files(tmp_path, capsys):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    assert main(["eval-seg", "--data", str(tmp_path / "d"), "--masks", str(tmp_path / "p"),
                 "--figures", str(a_file)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(a_file) in err[0]
    assert main(["eval-seg", "--data", str(tmp_path / "d"), "--masks", str(tmp_path / "p"),
                 "--figures", str(a_file / "sub")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is a file" in err[0]
    results = tmp_path / "r.csv"
    results.write_text("scene_id,im_id,obj_id,score,R,t,time\n")
    assert main(["evaluate", "--data", str(tmp_path / "d"), "--results", str(results), "--out", str(tmp_path / "ev"),
                 "--result-name", "x", "--results-dir", str(a_file)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(a_file) in err[0]
    assert not (tmp_path / "ev").exists()


@pytest.mark.parametrize("argv", [
    ["register", "--data", "{d}", "--method", "fgr", "--out", "{f}/r.csv"],
    ["predict-pose", "--data", "{d}", "--pose", "{d}", "--out", "{f}/r.csv"],
    ["export-bop", "--data", "{d}", "--out", "{f}/bop"],
    ["segment", "--data", "{d}", "--seg", "{d}", "--out", "{f}/pred"],
    ["train-pose", "--data", "{d}", "--out", "{f}/run"],
    ["evaluate", "--data", "{d}", "--results", "{d}/r.csv", "--out", "{f}/ev"],
    ["generate", "--out", "{f}/g", "--profile", "smoke", "--no-progress"],
    ["train-seg", "--data", "{d}", "--out", "{f}/run"],
    ["train-refiner", "--pose", "{d}", "--data", "{d}", "--out", "{f}/run"],
    ["pose-ablation", "--data", "{d}", "--val", "{d}", "--out", "{f}/abl", "--epochs", "1"],
    ["fetch-ycb", "--out", "{f}/assets", "--objects", "055_baseball", "--base-url", "http://127.0.0.1:9"],
])
def test_out_whose_parent_is_a_file(argv, tmp_path, capsys):
    """An --out below a regular file: one line, exit 2 (was a FileExistsError traceback)."""
    f = tmp_path / "file"
    f.write_text("x")
    d = tmp_path / "nodata"
    rc = main([s.format(d=d, f=f) for s in argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and f"{f} is a file" in err[0], err
    assert f.read_text() == "x"


def test_read_only_output_dirs(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        if os.access(ro, os.W_OK):
            pytest.skip("running as root: a read-only directory is writable")
        assert main(["eval-seg", "--data", str(tmp_path / "d"), "--masks", str(tmp_path / "p"),
                     "--figures", str(ro)]) == 2
        assert "not writable" in capsys.readouterr().err
    finally:
        ro.chmod(0o700)


def test_path_names():
    from sixdpose.errors import OutputError
    from sixdpose.fileio import check_path_name
    from sixdpose.segmentation.config import profile_config

    with pytest.raises(ConfigError, match="train_split"):
        profile_config("smoke", train_split="../x")
    for ok in ("test", "train_synt", "_smoke", "pose_ablation_cpu", "a.b"):
        assert check_path_name(ok) == ok
    for bad in ("", ".", "..", "a/b", "../a", "/abs", "a\\b", " a", "a\0b"):
        with pytest.raises(OutputError):
            check_path_name(bad)


def test_predict_pose_set_reaches_the_estimator(tmp_path):
    """A valid ``predict-pose --set num_points=N`` is used (and recorded in <out>.config.yml)."""
    import yaml

    from sixdpose.pose.config import profile_config
    from test_pose import fake_pose_run, write_pose_dataset

    ds = write_pose_dataset(tmp_path / "ds", n_images=1)
    run = fake_pose_run(tmp_path / "run", profile_config("smoke"))
    out = tmp_path / "r.csv"
    assert main(["predict-pose", "--data", str(ds), "--pose", str(run), "--out", str(out), "--no-progress",
                 "--device", "cpu", "--set", "num_points=48"]) == 0
    settings = yaml.safe_load(out.with_name("r.config.yml").read_text())
    assert settings["pose_config"]["num_points"] == 48 and profile_config("smoke").num_points != 48


def test_option_types_accept_only_what_they_describe():
    """Any text: an option type returns a value within its range or raises ArgumentTypeError, never anything else."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    types = [O.Int(0, None), O.Int(1, 10_000), O.Float(0.0, 1.0), O.Float(0.0, 10.0, lo_open=True), O.Float(),
             O.Name(), O.Name(allow_empty=True)]
    texts = st.one_of(st.text(max_size=12), st.integers().map(str), st.floats(allow_nan=True).map(repr),
                      st.sampled_from(["nan", "-inf", "1e999", "0", "-0.0", "..", "a/b", " 3 "]))

    @settings(max_examples=300, deadline=None)
    @given(st.sampled_from(types), texts)
    def check(t, text):
        try:
            v = t(text)
        except argparse.ArgumentTypeError as e:
            assert str(e) and "\n" not in str(e)
            return
        if isinstance(t, O.Int):
            assert isinstance(v, int) and (t.lo is None or v >= t.lo) and (t.hi is None or v <= t.hi)
        elif isinstance(t, O.Float):
            assert math.isfinite(v) and (t.lo is None or v > t.lo or (v == t.lo and not t.lo_open))
            assert t.hi is None or v <= t.hi
        else:
            assert "/" not in v and v not in (".", "..")

    check()
