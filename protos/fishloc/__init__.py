"""Package fishloc of the gRPC API."""
