"""Logging set-up of the command line (light: the CLI imports it before any stage's heavy modules)."""

from __future__ import annotations

import logging
import sys


def setup_logging(verbose: bool = False) -> None:
    """One-line messages on stderr for the ``sixdpose`` loggers (unless logging is configured)."""
    logger = logging.getLogger("sixdpose")
    if not logger.handlers and not logging.getLogger().handlers:
        h = logging.StreamHandler(sys.stderr)
        h.setFormatter(logging.Formatter("sixdpose: %(message)s"))
        logger.addHandler(h)
        logger.propagate = False
    logger.setLevel(logging.INFO if verbose else logging.WARNING)
