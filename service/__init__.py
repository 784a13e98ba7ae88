"""FishLoc's runtime. Never imports torch.

Its rooms: `core/` (settings, errors, metrics, logs, TLS), `http/` (the FastAPI app, middleware and one
routes file per resource), `grpc/` (the Localizer servicer and its conversions), `sites/` (the site
hubs, the registry rows of zones and lines, site views), `gateway/` (the reference camera gateway).
Beside them: the pipeline, the camera registry, the runner, the server and the CLI. The tools that
evaluate the runtime (site sequences played and scored) live in the top-level `evaluation` package.
"""
