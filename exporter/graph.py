"""The module that becomes the ONNX graph: uint8 RGB images in, decoded boxes and scores out.

Everything model-specific (normalisation, the network, peak extraction, top-K) lives inside, so the
service only letterboxes frames and reads `boxes` (N, K, 4) and `scores` (N, K).
"""

from __future__ import annotations

from torch import Tensor, nn

from detector.decode import decode
from detector.model import FishLocNet


class ContractModel(nn.Module):
    """(N, S, S, 3) uint8 RGB -> boxes (N, K, 4) float32 input px `cxcywh`, scores (N, K) float32."""

    def __init__(self, net: FishLocNet) -> None:
        super().__init__()
        self.net = net
        self.input_size = net.config.input_size
        self.max_detections = net.config.max_detections

    def forward(self, image: Tensor) -> tuple[Tensor, Tensor]:
        predictions = self.net(self.net.normalise(image))  # (N, 5, S/4, S/4)
        return decode(predictions, self.input_size, self.max_detections)
