"""objslam core: the object-based SLAM model, factor graph, association and map building.

Everything in this package except ``objslam_mapper.node`` imports no rclpy and no
message types, so the whole pipeline runs and is tested without a ROS graph.
"""
