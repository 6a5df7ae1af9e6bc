"""Node-side helpers (rclpy and message types live here and in the nodes, never in the core)."""
