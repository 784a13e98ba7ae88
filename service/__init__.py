"""FishLoc's runtime: pipeline, camera registry, REST and gRPC front ends, CLI. Never imports torch."""
