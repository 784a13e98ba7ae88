"""TLS for both front ends from a PEM certificate (chain) and its private key.

The files are checked once at start (readable, PEM, key matching the certificate) so that a wrong
path or a mismatched key stops `fishloc serve` with a clear message instead of failing the first
handshake. REST hands the paths to uvicorn; gRPC takes the bytes (`grpc.ssl_server_credentials`).
"""

from __future__ import annotations

import ssl
from dataclasses import dataclass
from pathlib import Path

from service.core.config import Settings


class TlsError(RuntimeError):
    """A certificate or key that cannot be served."""


@dataclass(frozen=True)
class TlsFiles:
    """A checked certificate chain and key: their paths and PEM bytes."""

    cert_path: Path
    key_path: Path
    cert_pem: bytes
    key_pem: bytes


def _read(path: Path, what: str) -> bytes:
    try:
        data = path.read_bytes()
    except OSError as error:
        raise TlsError(f"cannot read the TLS {what} {path}: {error.strerror}") from None
    if b"-----BEGIN" not in data:
        raise TlsError(f"the TLS {what} {path} is not PEM")
    return data


def load_tls(cert_path: Path, key_path: Path) -> TlsFiles:
    """Read and check a certificate chain and its key; TlsError says what is wrong."""
    cert_pem = _read(cert_path, "certificate")
    key_pem = _read(key_path, "key")
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    try:
        context.load_cert_chain(cert_path, key_path)
    except ssl.SSLError as error:
        raise TlsError(f"the TLS key {key_path} does not fit the certificate {cert_path}: "
                       f"{error.reason or error}") from None
    return TlsFiles(cert_path=cert_path, key_path=key_path, cert_pem=cert_pem, key_pem=key_pem)


def tls_from_settings(settings: Settings) -> TlsFiles | None:
    """The checked TLS files the settings name, or None when TLS is off."""
    if settings.tls_cert is None or settings.tls_key is None:
        return None
    return load_tls(settings.tls_cert, settings.tls_key)
