"""The root of every objslam error, and the errors of the shared package.

Each package has one base below :class:`ObjslamError` (``DetectorError``, ``MapperError``,
``ToolsError``), and each error says in one line what is wrong; the ``objslam`` command
prints that line and exits with code 2. Errors about values also derive from ValueError,
so code that validates with the standard exceptions keeps working.
"""


class ObjslamError(Exception):
    """Anything objslam reports as a failure of what it was given."""


class ConfigError(ObjslamError, ValueError):
    """A configuration file or value that cannot be used.

    Its message quotes what the file holds (a key may hold a line break): line breaks are
    escaped, so that the error stays the one line the command prints.
    """

    def __init__(self, message: str = "") -> None:
        super().__init__(str(message).replace("\r", "\\r").replace("\n", "\\n"))


class RecordError(ObjslamError, ValueError):
    """An input record with impossible values."""


class CameraModelError(ObjslamError, ValueError):
    """A calibration that no supported camera model can represent."""


class MessageError(ObjslamError, ValueError):
    """A message that cannot become a record (the nodes count and drop it).

    ``kind`` names the problem without its numbers, so that warnings can be rate-limited
    per kind of problem.
    """

    def __init__(self, kind: str, detail: str = ""):
        super().__init__(f"{kind} ({detail})" if detail else kind)
        self.kind = kind
