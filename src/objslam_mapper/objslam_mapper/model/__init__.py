"""The measurement model: what a slice and an odometry increment predict, and how far from it a measurement may be."""
