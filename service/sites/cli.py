"""`fishloc sites`: a tracking worker behind a sites bus (the other half of `fishloc serve --sites-bus`)."""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import signal
import sys

from service.core.config import Settings
from service.core.logs import configure_logging

log = logging.getLogger("fishloc.sites")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Track the sites whose frames `fishloc serve --sites-bus` replicas publish to Redis. Run one or "
        "more: they share the site partitions by lease, snapshot each site's tracker to Redis and take "
        "over a dead worker's partitions within seconds, losing nothing."
    )
    parser.add_argument("--bus", metavar="redis://HOST:PORT/DB", default=os.environ.get("FISHLOC_SITES_BUS"),
                        help="the sites bus (default: FISHLOC_SITES_BUS)")
    parser.add_argument("--database", metavar="URL_OR_PATH",
                        help="the camera registry the replicas use, for zones and lines (SQLite file or "
                             "SQLAlchemy URL; default FISHLOC_DATABASE_URL, FISHLOC_DATABASE or "
                             "~/.local/share/fishloc/cameras.db, as `fishloc serve`)")
    parser.add_argument("--host", default=os.environ.get("FISHLOC_HOST", "127.0.0.1"),
                        help="address of the metrics endpoint (default 127.0.0.1; 0.0.0.0 in containers)")
    parser.add_argument("--metrics-port", type=int, default=int(os.environ.get("FISHLOC_METRICS_PORT", "-1")),
                        help="serve Prometheus metrics on this port (default -1: none; 0: any free port)")
    parser.add_argument("--log-level", default=os.environ.get("FISHLOC_LOG_LEVEL", "info"))
    parser.add_argument("--mqtt", metavar="URL", default=None,
                        help="publish occupancy to an MQTT broker, as `fishloc serve --mqtt` (default "
                             "FISHLOC_MQTT; history and webhooks are written to the registry's database)")


async def _run(args: argparse.Namespace) -> int:
    from prometheus_client import start_http_server

    from service.cameras import CameraRegistry
    from service.core.metrics import ServiceMetrics
    from service.outputs.attach import attach_outputs
    from service.outputs.build import build_outputs
    from service.sites import bus
    from service.sites.store import SiteStore
    from service.sites.worker import SitesWorker

    try:
        redis = await bus.connect(args.bus)
    except bus.BusError as error:
        print(f"fishloc sites: {error}", file=sys.stderr)
        return 2
    registry = CameraRegistry(args.database or Settings().database)
    metrics = ServiceMetrics()
    if args.metrics_port >= 0:
        server, _ = start_http_server(args.metrics_port, addr=args.host, registry=metrics.registry)
        log.info("metrics on http://%s:%d/metrics", args.host, server.server_port)
    store = SiteStore(registry)
    worker = SitesWorker(redis, store, metrics)
    # The outputs run where the trackers do: each crossing is pushed once, by the worker that made it.
    settings = Settings() if args.mqtt is None else Settings(mqtt=args.mqtt)
    outputs = build_outputs(settings, registry.engine, metrics)
    attach_outputs(outputs.dispatcher, worker, store)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await outputs.dispatcher.start()
    try:
        await worker.run(stop)
    finally:
        await outputs.dispatcher.close()
        await redis.aclose()
        registry.close()
    return 0


def run(args: argparse.Namespace) -> int:
    configure_logging(args.log_level, True)
    if not args.bus:
        print("fishloc sites: --bus redis://HOST:PORT/DB is required (or FISHLOC_SITES_BUS)", file=sys.stderr)
        return 2
    try:
        return asyncio.run(_run(args))
    except KeyboardInterrupt:
        return 0
