"""mqtts://: the MQTT sink on a mosquitto TLS listener that asks for a client certificate (a CA,
server and client certificates made here), next to a plain listener the test reads from."""

from __future__ import annotations

import asyncio
import datetime
import ipaddress
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID
from output_peers import Subscriber, free_port, mosquitto, wait_for
from prometheus_client import CollectorRegistry

from service.outputs.events import SiteUpdate
from service.outputs.mqtt import MqttConfig, MqttSink
from service.outputs.sink import OutputMetrics


def _issue(folder: Path, name: str, issuer: tuple[x509.Certificate, ec.EllipticCurvePrivateKey] | None,
           ) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    now = datetime.datetime.now(datetime.UTC)
    builder = (x509.CertificateBuilder().subject_name(subject).public_key(key.public_key())
               .serial_number(x509.random_serial_number())
               .not_valid_before(now - datetime.timedelta(minutes=5))
               .not_valid_after(now + datetime.timedelta(days=1)))
    if issuer is None:
        builder = builder.issuer_name(subject).add_extension(x509.BasicConstraints(ca=True, path_length=0),
                                                             critical=True)
    else:
        builder = builder.issuer_name(issuer[0].subject).add_extension(
            x509.SubjectAlternativeName([x509.DNSName("localhost"),
                                         x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
    certificate = builder.sign(issuer[1] if issuer else key, hashes.SHA256())
    (folder / f"{name}.pem").write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
    (folder / f"{name}.key").write_bytes(key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()))
    return certificate, key


def test_mqtts_with_a_client_certificate(tmp_path: Path) -> None:
    ca = _issue(tmp_path, "ca", None)
    _issue(tmp_path, "server", ca)
    _issue(tmp_path, "client", ca)
    tls_port = free_port()
    listener = (f"listener {tls_port} 127.0.0.1\ncafile {tmp_path / 'ca.pem'}\n"
                f"certfile {tmp_path / 'server.pem'}\nkeyfile {tmp_path / 'server.key'}\n"
                "require_certificate true\n")
    update = SiteUpdate("hall", 1.0, {"count": 3, "zones": {"entrance": {"count": 2}},
                                      "lines": {"door": {"in": 4, "out": 1}}}, {})

    async def publish(config: MqttConfig) -> dict[str, object]:
        sink = MqttSink(config, OutputMetrics(CollectorRegistry()), retry_s=0.2, max_retry_s=0.5)
        await sink.start()
        await sink.publish(update)
        for _ in range(400):
            if (sink.connected and not sink.pending) or sink.health().get("error"):
                break
            await asyncio.sleep(0.05)
        health = sink.health()
        await sink.close()
        return health

    url = f"mqtts://127.0.0.1:{tls_port}"
    with mosquitto(tmp_path, extra_config=listener) as broker, Subscriber(broker.port) as heard:
        without_certificate = asyncio.run(publish(MqttConfig.from_url(url, ca_file=tmp_path / "ca.pem")))
        assert without_certificate["connected"] is False and without_certificate["error"]
        health = asyncio.run(publish(MqttConfig.from_url(
            url, ca_file=tmp_path / "ca.pem", cert_file=tmp_path / "client.pem",
            key_file=tmp_path / "client.key")))
        assert health["connected"] is True
        wait_for(lambda: heard.latest.get("fishloc/hall/count") == "3", 10, "the count over TLS")
        assert heard.latest["fishloc/hall/zones/entrance/count"] == "2"
        assert heard.latest["fishloc/hall/lines/door"] == '{"in": 4, "out": 1}'
