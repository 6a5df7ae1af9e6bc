"""The nodes and what only they need (rclpy and message types live here, never in the core)."""
