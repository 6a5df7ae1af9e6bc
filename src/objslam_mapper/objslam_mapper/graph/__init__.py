"""The factor graph of one association: problem, keyframes, linear systems, solvers, covariances."""
