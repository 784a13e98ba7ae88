from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import pytest
import torch

from contract import FisheyeInput, OnnxModel, RawOutputs, SessionThreads, select_detections
from detector.checkpoint import Checkpoint, CheckpointError, ModelInfo, load_checkpoint, save_checkpoint
from detector.model import build_model, tiny_config
from exporter.export import contract_model, export_onnx
from exporter.parity import check_parity, synthetic_parity_frames
from fisheye import Letterbox
from service.cli import main

REQUIRED_METADATA = ("fishloc.view", "fishloc.input_size", "fishloc.pad_value", "fishloc.box_format",
                     "fishloc.model_name", "fishloc.model_version", "fishloc.trained_on",
                     "fishloc.default_min_score")


def _onnx(path: Path) -> OnnxModel:
    return OnnxModel(path, SessionThreads(intra_op=1))


def _infer(model: OnnxModel, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    raw = model.run_batch(frames)
    return np.stack([r.boxes for r in raw]), np.stack([r.scores for r in raw])

SIZE = 64


def _varied_checkpoint(seed: int = 0) -> Checkpoint:
    """A tiny random network whose heatmap varies strongly, so that some scores pass 0.3."""
    torch.manual_seed(seed)
    config = tiny_config(SIZE)
    net = build_model(config)
    with torch.no_grad():
        net.head.heatmap.weight.normal_(0.0, 0.6)
        net.head.heatmap.bias.fill_(-0.5)
        net.head.regression.weight.normal_(0.0, 0.05)
    net.eval()
    return Checkpoint(config, net.state_dict(), ModelInfo("1.2.3", "unit-test frames", 0.3))


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Checkpoint, Path, Path]:
    folder = tmp_path_factory.mktemp("export")
    checkpoint = _varied_checkpoint()
    checkpoint_path = folder / "tiny.pt"
    save_checkpoint(checkpoint_path, checkpoint)
    model_path = folder / "tiny.onnx"
    report = export_onnx(load_checkpoint(checkpoint_path), model_path)
    assert report.parity.detections_above_threshold > 0  # the comparison covered real detections
    return checkpoint, checkpoint_path, model_path


def test_contract_inputs_outputs_and_metadata(exported: tuple[Checkpoint, Path, Path]) -> None:
    _, _, model_path = exported
    proto = onnx.load(str(model_path))
    onnx.checker.check_model(proto, full_check=True)
    props = {p.key: p.value for p in proto.metadata_props}
    assert set(REQUIRED_METADATA) <= set(props)
    assert props["fishloc.input_size"] == str(SIZE)
    assert props["fishloc.box_format"] == "cxcywh_radius_aligned" and props["fishloc.view"] == "fisheye"
    assert props["fishloc.model_version"] == "1.2.3"
    assert props["fishloc.trained_on"] == "unit-test frames"
    (image,) = proto.graph.input
    tensor = image.type.tensor_type
    assert image.name == "image" and tensor.elem_type == onnx.TensorProto.UINT8
    dims = [d.dim_param or d.dim_value for d in tensor.shape.dim]
    assert isinstance(dims[0], str) and dims[1:] == [SIZE, SIZE, 3]
    assert [o.name for o in proto.graph.output] == ["boxes", "scores"]
    node_keys = {entry.key for node in proto.graph.node for entry in node.metadata_props}
    assert "namespace" in node_keys and "pkg.torch.onnx.stack_trace" not in node_keys  # no machine's paths


@pytest.mark.parametrize("batch", [1, 3])
def test_parity_with_torch_and_dynamic_batch(exported: tuple[Checkpoint, Path, Path], batch: int) -> None:
    checkpoint, _, model_path = exported
    detector = _onnx(model_path)
    frames = synthetic_parity_frames(SIZE, count=batch, seed=7)
    report = check_parity(contract_model(checkpoint)[0], detector, frames, threshold=0.3)
    assert report.frames == batch
    boxes, scores = _infer(detector, frames)
    K = checkpoint.config.max_detections
    assert boxes.shape == (batch, K, 4) and scores.shape == (batch, K)
    assert np.all(np.diff(scores, axis=1) <= 0)  # sorted descending
    # Each image of a batch gives what it gives alone.
    _, single_scores = _infer(detector, frames[-1:])
    np.testing.assert_allclose(single_scores[0], scores[-1], atol=1e-5)


def test_parity_check_fails_loudly_on_a_different_model(exported: tuple[Checkpoint, Path, Path]) -> None:
    _, _, model_path = exported
    other, _ = contract_model(_varied_checkpoint(seed=1))
    with pytest.raises(RuntimeError, match=r"no counterpart|detections above|differ"):
        check_parity(other, _onnx(model_path), synthetic_parity_frames(SIZE, 2), threshold=0.3)


def test_postprocess_maps_boxes_back_to_the_frame() -> None:
    letterbox = Letterbox.fit((200, 100), 64)  # 2x wider than high -> scale 0.32, pad rows
    boxes = np.array([[31.5, 31.5, 4.0, 8.0], [10.0, 20.0, 2.0, 3.0], [0.0, 0.0, 1.0, 1.0]], np.float32)
    scores = np.array([0.9, 0.5, 0.1], np.float32)
    found = select_detections(RawOutputs(boxes, scores), FisheyeInput(letterbox), (99.5, 49.5),
                              min_score=0.3, nms_iou=None)
    np.testing.assert_allclose(found.scores, [0.9, 0.5], rtol=1e-6)
    np.testing.assert_allclose(found.boxes_cxcywh[0], [99.5, 49.5, 12.5, 25.0], rtol=1e-5)
    np.testing.assert_allclose(found.principal_point, (99.5, 49.5), rtol=1e-6)


def test_int8_export_runs_integer_convolutions(tmp_path: Path) -> None:
    checkpoint = _varied_checkpoint()
    frames = synthetic_parity_frames(SIZE, count=6, seed=3)
    report = export_onnx(checkpoint, tmp_path / "int8.onnx", int8=True, calibration_frames=frames)
    assert report.integer_ops is not None
    assert report.integer_ops.get("QLinearConv", 0) >= 10
    assert report.integer_ops.get("Conv", 0) == 0
    detector = _onnx(tmp_path / "int8.onnx")
    assert detector.info.version == "1.2.3"
    boxes, scores = _infer(detector, frames[:2])
    assert boxes.shape == (2, checkpoint.config.max_detections, 4) and np.all(np.isfinite(scores))


def test_cli_reports_corrupt_and_mismatched_checkpoints(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(b"not a checkpoint at all" * 10)
    assert main(["export", "--checkpoint", str(corrupt), "--output", str(tmp_path / "x.onnx")]) == 2
    assert "cannot be read" in capsys.readouterr().err

    checkpoint = _varied_checkpoint()
    state = checkpoint.model_state
    wrong_config = tiny_config(SIZE)
    wrong = Checkpoint(type(wrong_config)(**{**wrong_config.to_dict(), "neck_width": 20,
                                             "widths": wrong_config.widths, "blocks": wrong_config.blocks}),
                       state)
    save_checkpoint(tmp_path / "wrong.pt", wrong)
    assert main(["export", "--checkpoint", str(tmp_path / "wrong.pt"),
                 "--output", str(tmp_path / "y.onnx")]) == 2
    assert "do not fit its network config" in capsys.readouterr().err
    with pytest.raises(CheckpointError, match="does not exist"):
        load_checkpoint(tmp_path / "missing.pt")
    assert not (tmp_path / "x.onnx").exists() and not (tmp_path / "y.onnx").exists()


def test_calibration_frames_are_the_models_own_inputs(tmp_path: Path) -> None:
    import shutil

    from contract import ModelInfo, PolarSpec
    from exporter.export import load_calibration_frames

    samples = Path(__file__).resolve().parents[2] / "samples"
    polar = ModelInfo(name="p", version="1", view="polar", input_size=64, pad_value=0, default_min_score=0.3,
                      trained_on="x", box_format="xyxy_polar", polar=PolarSpec(256, 32, 90.0))
    strips = load_calibration_frames(samples, polar)  # a synth folder: each frame with its camera
    assert strips.shape == (3, 64, 288, 3) and strips.dtype == np.uint8 and strips.std() > 5
    plain = tmp_path / "plain"
    plain.mkdir()
    shutil.copy(samples / "000001.jpg", plain / "a.jpg")  # no annotations: the assumed camera
    fisheye = ModelInfo(name="f", version="1", view="fisheye", input_size=64, pad_value=0,
                        default_min_score=0.3, trained_on="x", box_format="cxcywh_radius_aligned")
    assert load_calibration_frames(plain, fisheye).shape == (1, 64, 64, 3)
    with pytest.raises(ValueError, match="no images"):
        load_calibration_frames(tmp_path, fisheye)
