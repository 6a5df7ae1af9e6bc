"""What every objslam package shares: cameras and the mount, the class catalog, geometry,
input records, configuration and errors (numpy and PyYAML only), and, under ``ros``, the
helpers the nodes use (rclpy and message types live there and nowhere else here)."""

from objslam_common.process import keep_freed_memory, pin_blas_threads

# Before numpy loads its BLAS; what and why: objslam_common.process.
pin_blas_threads()
keep_freed_memory()
