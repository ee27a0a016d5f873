"""Evaluation (the scoring layer): ADD(-S) and the BOP 2019 metrics (:mod:`.metrics`, paper eq. 4), accuracy
and timing of results (:mod:`.evaluate`, :mod:`.bop`) and figures (:mod:`.visualize`); method comparisons and
the paper's tables are in :mod:`sixdpose.reporting`. Imported lazily, so building the command line does not
load scipy."""

import importlib

_LAZY = {
    name: "metrics" for name in ("add", "add_or_adds", "adds", "is_correct", "rotation_error", "translation_error")
}


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = sorted(_LAZY)
