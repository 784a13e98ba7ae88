"""Data: the synthetic scene renderer and the dataset readers."""
