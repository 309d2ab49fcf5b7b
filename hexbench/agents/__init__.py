"""Controllers built from shipped weights (the trained baselines)."""
