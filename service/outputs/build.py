"""`build_outputs`: the sinks a service's settings ask for, on the registry's database."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.engine import Engine

from service.core.config import Settings
from service.core.metrics import ServiceMetrics
from service.outputs.history import HistorySink, HistoryStore
from service.outputs.mqtt import MqttConfig, MqttSink
from service.outputs.sink import Dispatcher, OutputMetrics, Sink
from service.outputs.tables import migrate
from service.outputs.webhooks import DeliveryConfig, WebhookSink, WebhookStore


@dataclass
class Outputs:
    """The dispatcher and the sinks the routes read (history, webhooks)."""

    dispatcher: Dispatcher
    history: HistorySink
    webhooks: WebhookSink
    mqtt: MqttSink | None = None


def mqtt_config(settings: Settings) -> MqttConfig | None:
    if settings.mqtt is None:
        return None
    return MqttConfig.from_url(
        settings.mqtt.get_secret_value(), prefix=settings.mqtt_prefix,
        discovery_prefix=settings.mqtt_discovery_prefix, ca_file=settings.mqtt_ca,
        cert_file=settings.mqtt_cert, key_file=settings.mqtt_key, client_id=settings.mqtt_client_id)


def build_outputs(settings: Settings, engine: Engine, metrics: ServiceMetrics) -> Outputs:
    """History and webhooks always (webhooks are written through the API); MQTT when a broker is set."""
    migrate(engine)
    output_metrics = OutputMetrics(metrics.registry)
    history = HistorySink(HistoryStore(engine, settings.history_retention_days))
    delivery = DeliveryConfig(timeout_s=settings.webhook_timeout_s,
                              max_backoff_s=settings.webhook_max_backoff_s)
    webhooks = WebhookSink(WebhookStore(engine), output_metrics, delivery)
    config = mqtt_config(settings)
    mqtt = None if config is None else MqttSink(config, output_metrics)
    sinks: list[Sink] = [history, webhooks, *([mqtt] if mqtt is not None else [])]
    return Outputs(Dispatcher(sinks, output_metrics), history, webhooks, mqtt)
