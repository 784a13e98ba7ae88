"""`fishloc gateway`: stream a camera's frames to a FishLoc server over gRPC, print the answers."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from pathlib import Path
from typing import TextIO

from service.gateway.client import Gateway, GatewayConfig
from service.gateway.frame_sources import FrameSource, InterleavedSource, ReopenPolicy, open_source


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Stream frames to `fishloc serve` (StreamDetect) and write each answer as a JSON line. "
        "At the end, the counts (sent, answered, dropped, errors, lost, reconnects) go to stderr."
    )
    parser.add_argument("--server", required=True, metavar="HOST:PORT",
                        help="gRPC address, e.g. localhost:50051")
    parser.add_argument("--camera", required=True, metavar="ID", action="append",
                        help="camera id in the server's registry; repeat --camera ID --source SRC to "
                             "stream several cameras (e.g. of one site) on one stream, a frame of each in "
                             "turn")
    parser.add_argument("--source", required=True, metavar="SRC", action="append",
                        help="video file, rtsp:// or http:// URL, folder of images, or webcam index (0)")
    parser.add_argument("--fps", type=float, default=None,
                        help="send at most N frames per second of each camera (default: a video file's "
                             "own rate; folders and live sources unpaced; 0: unpaced)")
    parser.add_argument("--min-score", type=float, default=None,
                        help="score threshold (default: the model's)")
    parser.add_argument("--out", type=Path, default=None, help="write the JSON lines here instead of stdout")
    parser.add_argument("--max-backoff", type=float, default=30.0,
                        help="longest wait between reconnects to the server, and between attempts to "
                             "open a live source (URL, webcam) again (s)")


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s",
                        stream=sys.stderr)
    if len(args.camera) != len(args.source) or len(set(args.camera)) != len(args.camera):
        print("fishloc gateway: give one --source per --camera, each camera once", file=sys.stderr)
        return 2
    try:
        reopen = ReopenPolicy(first_backoff_s=min(0.5, args.max_backoff), max_backoff_s=args.max_backoff)
        pairs = zip(args.camera, args.source, strict=True)
        sources = {camera: open_source(src, reopen) for camera, src in pairs}
    except ValueError as error:
        print(f"fishloc gateway: {error}", file=sys.stderr)
        return 2
    source: FrameSource = sources[args.camera[0]] if len(sources) == 1 else InterleavedSource(sources)
    fps = args.fps * len(sources) if args.fps else args.fps
    config = GatewayConfig(server=args.server, camera_id=args.camera[0], fps=fps,
                           min_score=args.min_score, max_backoff_s=args.max_backoff)
    out: TextIO = args.out.open("w", encoding="utf-8") if args.out is not None else sys.stdout

    def write_line(line: str) -> None:
        out.write(line + "\n")
        out.flush()

    gateway = Gateway(config, source, write_line)

    async def stream() -> None:
        try:
            await gateway.run()
        finally:
            source.stop()  # on Ctrl-C, a wait between attempts to open the source ends at once

    try:
        asyncio.run(stream())
    except KeyboardInterrupt:
        pass
    finally:
        source.close()
        if out is not sys.stdout:
            out.close()
        print(gateway.summary(), file=sys.stderr)
    return 0
