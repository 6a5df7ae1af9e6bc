"""objslam core: odometry and slices to the object-based map.

``model`` holds the measurement model, ``graph`` the factor graph of one association and
its solvers, ``inference`` the unknown data association and map building, ``pipeline``
the one entry point. None of it imports rclpy or message types; the node and its message
helpers live under ``ros``.
"""

# First, before any module here loads numpy: it pins BLAS to one thread (objslam_common.process);
# a script or a Ray worker that imports a submodule directly would otherwise get a thread per core.
import objslam_common  # noqa: F401
