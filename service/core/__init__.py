"""Settings, errors, metrics, logs and TLS: what every part of the runtime shares."""
