"""NanoDet-Plus-m in torch against onnxruntime on the released ONNX it loads its weights from
(`../shared/pretrained/nanodet-plus-m_416.onnx`, beside the checkout as in CI)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch
from numpy.typing import NDArray

from detector.nanodet import NanoDetPlus, load_nanodet_onnx, nanodet_state_dict_from_onnx
from detector.nanodet.decode import decode, top_people
from detector.nanodet.network import BGR_MEAN, BGR_STD, STRIDES
from detector.nanodet.onnx_weights import conv_order
from detector.yolox import PretrainedWeightsError
from detector.yolox.polar import NANODET_PLUS_M, PolarContract, PolarDetectorConfig
from models import ASSETS_DIR
from tests.ci_policy import skip_or_fail_in_ci
from tests.detector.test_yolox_load import smooth_image

SHARED_ONNX = Path(__file__).resolve().parents[2].parent / "shared" / "pretrained" / "nanodet-plus-m_416.onnx"
SIZE = 416
PARITY_ATOL = 1e-3  # the file's weights came from fp16; outputs are probabilities and logits


def nanodet_onnx_path() -> Path:
    if not SHARED_ONNX.is_file():
        skip_or_fail_in_ci(f"{SHARED_ONNX} is not here (../shared beside the checkout)")
    return SHARED_ONNX


@pytest.fixture(scope="module")
def model() -> NanoDetPlus:
    return load_nanodet_onnx(nanodet_onnx_path())


def smooth_bgr(height: int = SIZE, width: int = SIZE) -> NDArray[np.float32]:
    """(1, 3, H, W) BGR 0-255, closer to a photograph than noise (the YOLOX tests' image)."""
    return smooth_image(height, width)


def onnx_output(image_bgr: NDArray[np.float32]) -> NDArray[np.float32]:
    """The released file's `output` (3598, 112) for a (1, 3, 416, 416) BGR 0-255 image."""
    session = ort.InferenceSession(str(nanodet_onnx_path()), providers=["CPUExecutionProvider"])
    mean, std = np.array(BGR_MEAN, np.float32), np.array(BGR_STD, np.float32)
    normalised = (image_bgr - mean[:, None, None]) / std[:, None, None]
    return np.asarray(session.run(None, {"data": normalised.astype(np.float32)})[0][0])


def torch_output(model: NanoDetPlus, image_bgr: NDArray[np.float32]) -> NDArray[np.float32]:
    """The same layout from the torch network: class probabilities then box logits per cell."""
    with torch.no_grad():
        maps = model(torch.from_numpy(image_bgr))
    flat = torch.cat([m.flatten(2).transpose(1, 2) for m in maps], dim=1)[0]  # (A, 112)
    return torch.cat([flat[:, :80].sigmoid(), flat[:, 80:]], dim=1).numpy()


def test_every_convolution_is_loaded_once_in_forward_order(model: NanoDetPlus) -> None:
    order = conv_order(model)
    nodes = [n for n in onnx.load(str(nanodet_onnx_path())).graph.node if n.op_type == "Conv"]
    assert len(order) == len(nodes) == 110
    assert order[0] == "backbone.stem.conv" and order[-1] == "head.preds.3"


@pytest.mark.parametrize("image", ["smooth", "noise"])
def test_torch_network_matches_the_released_onnx(model: NanoDetPlus, image: str) -> None:
    bgr = (smooth_bgr() if image == "smooth"
           else np.random.default_rng(3).uniform(0, 255, (1, 3, SIZE, SIZE)).astype(np.float32))
    expected, got = onnx_output(bgr), torch_output(model, bgr)
    assert got.shape == expected.shape == (3598, 112)
    np.testing.assert_allclose(got, expected, atol=PARITY_ATOL)


def test_any_multiple_of_32_gives_four_levels(model: NanoDetPlus) -> None:
    with torch.no_grad():
        maps = model(torch.zeros(1, 3, 96, 320))
    assert [tuple(m.shape[2:]) for m in maps] == [(12, 40), (6, 20), (3, 10), (2, 5)]
    assert all(m.shape[1] == 112 for m in maps)


def test_person_only_copy_scores_the_person_as_before(model: NanoDetPlus) -> None:
    person = model.to_person_only()
    image = torch.from_numpy(smooth_bgr(128, 256))
    with torch.no_grad():
        full, one = model(image), person(image)
    for f, o in zip(full, one, strict=True):
        torch.testing.assert_close(o[:, 0], f[:, 0])
        torch.testing.assert_close(o[:, 1:], f[:, 80:])


def test_decode_places_boxes_about_the_cells() -> None:
    # One cell of stride 8 at (col 2, row 1) sure of each side's distance: l=1, t=2, r=3, b=4 strides.
    maps = [torch.full((1, 33, 4, 4), -20.0)] + [torch.full((1, 33, s, s), -20.0) for s in (2, 1, 1)]
    for side, bins in enumerate((1, 2, 3, 4)):
        maps[0][0, 1 + side * 8 + bins, 1, 2] = 40.0
    maps[0][0, 0, 1, 2] = 5.0  # its person logit
    boxes = decode(maps, num_classes=1, strides=STRIDES)  # (1, A, 5)
    cell = 1 * 4 + 2
    x1, y1, x2, y2 = 16 - 8, 8 - 16, 16 + 24, 8 + 32
    np.testing.assert_allclose(boxes[0, cell, :4].numpy(), [(x1 + x2) / 2, (y1 + y2) / 2, x2 - x1, y2 - y1],
                               atol=1e-4)
    assert boxes[0, cell, 4] == pytest.approx(torch.sigmoid(torch.tensor(5.0)).item())


def test_contract_finds_the_same_top_people_as_the_network(model: NanoDetPlus) -> None:
    person = model.to_person_only()
    rgb = np.ascontiguousarray(smooth_bgr(128, 256)[0].transpose(1, 2, 0)[..., ::-1])
    strips = torch.from_numpy(rgb)[None].round().to(torch.uint8)  # (1, 128, 256, 3) RGB
    with torch.no_grad():
        boxes, scores = PolarContract(person, 20)(strips)
        cxcywh, top_scores = top_people(person, strips, 20)
    torch.testing.assert_close(scores, top_scores)
    torch.testing.assert_close(boxes[..., 2:] - boxes[..., :2], cxcywh[..., 2:])
    assert boxes.shape == (1, 20, 4) and bool((scores[:, :-1] >= scores[:, 1:]).all())


def test_polar_config_refuses_what_nanodet_lacks() -> None:
    with pytest.raises(ValueError, match="foot"):
        PolarDetectorConfig(network=NANODET_PLUS_M, foot=True)
    with pytest.raises(ValueError, match="none of"):
        PolarDetectorConfig(network="resnet")


def test_a_yolox_file_is_no_nanodet(tmp_path: Path) -> None:
    with pytest.raises(PretrainedWeightsError, match="not NanoDet-Plus-m: 113 Conv nodes, expected 110"):
        nanodet_state_dict_from_onnx(ASSETS_DIR / "pretrained" / "yolox_nano.onnx")
    with pytest.raises(PretrainedWeightsError, match="no such file"):
        nanodet_state_dict_from_onnx(tmp_path / "missing.onnx")
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"not a protobuf at all")
    with pytest.raises(PretrainedWeightsError, match=r"garbage\.onnx"):
        nanodet_state_dict_from_onnx(garbage)


@pytest.mark.slow
def test_zero_shot_checkpoint_exports_a_planned_graph(tmp_path: Path) -> None:
    from detector.checkpoint import ModelInfo, load_checkpoint, save_checkpoint
    from detector.zero_shot import zero_shot_checkpoint
    from exporter.export import export_onnx

    config = PolarDetectorConfig(input_size=64, polar_width=224, polar_overlap=32, network=NANODET_PLUS_M,
                                 peaks=True, planned=True, max_detections=50)
    checkpoint = zero_shot_checkpoint(str(nanodet_onnx_path()), config, ModelInfo(default_min_score=0.3))
    save_checkpoint(tmp_path / "zero.pt", checkpoint)
    loaded = load_checkpoint(tmp_path / "zero.pt")
    assert loaded.config.network == NANODET_PLUS_M  # type: ignore[union-attr]
    # Parity is checked inside, at the trained strip and at a second size (the graph is planned).
    report = export_onnx(loaded, tmp_path / "zero.onnx")
    assert report.parity.max_score_error < 1e-4 and report.max_detections == 50
    metadata = {p.key: p.value for p in onnx.load(str(tmp_path / "zero.onnx")).metadata_props}
    assert metadata["fishloc.view_planned"] == "1" and "NanoDet-Plus-m" in metadata["fishloc.licence"]
