"""The `fishloc` command: a table of subcommands, each implemented in the package that owns it.

A subcommand's module is imported only when that subcommand runs, so `fishloc serve` never loads
torch and `fishloc --help` stays fast. Each module provides `add_arguments(parser)` and
`run(args) -> int`.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

# name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "bench": ("benchmarks.cli", "latency and throughput on realistic frames (in process, HTTP, gRPC)"),
    "calibrate": ("fisheye.calibrate_cli", "fit a camera's lens from ruler marks, or import OpenCV K/D"),
    "serve": ("service.serve_cli", "serve the model over REST and gRPC (default model, demo camera)"),
    "sites": ("service.sites.cli", "track sites behind a sites bus: the workers of `serve --sites-bus`"),
    "gateway": ("service.gateway.cli", "stream a camera's frames to a server over gRPC, print the answers"),
    "synth": ("detector.data.synth_cli", "render synthetic fisheye frames with exact ground truth"),
    "export": ("exporter.export", "turn a training checkpoint into a verified ONNX model (optional INT8)"),
    "train": ("detector.train", "train the person detector on annotated fisheye frames"),
    "eval": ("detector.evaluate", "evaluate a checkpoint or ONNX model: mAP, AP by distance, PE in metres"),
}

# A flag that sends a subcommand to another module: `fishloc eval --tracks` needs no torch.
_VARIANTS: dict[tuple[str, str], str] = {("eval", "--tracks"): "evaluation.track_eval_cli"}

# Modules that only the training extra installs.
_TRAIN_ONLY = ("torch", "onnx", "onnxscript", "matplotlib", "scipy")


def _overview() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fishloc",
        description="Find people in overhead fisheye frames and place them on the floor, in metres.",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_, summary) in COMMANDS.items():
        commands.add_parser(name, help=summary, add_help=False)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    arguments = list(sys.argv[1:] if argv is None else argv)
    overview = _overview()
    if not arguments or arguments[0] not in COMMANDS:
        if arguments and not arguments[0].startswith("-"):
            overview.error(f"unknown command {arguments[0]!r}; choose from {', '.join(COMMANDS)}")
        overview.parse_args(arguments)  # handles --help
        overview.print_help()
        return 2
    name, rest = arguments[0], arguments[1:]
    module_name, summary = COMMANDS[name]
    module_name = next((m for (n, flag), m in _VARIANTS.items() if n == name and flag in rest), module_name)
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        if error.name and error.name.split(".")[0] in _TRAIN_ONLY:
            print(
                f"fishloc {name} needs the training tools ({error.name} is missing): "
                "pip install 'fishloc[train]'",
                file=sys.stderr,
            )
            return 2
        raise
    parser = argparse.ArgumentParser(prog=f"fishloc {name}", description=summary)
    module.add_arguments(parser)
    args = parser.parse_args(rest)
    return int(module.run(args))


if __name__ == "__main__":
    sys.exit(main())
