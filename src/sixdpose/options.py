"""The option layer of the ``sixdpose`` command line: every shared option declared once.

Each shared concept (``--out``, ``--limit``, ``--device``, ``--workers``, ``--score-thresh`` ...) is an
:class:`Opt` in :data:`OPTIONS` with its one canonical spelling, its type (a checking callable below),
its range, its default and its help; a subcommand adds it with :func:`add`. Old spellings are hidden
aliases: they still parse (they reach the same argparse action) but appear neither in ``--help`` nor in
error messages. Where a command needs another default or range for a concept (``register`` runs 2
worker processes, ``segment`` loads images in the main process), the difference is declared here too,
in :data:`PER_COMMAND`, so every default of the command line is defined in this module.

One spelling per concept: ``--out`` (every output; old ``--to``), ``--data`` (the input dataset; old
``--train``), ``--masks`` (``gt`` or a prediction directory; old ``--pred``), ``--score-thresh`` (old
``--min-score``), ``--profile`` (a stage's named config; old ``--preset``), ``--workers`` (processes:
scene workers, registration pool, data loaders; old ``--num-workers``), ``--threads`` (torch CPU threads
inside one process: another concept), ``--limit`` (first N images, 0 = all, everywhere; old
``--val-images``), ``--seg`` / ``--pose`` / ``--refiner`` (a trained run, named by the network it holds;
old ``--ckpt``), ``--device``, ``--split``, ``--no-progress``, ``-v/--verbose``, ``--set``.

Values are checked while parsing: the argparse ``type=`` callables raise
:class:`argparse.ArgumentTypeError`, which :class:`sixdpose.cli._Parser` prints as one line
(``sixdpose CMD: error: argument --x: ...``, exit status 2) before anything is read or written.
Floats are always finite; sizes that allocate memory or time (views, scenes, points, batch) have upper
bounds; names that become part of a path are single path components
(:func:`sixdpose.fileio.check_path_name`); ``--device`` is checked against this machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
from dataclasses import dataclass
from typing import Any

from .constants import MIN_DETECTION_SCORE, MIN_VISIBLE_PX
from .errors import OutputError

#: Seeds: non-negative and below 2**32 (numpy's limit).
SEED_MAX = 2**32 - 1


def _range_text(lo, hi, lo_open: bool = False, hi_open: bool = False) -> str:
    from .config import bounds_text

    return bounds_text({"min": lo, "max": hi, "min_open": lo_open, "max_open": hi_open})


@dataclass(frozen=True)
class Int:
    """argparse type: a decimal integer in ``[lo, hi]`` (``None``: unbounded on that side)."""

    lo: int | None = None
    hi: int | None = None

    def describe(self) -> str:
        """What is allowed, e.g. ``an integer in [1, 10000]``."""
        return "an integer" + _range_text(self.lo, self.hi)

    def __call__(self, text: str) -> int:
        """Parse ``text``; raises :class:`argparse.ArgumentTypeError` naming what is allowed."""
        try:
            v = int(str(text).strip(), 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {self.describe()}, got {text!r}") from None
        if (self.lo is not None and v < self.lo) or (self.hi is not None and v > self.hi):
            raise argparse.ArgumentTypeError(f"{v} is out of range: expected {self.describe()}")
        return v


@dataclass(frozen=True)
class Float:
    """argparse type: a finite float in the interval from ``lo`` to ``hi`` (open ends if asked)."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False

    def describe(self) -> str:
        """What is allowed, e.g. ``a finite number in (0, 1]``."""
        return "a finite number" + _range_text(self.lo, self.hi, self.lo_open, self.hi_open)

    def __call__(self, text: str) -> float:
        """Parse ``text``; NaN, infinities and values out of range raise :class:`argparse.ArgumentTypeError`."""
        try:
            v = float(str(text).strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {self.describe()}, got {text!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"expected {self.describe()}, got {text!r}")
        lo, hi = self.lo, self.hi
        if (lo is not None and (v < lo or (self.lo_open and v == lo))) or (
                hi is not None and (v > hi or (self.hi_open and v == hi))):
            raise argparse.ArgumentTypeError(f"{v:g} is out of range: expected {self.describe()}")
        return v


@dataclass(frozen=True)
class Name:
    """argparse type: a name that becomes one component of a path (a split, a tag, a result name):
    no separator, not ``.``/``..``, not absolute (:func:`sixdpose.fileio.check_path_name`)."""

    allow_empty: bool = False

    def describe(self) -> str:
        """What is allowed."""
        return "a plain name (no '/', '\\', '..' or absolute path)"

    def __call__(self, text: str) -> str:
        """Check ``text``; raises :class:`argparse.ArgumentTypeError`."""
        from .fileio import check_path_name

        if text == "" and self.allow_empty:
            return text
        try:
            return check_path_name(text)
        except OutputError as e:
            raise argparse.ArgumentTypeError(str(e)) from None


_DEVICE = re.compile(r"^(auto|cpu|cuda)(?::(\d+))?$")


@dataclass(frozen=True)
class Device:
    """argparse type: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``, checked against this machine (CUDA
    present, ``N`` below the device count)."""


    def describe(self) -> str:
        """What is allowed."""
        return "auto, cpu, cuda or cuda:N"

    def __call__(self, text: str) -> str:
        """Check ``text``; raises :class:`argparse.ArgumentTypeError` for a misspelt or absent device."""
        m = _DEVICE.match(str(text).strip())
        if not m or (m.group(2) is not None and m.group(1) != "cuda"):
            raise argparse.ArgumentTypeError(f"expected {self.describe()}, got {text!r}")
        if m.group(1) == "cuda":
            import torch

            if not torch.cuda.is_available():
                raise argparse.ArgumentTypeError(f"{text!r} requested but CUDA is not available on this machine "
                                                 "(use cpu or auto)")
            n = torch.cuda.device_count()
            if m.group(2) is not None and int(m.group(2)) >= n:
                raise argparse.ArgumentTypeError(f"{text!r}: this machine has {n} CUDA device(s)")
        return m.group(0)


def field_type(cls, name: str):
    """An :class:`Int` / :class:`Float` argparse type with the bounds of config field ``cls.name``
    (its ``metadata``, see :func:`sixdpose.config.bounded`): a flag that sets a config field checks
    exactly what the config does."""
    import typing

    from .config import field_metadata

    hint = typing.get_type_hints(cls)[name]
    md = field_metadata(cls, name)
    base = int if hint is int or hint == (int | None) else float
    if base is int:
        return Int(md.get("min"), md.get("max"))
    return Float(md.get("min"), md.get("max"), bool(md.get("min_open")), bool(md.get("max_open")))


@dataclass(frozen=True)
class Opt:
    """One option of the command line: canonical ``flag``, hidden ``aliases`` and argparse settings."""

    flag: str
    dest: str
    help: str
    type: Any = None
    default: Any = None
    action: str | None = None
    choices: Any = None
    metavar: str | None = None
    required: bool = False
    aliases: tuple[str, ...] = ()
    short: str | None = None


#: Upper bounds of sizes given on the command line.
MAX_WORKERS = 256
MAX_THREADS = 1024
MAX_BATCH = 1024
MAX_PIXELS = 10_000_000

#: Every shared option, by canonical flag.
OPTIONS: dict[str, Opt] = {o.flag: o for o in (
    Opt("--data", "data", "dataset directory (synthetic layout or BOP root)", required=True, aliases=("--train",)),
    Opt("--out", "out", "output path", required=True, aliases=("--to",)),
    Opt("--split", "split", "BOP split (ignored for the synthetic layout)", type=Name(), default="test"),
    Opt("--limit", "limit", "first N images only (0: all)", type=Int(0, None), default=0, metavar="N",
        aliases=("--val-images",)),
    Opt("--device", "device", "auto, cpu, cuda or cuda:N (default auto: the GPU when present)", type=Device(),
        default=None),
    Opt("--threads", "threads", "torch CPU threads per process (0 or unset: the config's / torch default)",
        type=Int(0, MAX_THREADS), default=None),
    Opt("--workers", "workers", "worker processes", type=Int(0, MAX_WORKERS), default=None,
        aliases=("--num-workers",)),
    Opt("--score-thresh", "score_thresh", "minimum score of a predicted mask (detections below it are skipped)",
        type=Float(0.0, 1.0), default=MIN_DETECTION_SCORE, aliases=("--min-score",)),
    Opt("--masks", "masks", "gt (ground-truth masks) or PRED_DIR of `sixdpose segment`", default="gt",
        aliases=("--pred",)),
    Opt("--no-progress", "no_progress", "no progress bar", action="store_true", default=False),
    Opt("--verbose", "verbose", "log more (every skipped instance, every epoch)", action="store_true", default=False,
        short="-v"),
    Opt("--profile", "profile", "named config profile", default=None, aliases=("--preset",)),
    Opt("--seed", "seed", "random seed", type=Int(0, SEED_MAX), default=None),
    Opt("--epochs", "epochs", "number of epochs", type=Int(1, 100_000), default=None),
    Opt("--time-budget", "time_budget", "seconds of training (0: none)", type=Float(0.0, 30 * 24 * 3600.0),
        default=None),
    Opt("--min-px", "min_px", "visible pixels of a scored instance", type=Int(0, MAX_PIXELS), default=MIN_VISIBLE_PX),
    Opt("--result-name", "result_name", "result artifact name (RESULTS_DIR/NAME.json)", type=Name(), default=None,
        metavar="NAME"),
    Opt("--results-dir", "results_dir", "directory of result artifacts (default: results)", default="results"),
    Opt("--batch-size", "batch_size", "images per step (training) or per forward pass (inference)",
        type=Int(1, MAX_BATCH), default=None),
    Opt("--val", "val", "held-out dataset scored every epoch (ADD(-S) %% into metrics.csv), e.g. data/val",
        default=None),
    Opt("--verify", "verify", "verify several pose hypotheses per instance against the frame (depth with "
        "occlusion, mask overlap, texture; sixdpose.registration.hypotheses) and keep the best", action="store_true",
        default=False),
    Opt("--pose", "pose", "run directory of train-pose", required=True),
    Opt("--seg", "ckpt", "run directory of train-seg (or a checkpoint file)", required=True, aliases=("--ckpt",)),
)}

#: Per-command differences from :data:`OPTIONS` (defaults, ranges, required), all declared here.
PER_COMMAND: dict[tuple[str, str], dict] = {
    # process pools: at least one process
    ("generate", "--workers"): {"default": 1, "type": Int(1, MAX_WORKERS),
                                "help": "parallel scene workers (default 1)"},
    ("register", "--workers"): {"default": 2, "type": Int(1, MAX_WORKERS), "help": "processes (default 2)"},
    # data loaders: 0 loads in the main process
    ("segment", "--batch-size"): {"default": 4, "help": "images per forward pass (default 4)"},
    ("segment", "--workers"): {"default": 0, "help": "image-loading worker processes (0: in the main process)"},
    ("train-seg", "--workers"): {"help": "data-loading worker processes (default: the config's num_workers)"},
    # segment keeps every detection above the run's own low threshold (AP needs the full curve)
    ("segment", "--score-thresh"): {"default": None, "help": "minimum detection score (default: the run's, 0.05)"},
    ("evaluate", "--min-px"): {"help": "count GT instances with at least this many visible pixels"},
    ("register", "--min-px"): {"default": 0, "help": "with GT masks, skip instances with fewer visible pixels"},
    ("pose-ablation", "--limit"): {"help": "score on the first N images of --val (0: all)"},
    ("fetch-ycb", "--out"): {"help": "destination asset directory"},
    ("evaluate", "--out"): {"required": False, "default": None,
                            "help": "output directory (default: next to the results, <results>_eval)"},
    ("generate", "--profile"): {"default": "demo"},
    ("register", "--profile"): {"default": "default"},
    # register verifies by default (measured to help every method on the real sample and on data/test);
    # --no-verify gives the unverified methods (the paper's Table rows). None: the profile's choice, on with
    # `default`, off with `paper` (sixdpose.registration.presets.verify_by_default)
    ("register", "--verify"): {"action": argparse.BooleanOptionalAction, "default": None,
                               "help": "verify several pose hypotheses per instance against the frame (depth with "
                                       "occlusion, mask overlap, texture; sixdpose.registration.hypotheses) and keep "
                                       "the best; default: on with --profile default, off with --profile paper "
                                       "(--no-verify: the global method [+ ICP] alone, as in the paper)"},
    ("pose-ablation", "--profile"): {"default": "cpu"},
}

#: Old spellings (hidden aliases) and the canonical flag they stand for.
ALIASES: dict[str, str] = {a: o.flag for o in OPTIONS.values() for a in o.aliases}


def command_of(parser: argparse.ArgumentParser) -> str:
    """The subcommand name of a subparser (the last word of its ``prog``)."""
    return parser.prog.split()[-1]


def spec(command: str, flag: str) -> Opt:
    """The :class:`Opt` of ``flag`` as used by ``command`` (:data:`OPTIONS` with :data:`PER_COMMAND`)."""
    o = OPTIONS[flag]
    per = PER_COMMAND.get((command, flag))
    return dataclasses.replace(o, **per) if per else o


def add(parser: argparse.ArgumentParser, flag: str, group=None, **changes) -> argparse.Action:
    """Add the shared option ``flag`` (canonical spelling) with its hidden aliases to a subparser
    (into its argument ``group`` if given).

    ``changes`` may set ``help`` (the command's wording), ``required``, ``choices`` or ``metavar``:
    the type, range and default come from this module (:data:`OPTIONS`, :data:`PER_COMMAND`).
    """
    bad = set(changes) - {"help", "required", "choices", "metavar"}
    if bad:
        raise TypeError(f"options.add: {sorted(bad)} are defined in the option layer, not by a command")
    o = dataclasses.replace(spec(command_of(parser), flag), **changes)
    kw: dict[str, Any] = {"dest": o.dest, "help": o.help, "default": o.default}
    if o.action:
        kw["action"] = o.action
    else:
        kw["type"] = o.type
        if o.metavar:
            kw["metavar"] = o.metavar
        if o.choices is not None:
            kw["choices"] = o.choices
    if o.required:
        kw["required"] = True
        kw.pop("default")
    names = (o.short, o.flag) if o.short else (o.flag,)
    action = (group or parser).add_argument(*names, **kw)
    add_aliases(parser, action, o.aliases)
    return action


def add_aliases(parser: argparse.ArgumentParser, action: argparse.Action, aliases) -> None:
    """Make each of ``aliases`` (old spellings) parse as ``action`` without showing it in help, usage
    or error messages (which name the canonical spelling)."""
    for a in aliases:
        if a in parser._option_string_actions:
            raise ValueError(f"{command_of(parser)}: alias {a} already used")
        parser._option_string_actions[a] = action
    action.aliases = tuple(getattr(action, "aliases", ())) + tuple(aliases)


def add_many(parser: argparse.ArgumentParser, *flags: str) -> None:
    """Add several shared options with their own help (:func:`add` of each ``flag``, in order)."""
    for flag in flags:
        add(parser, flag)


def set_threads(threads: int | None) -> None:
    """Apply ``--threads``: torch's CPU threads of this process (None or 0: torch's default)."""
    if threads:
        import torch

        torch.set_num_threads(threads)


def add_profile(parser: argparse.ArgumentParser, profiles, help: str) -> argparse.Action:
    """``--profile`` (hidden alias ``--preset``) whose choices are the names of a stage's config registry;
    its default is the command's entry in :data:`PER_COMMAND` (None: chosen by the command, e.g. the
    run's own on ``--resume``)."""
    return add(parser, "--profile", choices=tuple(profiles), help=help)
