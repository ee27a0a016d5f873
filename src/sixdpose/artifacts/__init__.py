"""The files that pass between stages, one module per artifact, each with its one writer and reader.

================================  ==========================  ==========================================
artifact                          module                      writer -> readers
================================  ==========================  ==========================================
predicted instance masks (.npz)   :mod:`.predictions`         ``segment`` -> ``register``, ``predict-pose``
pose results (BOP CSV)            :mod:`.poses`               ``register``, ``predict-pose`` -> ``evaluate``
result tables (CSV + LaTeX)       :mod:`.tables`              ``evaluate``, notebooks, benchmarks
result artifacts (results/*.json) :mod:`.results`             benchmarks, ``evaluate --result-name`` -> reporting
reference models (PLY)            :mod:`sixdpose.datasets.ply`  ``generate``, ``export-bop`` -> readers
the synthetic layout              :mod:`sixdpose.datasets.layout`  ``generate`` (and test data) -> reader
================================  ==========================  ==========================================
"""

from .poses import RESULTS_HEADER, PoseEstimate, read_results, write_results
from .predictions import (
    Detection,
    list_predictions,
    prediction_path,
    read_predictions,
    read_predictions_meta,
    write_predictions,
    write_predictions_meta,
)
from .results import Result, ResultError, read_result, write_result
from .tables import tex_escape, write_table

__all__ = [
    "RESULTS_HEADER",
    "Detection",
    "PoseEstimate",
    "Result",
    "ResultError",
    "list_predictions",
    "prediction_path",
    "read_predictions",
    "read_predictions_meta",
    "read_result",
    "read_results",
    "tex_escape",
    "write_predictions",
    "write_predictions_meta",
    "write_result",
    "write_results",
    "write_table",
]
