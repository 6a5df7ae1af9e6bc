"""Errors of the ``objslam`` command and its tools (the CLI prints any objslam error as one line, exit code 2)."""

from objslam_common.errors import ObjslamError


class ToolsError(ObjslamError):
    """The base of the tools' errors."""


class UserError(ToolsError):
    """A mistake in what the user asked for: a bad path, a bag without a needed topic, ..."""
