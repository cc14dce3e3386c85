"""lburst's one family of errors: every exception that lburst raises on purpose derives from
:class:`LBurstError`, and each one also from the built-in exception it always was
(``ValueError``, ``OSError``, ``RuntimeError``, ``ImportError``), so ``except ValueError``
still catches a bad value.  Catch :class:`LBurstError` to catch them all.

The ``lburst`` command prints one of them as one line, ``lburst COMMAND: error: MESSAGE``,
and exits with its :attr:`LBurstError.exit_code` (:mod:`lburst.cli`).

This module imports nothing, so every process (the COLMAP child included) can import it.
"""

from __future__ import annotations

#: Exit status of the ``lburst`` command: it finished.
EXIT_OK = 0
#: It ran, but some or all of its work failed (an input among several, COLMAP registered
#: no image, a model that fails its checks, a recording stopped early); what it finished is kept.
EXIT_FAILED = 1
#: It did nothing: bad options or input (a usage error, a bad spec, a missing or unreadable
#: file, a missing optional extra, a folder another run holds).
EXIT_BAD_INPUT = 2
#: Interrupted (Ctrl-C); finished work is kept and a re-run resumes.
EXIT_INTERRUPTED = 130


class LBurstError(Exception):
    """Base class of every error that lburst raises on purpose; the message says what and why
    (naming the file where there is one)."""

    #: exit status of the ``lburst`` command when this error ends it
    exit_code: int = EXIT_BAD_INPUT


class LBurstValueError(LBurstError, ValueError):
    """A value lburst cannot use: an option, a spec, a file's contents, a shape."""


class LBurstOSError(LBurstError, OSError):
    """A file that cannot be read or written, found by lburst rather than by the operating system."""


class LBurstFileNotFoundError(LBurstError, FileNotFoundError):
    """A file or folder that lburst needs is not there."""


class LBurstFileExistsError(LBurstError, FileExistsError):
    """A file that lburst would overwrite is there already."""


class RunFailed(LBurstError):
    """A command that ran but whose work failed (COLMAP registered no image, a recording
    stopped early): what it finished is kept, and ``lburst`` exits with :data:`EXIT_FAILED`."""

    exit_code = EXIT_FAILED
