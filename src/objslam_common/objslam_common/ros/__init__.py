"""ROS helpers of the nodes: parameters, message conversions, the spin loop."""
