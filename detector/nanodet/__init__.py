"""NanoDet-Plus-m in PyTorch, initialised from the released COCO weights (../shared/pretrained)."""

from detector.nanodet.network import PERSON, STRIDES, NanoDetConfig, NanoDetPlus, keep_classes
from detector.nanodet.onnx_weights import load_nanodet_onnx, nanodet_state_dict_from_onnx

__all__ = ["PERSON", "STRIDES", "NanoDetConfig", "NanoDetPlus", "keep_classes", "load_nanodet_onnx",
           "nanodet_state_dict_from_onnx"]
