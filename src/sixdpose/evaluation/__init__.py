"""Evaluation: ADD(-S) metrics (:mod:`.metrics`, paper eq. 4) and accuracy/timing of results files
(:mod:`.evaluate`)."""

from .metrics import add, add_or_adds, adds, is_correct, rotation_error, translation_error

__all__ = ["add", "add_or_adds", "adds", "is_correct", "rotation_error", "translation_error"]
