"""The REST front end: the FastAPI app, its middleware and one routes file per resource."""
