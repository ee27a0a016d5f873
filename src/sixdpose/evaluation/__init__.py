"""Evaluation (the scoring layer): ADD(-S) and the BOP 2019 metrics (:mod:`.metrics`, paper eq. 4), accuracy
and timing of results (:mod:`.evaluate`, :mod:`.bop`) and figures (:mod:`.visualize`); method comparisons and
the paper's tables are in :mod:`sixdpose.reporting`. Imported lazily, so building the command line does not
load scipy."""

from ..lazy import lazy_getattr

_LAZY = {
    name: "metrics" for name in ("add", "add_or_adds", "adds", "is_correct", "rotation_error", "translation_error")
}


__getattr__ = lazy_getattr(__name__, _LAZY)  # lazy, so that building the CLI parser does not import torch


__all__ = sorted(_LAZY)
