"""`python -m detector.zero_shot`: a release checkpoint of a COCO network as it is (its person class,
no training) reading the polar view, to export and evaluate beside the fine-tuned models.

    python -m detector.zero_shot --network nanodet-plus-m ../shared/pretrained/nanodet-plus-m_416.onnx \\
        runs/nanodet-zero-shot.pt
    fishloc eval --operating-point --model runs/nanodet-zero-shot.pt --data data/val1024/annotations.json
    fishloc export --checkpoint runs/nanodet-zero-shot.pt --output nanodet.onnx --min-score T --nms-iou I

The graph takes planned views and its top K among peak cells (as 0.6.0's), unless told otherwise.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from detector.checkpoint import Checkpoint, ModelInfo, save_checkpoint
from detector.yolox.onnx_weights import PretrainedWeightsError
from detector.yolox.polar import (
    NANODET_PLUS_M,
    NETWORKS,
    YOLOX_NANO,
    PolarDetectorConfig,
    init_network_from_pretrained,
)

TRAINED_ON = {YOLOX_NANO: "COCO 2017 (YOLOX-Nano), zero-shot",
              NANODET_PLUS_M: "COCO 2017 (NanoDet-Plus-m), zero-shot"}


def zero_shot_checkpoint(onnx_path: str, config: PolarDetectorConfig, info: ModelInfo) -> Checkpoint:
    """The person network of the COCO ONNX at `onnx_path` in `config` (its `network`), unchanged."""
    network = init_network_from_pretrained(onnx_path, config)
    return Checkpoint(config, network.state_dict(), info, {})


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m detector.zero_shot", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("onnx", help="the COCO network's ONNX (../shared/pretrained/)")
    parser.add_argument("target", help="release checkpoint to write")
    parser.add_argument("--network", choices=NETWORKS, default=YOLOX_NANO)
    parser.add_argument("--min-score", type=float, default=0.3, help="the default score threshold")
    parser.add_argument("--nms-iou", type=float, default=0.35, help="the rotated NMS IoU")
    parser.add_argument("--fixed-strip", action="store_true",
                        help="a graph of the fixed strip (no planned views, no peak cells)")
    args = parser.parse_args(argv)
    graph = not args.fixed_strip
    config = PolarDetectorConfig(network=args.network, model_name=f"fishloc-{args.network}-polar",
                                 peaks=graph, planned=graph)
    info = ModelInfo(model_version="0.0.0", trained_on=TRAINED_ON[args.network],
                     default_min_score=args.min_score, nms_iou=args.nms_iou)
    try:
        save_checkpoint(args.target, zero_shot_checkpoint(args.onnx, config, info))
    except (PretrainedWeightsError, ValueError) as error:
        print(f"detector.zero_shot: {error}", file=sys.stderr)
        return 2
    print(f"wrote {args.target}: {args.network} zero-shot")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
