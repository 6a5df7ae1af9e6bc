"""What every objslam package shares: cameras and the mount, the class catalog, geometry,
input records, configuration and errors (numpy and PyYAML only), and, under ``ros``, the
helpers the nodes use (rclpy and message types live there and nowhere else here)."""

import os

# The solver's linear systems are small (poses banded, a few objects dense): BLAS threads
# only contend for the cores and made a warm solve several times slower when measured.
# Every objslam package imports this one first, so this runs before numpy loads its BLAS;
# a value the user exported wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
del _var
