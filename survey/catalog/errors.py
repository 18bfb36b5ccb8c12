"""The exceptions survey raises for bad input, unreadable files and work that cannot go on;
each message is one line naming what is wrong and what to do. Numerical trouble inside a
cell is never one of them: it becomes the cell's Status."""
from __future__ import annotations


class ConfigError(ValueError):
    """A bad configuration: one line naming the key and the fix."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key


class ArchiveError(ValueError):
    """A file that is not a readable survey archive: one line saying what it is instead."""


class SurveyError(RuntimeError):
    """A survey that cannot go on for a reason outside its config (a full disk, a busy
    output, cells that could not be computed): one line saying what and what to do."""


class Inaccessible(Exception):
    """No initial condition exists at this grid point (e.g. U(q0) > E): a cell status, not
    an input error."""
