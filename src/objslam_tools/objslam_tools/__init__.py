"""objslam_tools: the ``objslam`` command, the bag simulator, bag I/O and evaluation."""
