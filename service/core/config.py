"""Service settings: `fishloc serve` flags over `FISHLOC_*` environment variables over defaults.

Read once at start (pydantic-settings) and handed to the factories; nothing below the entry points
reads the environment.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

from pydantic import AliasChoices, Field, SecretStr, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from contract.model import SpinningPolicy
from contract.views import DEFAULT_VIEW
from fisheye.camera import (
    MAX_LONGEST_PERSON_RATIO,
    MAX_SECOND_LOOK_PIXELS,
    MAX_VIEW_PIXELS,
    MIN_LONGEST_PERSON_RATIO,
    MIN_VIEW_PIXELS,
)
from fisheye.view_plan import SECOND_LOOK_FULL_PIXELS
from models import DEFAULT_MODEL_PATH, DEMO_CAMERA_PATH
from service.core.cpu import cpu_budget


def default_database_path() -> Path:
    """Where the camera registry lives unless told otherwise: $XDG_DATA_HOME/fishloc/cameras.db."""
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "fishloc" / "cameras.db"


class Settings(BaseSettings):
    """Everything `fishloc serve` can be told (flag, or environment variable FISHLOC_<NAME>)."""

    # hide_input_in_errors: a settings error must not print the tokens it was given.
    model_config = SettingsConfigDict(env_prefix="FISHLOC_", extra="ignore", frozen=True,
                                      populate_by_name=True, hide_input_in_errors=True)

    host: str = Field("127.0.0.1", description="address to listen on (0.0.0.0 in containers)")
    http_port: int = Field(8000, ge=0, le=65535, description="REST port (0: any free port)")
    grpc_port: int = Field(50051, ge=-1, le=65535, description="gRPC port (0: any free port, -1: no gRPC)")
    model: Path = Field(DEFAULT_MODEL_PATH, description="ONNX model following the FishLoc contract")
    cameras: Path | None = Field(None, description="camera file or folder written to the registry at start")
    # FISHLOC_DATABASE_URL is the name deployments use (a URL from a Secret); FISHLOC_DATABASE also works.
    database: str = Field(default_factory=lambda: str(default_database_path()),
                          validation_alias=AliasChoices("FISHLOC_DATABASE_URL", "FISHLOC_DATABASE"),
                          description="camera registry: SQLAlchemy URL or SQLite file path")
    demo_camera: bool = Field(True, description="add the `demo` camera the first time a database is used")
    demo_camera_path: Path = DEMO_CAMERA_PATH
    api_token: SecretStr | None = Field(None, description="bearer token required for registry writes")
    read_token: SecretStr | None = Field(
        None, description="bearer token required for site reads, site events and latest frames (the API "
                          "token also passes); none: open"
    )
    detect_token: SecretStr | None = Field(
        None, description="bearer token required for detection (the API token also passes); none: open"
    )
    tls_cert: Path | None = Field(None, description="PEM certificate (chain): serve REST and gRPC over TLS")
    tls_key: Path | None = Field(None, description="PEM private key of tls_cert")
    cors_origins: Annotated[list[str], NoDecode] = Field(
        default_factory=list, description="origins allowed to call from a browser (comma-separated; "
                                          "none: CORS off)",
    )
    head_timeout_s: float = Field(10.0, gt=0, description="time for a request's line and headers")
    body_timeout_s: float = Field(30.0, gt=0, description="time for a request's body to arrive")
    keep_alive_timeout_s: int = Field(5, ge=1, description="idle time before a keep-alive connection closes")
    max_body_bytes: int = Field(32 * 1024 * 1024, ge=1024, description="largest encoded frame accepted")
    max_pixels: int = Field(40_000_000, ge=1, description="largest decoded frame (width × height)")
    max_view_pixels: int = Field(900_000, ge=MIN_VIEW_PIXELS, le=MAX_VIEW_PIXELS,
                                 description="largest model input a camera's planned view may take "
                                             "(width × height; a planned model only), unless the "
                                             "camera has its own budget (`max_view_pixels` of its record)")
    max_camera_view_pixels: int = Field(4_000_000, ge=MIN_VIEW_PIXELS, le=MAX_VIEW_PIXELS,
                                        description="the largest budget a camera's record may ask for "
                                                    "(its `max_view_pixels`)")
    second_look: int = Field(DEFAULT_VIEW.second_look_pixels, ge=0, le=MAX_SECOND_LOOK_PIXELS,
                             description="input px the second look at a frame's small, uncertain "
                                         "detections may take, its patches packed into one input "
                                         "(a planned model only; 0: none; "
                                         f"{SECOND_LOOK_FULL_PIXELS}: 12 patches' px at their largest)")
    longest_person_ratio: float | None = Field(
        None, ge=MIN_LONGEST_PERSON_RATIO, le=MAX_LONGEST_PERSON_RATIO,
        description="candidates longer along the ray than this many standing adults where their feet "
                    "stand are dropped before NMS (a planned model only; for calibrated cameras: at a "
                    "guessed altitude it drops real people; none by default)")
    threads: int = Field(default_factory=cpu_budget, ge=1,
                         description="inference threads (default: the CPU quota of the container)")
    onnx_spinning: SpinningPolicy = Field(
        "alone", description="when onnxruntime's idle threads busy-wait between a run's operators: "
        "'alone' while a frame has the model to itself, 'on' always, 'off' never")
    max_in_flight: int | None = Field(None, ge=1,
                                      description="frames admitted at once before 503 (default 4 × threads)")
    retry_after_s: int = Field(1, ge=1, description="Retry-After of an overload answer")
    nms_iou: float | None = Field(None, gt=0, le=1,
                                  description="rotated NMS IoU threshold (default: the model's own)")
    grpc_max_message_bytes: int = Field(32 * 1024 * 1024, ge=1024)
    mqtt: SecretStr | None = Field(
        None, description="MQTT broker to publish occupancy to: mqtt://[user:pass@]HOST[:PORT] or mqtts://...")
    mqtt_prefix: str = Field("fishloc", pattern=r"^[A-Za-z0-9_./-]{1,64}$", description="MQTT topic prefix")
    mqtt_discovery_prefix: str = Field("homeassistant", pattern=r"^[A-Za-z0-9_./-]{1,64}$",
                                       description="Home Assistant discovery prefix")
    mqtt_ca: Path | None = Field(None, description="CA file of an mqtts:// broker (default: the system's)")
    mqtt_cert: Path | None = Field(None, description="client certificate (PEM) for an mqtts:// broker")
    mqtt_key: Path | None = Field(None, description="private key (PEM) of mqtt_cert")
    mqtt_client_id: str = Field("fishloc", min_length=1, max_length=64, description="MQTT client id")
    history_retention_days: float = Field(400.0, gt=0, description="days of counts history kept per site")
    webhook_timeout_s: float = Field(5.0, gt=0, description="a webhook receiver slower than this has failed")
    webhook_max_backoff_s: float = Field(60.0, gt=0, description="longest wait between a webhook's retries")
    sites_bus: str | None = Field(
        None, description="redis://HOST:PORT/DB: publish site observations there for `fishloc sites` "
                          "workers and serve site reads from what they publish (default: track sites here)")
    sites_bus_wait_s: float = Field(0.5, gt=0, le=10,
                                    description="how long a detect call waits for its frame's track ids")
    log_level: str = Field("info", description="debug, info, warning, error")
    log_json: bool = Field(True, description="JSON log lines (false: plain text)")

    @field_validator("cors_origins", mode="before")
    @classmethod
    def _split_origins(cls, value: object) -> object:
        if isinstance(value, str):
            return [origin.strip() for origin in value.split(",") if origin.strip()]
        return value

    @model_validator(mode="after")
    def _tls_needs_both(self) -> Settings:
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ValueError("tls_cert and tls_key go together: set both (FISHLOC_TLS_CERT, FISHLOC_TLS_KEY)")
        return self

    @field_validator("mqtt")
    @classmethod
    def _mqtt_url(cls, value: SecretStr | None) -> SecretStr | None:
        if value is None or not value.get_secret_value():
            return None
        from service.outputs.mqtt import MqttConfig

        MqttConfig.from_url(value.get_secret_value())  # MqttUrlError (a ValueError) names what is wrong
        return value

    @field_validator("api_token", "detect_token", "read_token")
    @classmethod
    def _empty_token_is_none(cls, value: SecretStr | None) -> SecretStr | None:
        return None if value is None or not value.get_secret_value() else value

    @property
    def in_flight_limit(self) -> int:
        return self.max_in_flight if self.max_in_flight is not None else 4 * self.threads
