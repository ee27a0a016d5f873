"""The exception hierarchy. Every error a user can fix (bad input, bad arguments, a missing or corrupt
file, an output directory that is not ours) derives from :class:`SixdposeError`; each stage raises its
own subclass and only :mod:`sixdpose.cli` turns them into one-line messages and exit statuses.
"""

from __future__ import annotations


class SixdposeError(Exception):
    """Base class of every user-fixable error of the package; the message names the file or field."""


class ConfigError(SixdposeError, ValueError):
    """A configuration value, profile name or ``--set key=value`` override is invalid."""


class OutputError(SixdposeError):
    """An output path cannot be used: a file where a directory is expected, no permission, or a
    non-empty directory that this command did not write."""


class UserError(SixdposeError):
    """A bad command-line argument found by a subcommand's own checks (one line, exit status 2). Raised only
    by the ``cli`` modules; library code raises its stage's own :class:`SixdposeError` subclass."""
