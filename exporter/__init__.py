"""Exporter: trained checkpoint -> ONNX model of the FishLoc contract, parity check, INT8 quantisation.

`exporter.onnx_runner` is the torch-free runtime side (letterbox, run, map boxes back to the frame)
that evaluation and the service share.
"""
