"""Exporter: trained checkpoint -> ONNX model of the FishLoc contract, parity check, INT8 quantisation.

The exported graph is read back through `contract`, the torch-free reader the service and
evaluation share, so the parity check runs the model exactly as it is served.
"""
