"""The reference camera gateway: frame sources and the StreamDetect client."""
