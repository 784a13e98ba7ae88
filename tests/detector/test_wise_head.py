"""The head interpolated towards the pretrained one (WiSE-FT): only the head moves."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from detector.yolox.wise import interpolate_head, interpolate_network
from models import ASSETS_DIR

COCO_ONNX = ASSETS_DIR / "pretrained" / "yolox_nano.onnx"


def _states() -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    pretrained = {"backbone.w": torch.ones(3), "head.cls.w": torch.zeros(2, 2),
                  "head.steps": torch.tensor(7), "foot.w": torch.zeros(4)}
    fine_tuned = {"backbone.w": torch.ones(3), "head.cls.w": torch.full((2, 2), 4.0),
                  "head.steps": torch.tensor(7), "foot.w": torch.full((4,), 9.0)}
    return fine_tuned, pretrained


@pytest.mark.parametrize(("alpha", "head"), [(1.0, 4.0), (0.0, 0.0), (0.9, 3.6), (0.25, 1.0)])
def test_only_the_head_is_interpolated(alpha: float, head: float) -> None:
    fine_tuned, pretrained = _states()
    blended = interpolate_head(fine_tuned, pretrained, alpha)
    assert torch.allclose(blended["head.cls.w"], torch.full((2, 2), head))
    assert torch.equal(blended["backbone.w"], fine_tuned["backbone.w"])
    assert torch.equal(blended["foot.w"], fine_tuned["foot.w"])  # the foot branch is the fine-tuned one's
    assert torch.equal(blended["head.steps"], torch.tensor(7))  # integer buffers are not averaged
    assert torch.equal(fine_tuned["head.cls.w"], torch.full((2, 2), 4.0))  # the input is left alone


def test_a_network_trained_beyond_its_head_is_refused() -> None:
    fine_tuned, pretrained = _states()
    fine_tuned["backbone.w"] = torch.full((3,), 2.0)
    with pytest.raises(ValueError, match="outside the head"):
        interpolate_head(fine_tuned, pretrained, 0.9)


@pytest.mark.parametrize("change", ["missing", "shape"])
def test_heads_that_do_not_match_are_refused(change: str) -> None:
    fine_tuned, pretrained = _states()
    if change == "missing":
        del pretrained["head.cls.w"]
    else:
        pretrained["head.cls.w"] = torch.zeros(3, 2)
    with pytest.raises(ValueError, match="no counterpart"):
        interpolate_head(fine_tuned, pretrained, 0.9)


@pytest.mark.parametrize("alpha", [-0.1, 1.5, float("nan")])
def test_alpha_outside_0_1_is_refused(alpha: float) -> None:
    with pytest.raises(ValueError, match="alpha"):
        interpolate_head(*_states(), alpha)


def test_a_nanodet_head_is_interpolated_towards_its_coco_head() -> None:
    # The NanoDet-Plus-m network reads its COCO head back from the file it started from: halfway
    # between a moved head and that one is the mean, and everything outside the head stays.
    from detector.checkpoint import ModelInfo
    from detector.yolox.polar import NANODET_PLUS_M, PolarDetectorConfig
    from detector.yolox.wise import wise_checkpoint
    from detector.zero_shot import zero_shot_checkpoint

    onnx = Path(__file__).resolve().parents[2].parent / "shared" / "pretrained" / "nanodet-plus-m_416.onnx"
    config = PolarDetectorConfig(input_size=64, polar_width=224, polar_overlap=32, network=NANODET_PLUS_M)
    coco = zero_shot_checkpoint(str(onnx), config, ModelInfo())
    moved = {name: tensor + 1.0 if name.startswith("head.") and tensor.is_floating_point() else tensor
             for name, tensor in coco.model_state.items()}
    fine_tuned = type(coco)(config, moved, coco.info, {})
    blended = wise_checkpoint(fine_tuned, str(onnx), 0.5).model_state
    for name, tensor in coco.model_state.items():
        expected = tensor + 0.5 if name.startswith("head.") and tensor.is_floating_point() else tensor
        assert torch.allclose(blended[name], expected, atol=1e-6), name


# ----- the whole network towards the checkpoint its run started from


@pytest.mark.parametrize(("alpha", "weight"), [(1.0, 4.0), (0.0, 0.0), (0.5, 2.0)])
def test_every_weight_is_interpolated_towards_the_start(alpha: float, weight: float) -> None:
    fine_tuned, start = _states()
    fine_tuned["backbone.w"] = torch.full((3,), 5.0)
    start["foot.w"] = torch.full((4,), 1.0)
    blended = interpolate_network(fine_tuned, start, alpha)
    assert torch.allclose(blended["head.cls.w"], torch.full((2, 2), weight))
    assert torch.allclose(blended["backbone.w"], torch.full((3,), alpha * 5.0 + (1 - alpha) * 1.0))
    assert torch.allclose(blended["foot.w"], torch.full((4,), alpha * 9.0 + (1 - alpha) * 1.0))
    assert torch.equal(blended["head.steps"], torch.tensor(7))


@pytest.mark.parametrize("change", ["missing", "shape", "alpha"])
def test_networks_that_do_not_match_are_refused_whole(change: str) -> None:
    fine_tuned, start = _states()
    alpha = 0.5
    if change == "missing":
        del start["backbone.w"]
    elif change == "shape":
        start["backbone.w"] = torch.ones(4)
    else:
        alpha = 1.5
    named = {"missing": "names", "shape": "backbone.w", "alpha": "alpha"}[change]
    with pytest.raises(ValueError, match=named):
        interpolate_network(fine_tuned, start, alpha)


def test_cli_interpolates_a_whole_run_towards_its_start_and_refuses_another_network(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from detector.checkpoint import Checkpoint, load_checkpoint, main, save_checkpoint
    from detector.yolox.polar import PolarDetectorConfig, init_from_pretrained

    config = PolarDetectorConfig(input_size=64, polar_width=256, polar_overlap=32)
    start = init_from_pretrained(str(COCO_ONNX), config).state_dict()
    moved = {k: v + 1.0 if v.is_floating_point() else v for k, v in start.items()}
    save_checkpoint(tmp_path / "start.pt", Checkpoint(config, start))
    save_checkpoint(tmp_path / "run.pt", Checkpoint(config, moved))
    run, start_path = str(tmp_path / "run.pt"), str(tmp_path / "start.pt")
    assert main([run, str(tmp_path / "half.pt"), "--wise-from", start_path, "--wise-alpha", "0.5"]) == 0
    half = load_checkpoint(tmp_path / "half.pt").model_state
    for name, tensor in start.items():
        expected = tensor + 0.5 if tensor.is_floating_point() else tensor
        assert torch.allclose(half[name], expected, atol=1e-6), name
    wider = PolarDetectorConfig(input_size=64, polar_width=288, polar_overlap=32)
    save_checkpoint(tmp_path / "other.pt", Checkpoint(wider, start))
    assert main([run, str(tmp_path / "refused.pt"), "--wise-from", str(tmp_path / "other.pt")]) == 2
    assert "another network or view" in capsys.readouterr().err
    assert not (tmp_path / "refused.pt").exists()
    missing = str(tmp_path / "missing.onnx")  # the head's interpolation refused: nothing written either
    assert main([run, str(tmp_path / "refused.pt"), "--wise-ft", missing]) == 2
    assert "missing.onnx" in capsys.readouterr().err
    assert not (tmp_path / "refused.pt").exists()
    with pytest.raises(SystemExit):
        main([run, str(tmp_path / "both.pt"), "--wise-from", start_path, "--wise-ft", str(COCO_ONNX)])
