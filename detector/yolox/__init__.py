"""YOLOX-Nano in PyTorch, initialised from the released COCO weights (models/pretrained)."""

from detector.yolox.decode import class_scores, decode, flatten_maps, to_onnx_layout
from detector.yolox.network import PERSON, STRIDES, YoloxConfig, YoloxNano, keep_classes
from detector.yolox.onnx_weights import PretrainedWeightsError, load_yolox_onnx, yolox_state_dict_from_onnx

__all__ = [
    "PERSON",
    "STRIDES",
    "PretrainedWeightsError",
    "YoloxConfig",
    "YoloxNano",
    "class_scores",
    "decode",
    "flatten_maps",
    "keep_classes",
    "load_yolox_onnx",
    "to_onnx_layout",
    "yolox_state_dict_from_onnx",
]
