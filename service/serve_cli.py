"""`fishloc serve`: the REST (and gRPC) service over the default model and the `demo` camera."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from pathlib import Path

from pydantic import ValidationError

from contract import ModelError
from contract.model import SPINNING_POLICIES
from fisheye import CalibrationError
from models import DEFAULT_MODEL_PATH
from service.core.config import Settings
from service.core.logs import configure_logging
from service.core.tls import TlsError
from service.sites.bus import BusError

log = logging.getLogger("fishloc.serve")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Serve the model over REST and gRPC. Every flag can also be set as FISHLOC_<NAME> in the "
        "environment (e.g. FISHLOC_API_TOKEN, FISHLOC_MAX_IN_FLIGHT); flags win."
    )
    parser.add_argument("--host", help="address to listen on (default 127.0.0.1; 0.0.0.0 in containers)")
    parser.add_argument("--http-port", type=int, help="REST port (default 8000)")
    parser.add_argument("--grpc-port", type=int, help="gRPC port (default 50051; -1: no gRPC)")
    parser.add_argument("--model", type=Path,
                        help="ONNX model (default: the shipped models/fishloc-default.onnx)")
    parser.add_argument("--cameras", type=Path, metavar="FILE_OR_DIR",
                        help="camera file or folder of them, written to the registry at start")
    parser.add_argument("--database", metavar="URL_OR_PATH",
                        help="camera registry: SQLite file or SQLAlchemy URL "
                             "(default ~/.local/share/fishloc/cameras.db)")
    parser.add_argument("--threads", type=int, help="inference threads (default: the container's CPU quota)")
    parser.add_argument("--onnx-spinning", choices=SPINNING_POLICIES,
                        help="when onnxruntime's threads busy-wait between a run's operators instead of "
                             "sleeping: 'alone' (the default) while a frame has the model to itself, 'on' "
                             "in every run (several frames at once then get about 20%% fewer frames/s), "
                             "'off' never (env FISHLOC_ONNX_SPINNING)")
    parser.add_argument("--mqtt", metavar="URL",
                        help="publish occupancy to an MQTT broker: mqtt://[user:pass@]HOST[:PORT] or "
                             "mqtts://... (with Home Assistant discovery)")
    parser.add_argument("--mqtt-prefix", help="MQTT topic prefix (default fishloc)")
    parser.add_argument("--history-retention-days", type=float,
                        help="days of counts history kept per site (default 400)")
    parser.add_argument("--sites-bus", metavar="redis://HOST:PORT/DB",
                        help="track sites in `fishloc sites` workers over this Redis "
                             "(default: in this process)")
    parser.add_argument("--no-demo-camera", dest="demo_camera", action="store_const", const=False,
                        help="do not add the demo camera to a new database")
    parser.add_argument("--max-view-pixels", type=int, metavar="PIXELS",
                        help="largest model input of a camera's planned view, width x height (a planned "
                             "model only; env FISHLOC_MAX_VIEW_PIXELS; default 900000), unless the "
                             "camera's record sets its own (max_view_pixels)")
    parser.add_argument("--second-look", type=int, metavar="PIXELS",
                        help="the second look: a frame's small, uncertain detections seen again at twice "
                             "their band's scale (a far one more, to 48 rows, 4x at most), in one input of "
                             "its patches of at most this many px (a "
                             "planned model only; env FISHLOC_SECOND_LOOK; default 0: none; 786432: "
                             "12 patches' px at their largest; 1.2-1.8x the time of a frame without it)")
    parser.add_argument("--longest-person-ratio", type=float, metavar="RATIO",
                        help="drop candidates longer along the ray than RATIO standing adults where their "
                             "feet stand, before NMS (a planned model only; env "
                             "FISHLOC_LONGEST_PERSON_RATIO; default: none; for calibrated cameras, 1.8 "
                             "chosen on renders)")
    parser.add_argument("--max-camera-view-pixels", type=int, metavar="PIXELS",
                        help="the largest budget a camera's record may set for its view (env "
                             "FISHLOC_MAX_CAMERA_VIEW_PIXELS; default 4000000)")


def settings_from_args(args: argparse.Namespace) -> Settings:
    """Settings from the environment with the flags that were given on top."""
    names = ("host", "http_port", "grpc_port", "model", "cameras", "database", "threads", "onnx_spinning",
             "demo_camera", "max_view_pixels", "max_camera_view_pixels", "second_look",
             "longest_person_ratio", "mqtt", "mqtt_prefix", "history_retention_days", "sites_bus")
    overrides = {name: getattr(args, name) for name in names if getattr(args, name, None) is not None}
    return Settings(**overrides)


def run(args: argparse.Namespace) -> int:
    try:
        settings = settings_from_args(args)
    except ValidationError as error:
        print(f"fishloc serve: invalid settings:\n{error}", file=sys.stderr)
        return 2
    configure_logging(settings.log_level, settings.log_json)
    from service.server import run_service

    try:
        asyncio.run(run_service(settings))
    except ModelError as error:
        hint = ""
        if settings.model == DEFAULT_MODEL_PATH and not settings.model.exists():
            hint = ("\nThe shipped default model is missing from this checkout; make it with "
                    "`fishloc export` (README) or pass --model PATH.")
        print(f"fishloc serve: cannot load the model: {error}{hint}", file=sys.stderr)
        return 2
    except CalibrationError as error:
        print(f"fishloc serve: bad camera file: {error}", file=sys.stderr)
        return 2
    except (TlsError, BusError) as error:
        print(f"fishloc serve: {error}", file=sys.stderr)
        return 2
    except (RuntimeError, OSError) as error:  # e.g. a port already in use
        print(f"fishloc serve: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        pass
    return 0
