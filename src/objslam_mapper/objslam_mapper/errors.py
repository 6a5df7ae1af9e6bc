"""The base of the mapper's errors; each subpackage raises its own subclasses of it."""

from objslam_common.errors import ObjslamError


class MapperError(ObjslamError):
    """Inputs or settings the mapper cannot turn into a map."""
