"""Training the baselines: the loop, checkpoint selection and publishing, learning curves, the epsilon sweep."""
