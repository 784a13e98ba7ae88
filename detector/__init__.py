"""FishLoc detector: network, losses, datasets, training and evaluation (PyTorch)."""
