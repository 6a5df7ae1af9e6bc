"""One module per ``objslam`` verb; each exposes ``register(subparsers)``."""
