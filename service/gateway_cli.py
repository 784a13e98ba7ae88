"""`fishloc gateway`: stream a camera's frames to a FishLoc server over gRPC, print the answers."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from pathlib import Path
from typing import TextIO

from service.frame_sources import ReopenPolicy, open_source
from service.gateway import Gateway, GatewayConfig


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Stream frames to `fishloc serve` (StreamDetect) and write each answer as a JSON line. "
        "At the end, the counts (sent, answered, dropped, errors, lost, reconnects) go to stderr."
    )
    parser.add_argument("--server", required=True, metavar="HOST:PORT",
                        help="gRPC address, e.g. localhost:50051")
    parser.add_argument("--camera", required=True, metavar="ID", help="camera id in the server's registry")
    parser.add_argument("--source", required=True, metavar="SRC",
                        help="video file, rtsp:// or http:// URL, folder of images, or webcam index (0)")
    parser.add_argument("--fps", type=float, default=None,
                        help="send at most N frames per second (default: a video file's own rate; "
                             "folders and live sources unpaced; 0: unpaced)")
    parser.add_argument("--min-score", type=float, default=None,
                        help="score threshold (default: the model's)")
    parser.add_argument("--out", type=Path, default=None, help="write the JSON lines here instead of stdout")
    parser.add_argument("--max-backoff", type=float, default=30.0,
                        help="longest wait between reconnects to the server, and between attempts to "
                             "open a live source (URL, webcam) again (s)")


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s",
                        stream=sys.stderr)
    try:
        reopen = ReopenPolicy(first_backoff_s=min(0.5, args.max_backoff), max_backoff_s=args.max_backoff)
        source = open_source(args.source, reopen)
    except ValueError as error:
        print(f"fishloc gateway: {error}", file=sys.stderr)
        return 2
    config = GatewayConfig(server=args.server, camera_id=args.camera, fps=args.fps,
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
