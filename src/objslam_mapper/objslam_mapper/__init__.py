"""objslam core: the object-based SLAM model, factor graph, association and map building.

Everything in this package except ``objslam_mapper.node`` and ``objslam_mapper.ros``
imports no rclpy and no message types, so the whole pipeline runs and is tested without
a ROS graph.
"""

import os

# The solver's linear systems are small (poses banded, a few objects dense): BLAS threads
# only contend for the two cores and made a warm solve several times slower when measured.
# Set before numpy loads its BLAS; a value the user exported wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
del _var
