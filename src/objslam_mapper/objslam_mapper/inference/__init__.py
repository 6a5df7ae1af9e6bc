"""Unknown data association: tracklets, the target, the Metropolis-Hastings chain and paper Algorithm 1."""
