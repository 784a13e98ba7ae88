"""`fishloc eval --tracks`: play a site sequence and score the site's tracks, zone counts and lines.

`--server URL` plays it against a running `fishloc serve`; `--model PATH` against the same server
run in this process; `--ground-truth-detections` feeds the annotated positions to the tracker's
in-process API instead (what fusion and tracking alone achieve). Figures: `evaluation.track_scoring`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from tqdm import tqdm

from evaluation.sequence_data import Sequence, SequenceFormatError, read_sequence
from evaluation.track_playback import (
    LocalServer,
    PlaybackError,
    ServerClient,
    play_ground_truth,
    play_through_server,
)
from evaluation.track_scoring import GATE_M, Reported, score_sequence


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = ("Play a site sequence (fishloc synth --sequence) through a server, one run in this "
                          "process, or the tracker alone, and score its tracks, zone counts and line counts.")
    parser.add_argument("--tracks", action="store_true", required=True,
                        help="score a site sequence's tracks (fishloc synth --sequence)")
    parser.add_argument("--data", required=True, type=Path, help="the sequence's annotations.json")
    parser.add_argument("--json", required=True, type=Path, help="where to write the figures")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--server", help="URL of a running fishloc serve (e.g. http://127.0.0.1:8000)")
    source.add_argument("--model", type=Path, help="ONNX model: serve it in this process and play through it")
    source.add_argument("--ground-truth-detections", action="store_true",
                        help="feed the annotated positions to the tracker instead of detecting")
    parser.add_argument("--noise-m", type=float, default=0.0,
                        help="with --ground-truth-detections: Gaussian noise (m per axis) on each position")
    parser.add_argument("--token", help="the server's API token (camera, zone and line writes; it passes "
                                        "site reads too)")
    parser.add_argument("--threads", type=int, help="with --model: inference threads")
    parser.add_argument("--min-score", type=float,
                        help="with --server or --model: detections kept (default: the model's threshold)")
    parser.add_argument("--gate-m", type=float, default=GATE_M, help="match distance in the floor plane")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _summary(figures: dict[str, Any]) -> str:
    def num(value: Any, digits: int = 3) -> str:
        return "n/a" if value is None else f"{value:.{digits}f}"

    return (f"MOTA {num(figures['mota'])}  IDF1 {num(figures['idf1'])}  "
            f"ID switches {figures['id_switches']}  "
            f"duplicates {num(100 * figures['duplicate_rate'], 2)} %  zone count MAE "
            f"{num(figures['zone_count_mae'], 2)}  worst line error {num(figures['line_error_max'])}")


def _play(url: str, token: str | None, sequence: Sequence, bar: tqdm, min_score: float | None) -> Reported:
    client = ServerClient(url, token)
    try:
        return play_through_server(client, sequence, lambda: bar.update(1), min_score)
    finally:
        client.close()


def run(args: argparse.Namespace) -> int:
    if args.noise_m < 0 or args.gate_m <= 0 or not 0 <= (args.min_score or 0) <= 1:
        print("fishloc eval: --noise-m must be >= 0, --gate-m > 0, --min-score within [0, 1]",
              file=sys.stderr)
        return 2
    try:
        import motmetrics  # noqa: F401  (scoring needs it; say so before playing for minutes)
    except ModuleNotFoundError:
        print("fishloc eval --tracks needs motmetrics: pip install 'fishloc[train]'", file=sys.stderr)
        return 2
    try:
        sequence = read_sequence(args.data)
    except (OSError, ValueError, KeyError, SequenceFormatError) as error:
        print(f"fishloc eval: cannot read {args.data}: {error}", file=sys.stderr)
        return 2
    started = time.perf_counter()
    with tqdm(total=len(sequence.steps), unit="step", disable=args.quiet) as bar:
        try:
            if args.ground_truth_detections:
                mode = "ground_truth_detections"
                reported = play_ground_truth(sequence, args.noise_m, on_step=lambda: bar.update(1))
            elif args.server:
                mode = "server"
                reported = _play(args.server, args.token, sequence, bar, args.min_score)
            else:
                mode = "model"
                with LocalServer(args.model, args.threads) as server:
                    reported = _play(server.url, None, sequence, bar, args.min_score)
        except (PlaybackError, OSError) as error:
            print(f"fishloc eval: {error}", file=sys.stderr)
            return 1
    figures = score_sequence(sequence, reported, args.gate_m)
    frames = sum(len(step.frames) for step in sequence.steps)
    document = {"data": str(args.data), "mode": mode, "site": sequence.site_id, "steps": len(sequence.steps),
                "frames": frames, "cameras": [c["id"] for c in sequence.cameras],
                "noise_m": args.noise_m if args.ground_truth_detections else None,
                "min_score": None if args.ground_truth_detections else args.min_score,
                "seconds": round(time.perf_counter() - started, 1), **figures}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
    print(f"{mode}: {_summary(figures)} -> {args.json}")
    return 0
