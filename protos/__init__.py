"""gRPC API definitions (protos/fishloc/v1/*.proto) and their generated Python stubs."""
