"""The measurement model: what a slice and an odometry increment predict, outliers, and the floor."""
