"""Errors that mean "the user asked for something impossible".

Every one of them is turned by the command line into a one-line message and a non-zero exit
status (never a traceback). Library users can catch :class:`PESError` to handle them all.
"""

from __future__ import annotations


class PESError(Exception):
    """Base class of every user-facing error raised by PES."""


class ConfigError(PESError, ValueError):
    """An unknown key, a mistyped value or an impossible setting in a configuration."""


class ActionError(PESError, ValueError):
    """Actions of the wrong shape, or holding NaN or infinite values."""


class CheckpointError(PESError):
    """A missing, corrupted or incompatible checkpoint or record file."""


class TrainingInterruptedError(PESError):
    """A training run stopped by SIGINT or SIGTERM after writing its checkpoint."""


class TrialsFailedError(PESError):
    """Trials of a sweep (``pes reproduce``, ``pes tune``) that Ray reported as failed; their
    tracebacks are in Ray's trial folders, and rerunning the command resumes them."""


class FolderInUseError(PESError):
    """An output folder that another running ``pes train``, ``pes tune`` or ``pes reproduce``
    holds (:mod:`pes.lock`): one writer per folder."""


class ClusterError(PESError):
    """A Ray cluster that cannot be joined (nothing answering at its address, a refused
    authentication) or that lacks the resources a trial needs."""
