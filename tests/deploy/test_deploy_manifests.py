"""The deployment files agree with each other and with the code: ports, user, probes, labels, cameras.

The validators (hadolint, kubernetes-validate, docker-compose config) check each file on its own in
`deploy/ci/check-manifests.sh`; these tests check what no schema can: that the pieces fit.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
import yaml

from fisheye import camera_to_dict, load_camera
from models import DEMO_CAMERA_PATH
from service.core.config import Settings

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
K8S = DEPLOY / "k8s"


def _documents(path: Path) -> list[dict[str, Any]]:
    return [doc for doc in yaml.safe_load_all(path.read_text(encoding="utf-8")) if doc]


def _resources() -> dict[tuple[str, str], dict[str, Any]]:
    """Every Kubernetes resource under deploy/k8s by (kind, name)."""
    found = {}
    for path in sorted(K8S.glob("*.yaml")):
        if path.name == "kustomization.yaml":
            continue
        for doc in _documents(path):
            found[(doc["kind"], doc["metadata"]["name"])] = doc
    return found


def _container() -> dict[str, Any]:
    deployment = _resources()[("Deployment", "fishloc")]
    (container,) = deployment["spec"]["template"]["spec"]["containers"]
    return dict(container)


def _dockerfile_runtime() -> str:
    """The runtime stage of the Dockerfile (its last FROM onwards), comment lines dropped."""
    text = (DEPLOY / "Dockerfile").read_text(encoding="utf-8")
    stage = text[text.rindex("\nFROM ") :]
    return "\n".join(line for line in stage.splitlines() if not line.lstrip().startswith("#"))


def test_kustomization_lists_every_manifest() -> None:
    kustomization = yaml.safe_load((K8S / "kustomization.yaml").read_text(encoding="utf-8"))
    on_disk = {p.name for p in K8S.glob("*.yaml")} - {"kustomization.yaml"}
    assert set(kustomization["resources"]) == on_disk


def test_camera_configmap_is_the_demo_camera() -> None:
    configmap = _resources()[("ConfigMap", "fishloc-cameras")]
    shipped = camera_to_dict(load_camera(DEMO_CAMERA_PATH))
    in_cluster = camera_to_dict(load_camera(yaml.safe_load(configmap["data"]["demo.yaml"])))
    assert in_cluster == shipped


def test_cameras_folder_is_where_the_configmap_is_mounted() -> None:
    container = _container()
    env = {item["name"]: item for item in container["env"]}
    mounts = {mount["name"]: mount["mountPath"] for mount in container["volumeMounts"]}
    assert env["FISHLOC_CAMERAS"]["value"] == mounts["cameras"]
    volumes = _resources()[("Deployment", "fishloc")]["spec"]["template"]["spec"]["volumes"]
    (cameras,) = [volume for volume in volumes if volume["name"] == "cameras"]
    assert cameras["configMap"]["name"] == "fishloc-cameras"


def test_database_url_comes_from_a_secret() -> None:
    env = {item["name"]: item for item in _container()["env"]}
    reference = env["FISHLOC_DATABASE_URL"]["valueFrom"]["secretKeyRef"]
    assert reference == {"name": "fishloc-database", "key": "url"}


def test_ports_match_the_image_and_the_services() -> None:
    expose = re.search(r"^EXPOSE (.+)$", _dockerfile_runtime(), re.M)
    assert expose is not None
    exposed = set(expose.group(1).split())
    ports = {port["name"]: port["containerPort"] for port in _container()["ports"]}
    assert {str(port) for port in ports.values()} == exposed
    env = {item["name"]: item.get("value") for item in _container()["env"]}
    assert env["FISHLOC_HTTP_PORT"] == str(ports["http"])
    assert env["FISHLOC_GRPC_PORT"] == str(ports["grpc"])
    resources = _resources()
    for name in ("fishloc", "fishloc-grpc"):
        for port in resources[("Service", name)]["spec"]["ports"]:
            assert port["targetPort"] in ports
    assert resources[("Service", "fishloc-grpc")]["spec"]["clusterIP"] == "None"


def test_probes_use_readyz_and_grpc_health() -> None:
    container = _container()
    assert container["readinessProbe"]["httpGet"] == {"path": "/readyz", "port": "http"}
    ports = {port["name"]: port["containerPort"] for port in container["ports"]}
    assert container["livenessProbe"]["grpc"]["port"] == ports["grpc"]
    assert "/readyz" in _dockerfile_runtime()


def test_runs_as_the_image_user_on_a_read_only_root() -> None:
    user = re.search(r"^USER (\d+):(\d+)$", _dockerfile_runtime(), re.M)
    assert user is not None
    pod = _resources()[("Deployment", "fishloc")]["spec"]["template"]["spec"]
    assert pod["securityContext"]["runAsNonRoot"] is True
    assert (pod["securityContext"]["runAsUser"], pod["securityContext"]["runAsGroup"]) == (
        int(user.group(1)), int(user.group(2)))
    context = _container()["securityContext"]
    assert context["readOnlyRootFilesystem"] is True
    assert context["allowPrivilegeEscalation"] is False
    # A read-only root still needs somewhere to spool uploads.
    assert "/tmp" in {mount["mountPath"] for mount in _container()["volumeMounts"]}


def test_selectors_find_the_deployment() -> None:
    resources = _resources()
    deployment = resources[("Deployment", "fishloc")]
    labels = deployment["spec"]["template"]["metadata"]["labels"]
    assert deployment["spec"]["selector"]["matchLabels"].items() <= labels.items()
    for kind, name in (("Service", "fishloc"), ("Service", "fishloc-grpc")):
        assert resources[(kind, name)]["spec"]["selector"].items() <= labels.items()
    budget = resources[("PodDisruptionBudget", "fishloc")]
    assert budget["spec"]["selector"]["matchLabels"].items() <= labels.items()
    target = resources[("HorizontalPodAutoscaler", "fishloc")]["spec"]["scaleTargetRef"]
    assert (target["kind"], target["name"]) == ("Deployment", "fishloc")


def test_disruption_budget_leaves_room_to_drain() -> None:
    resources = _resources()
    min_replicas = resources[("HorizontalPodAutoscaler", "fishloc")]["spec"]["minReplicas"]
    assert resources[("PodDisruptionBudget", "fishloc")]["spec"]["minAvailable"] < min_replicas


def test_prometheus_scrapes_the_compose_replicas_and_workers() -> None:
    compose = yaml.safe_load((DEPLOY / "compose.yaml").read_text(encoding="utf-8"))
    prometheus = yaml.safe_load((DEPLOY / "prometheus" / "prometheus.yml").read_text(encoding="utf-8"))
    jobs = prometheus["scrape_configs"]
    targets = {target for job in jobs for target in job["static_configs"][0]["targets"]}
    assert {target.split(":")[0] for target in targets} == {"fishloc-1", "fishloc-2", "sites-1", "sites-2"}
    for target in targets:
        host, port = target.split(":")
        assert port in compose["services"][host]["expose"]
    assert all(job["metrics_path"] == "/metrics" for job in prometheus["scrape_configs"])
    assert "registry" in compose["volumes"]


def _env(container: dict[str, Any]) -> dict[str, Any]:
    return {item["name"]: item.get("value", item.get("valueFrom")) for item in container["env"]}


def test_replicas_and_workers_share_one_bus_and_one_registry() -> None:
    resources = _resources()
    (worker,) = resources[("Deployment", "fishloc-sites")]["spec"]["template"]["spec"]["containers"]
    replica_env, worker_env = _env(_container()), _env(worker)
    assert replica_env["FISHLOC_SITES_BUS"] == worker_env["FISHLOC_SITES_BUS"]
    assert replica_env["FISHLOC_DATABASE_URL"] == worker_env["FISHLOC_DATABASE_URL"]
    redis_service = resources[("Service", "fishloc-redis")]
    port = redis_service["spec"]["ports"][0]["port"]
    assert worker_env["FISHLOC_SITES_BUS"] == f"redis://{redis_service['metadata']['name']}:{port}/0"
    redis_pods = resources[("StatefulSet", "fishloc-redis")]["spec"]["template"]["metadata"]["labels"]
    assert redis_service["spec"]["selector"].items() <= redis_pods.items()
    assert worker["args"][0] == "sites" and worker["image"] == _container()["image"]
    metrics_port = int(worker["args"][worker["args"].index("--metrics-port") + 1])
    assert worker["ports"][0]["containerPort"] == metrics_port
    assert worker["securityContext"]["readOnlyRootFilesystem"] is True
    # No Service selects the workers or Redis by the replicas' labels.
    localizer = resources[("Service", "fishloc")]["spec"]["selector"]
    sites_pods = resources[("Deployment", "fishloc-sites")]["spec"]["template"]["metadata"]["labels"]
    assert not localizer.items() <= sites_pods.items() and not localizer.items() <= redis_pods.items()


def test_compose_puts_two_replicas_behind_one_port_and_two_workers_on_the_bus() -> None:
    compose = yaml.safe_load((DEPLOY / "compose.yaml").read_text(encoding="utf-8"))
    services = compose["services"]
    replicas = [name for name, s in services.items()
                if "command" not in s and s.get("image") == "fishloc:latest"]
    workers = [name for name, s in services.items() if s.get("command", [None])[0] == "sites"]
    assert (len(replicas), len(workers)) == (2, 2)
    for name in replicas + workers:
        assert services[name]["environment"]["FISHLOC_SITES_BUS"] == "redis://redis:6379/0"
        assert "registry:/var/lib/fishloc" in services[name]["volumes"]
    nginx = (DEPLOY / "nginx" / "nginx.conf").read_text(encoding="utf-8")
    for name in replicas:
        assert f"server {name}:8000;" in nginx and f"server {name}:50051;" in nginx
    assert not any(services[name].get("ports") for name in replicas)  # only the proxy publishes
    published = [port for s in services.values() for port in s.get("ports", [])]
    assert any(port.endswith(":8000") for port in published)
    assert any(port.endswith(":50051") for port in published)


@pytest.mark.parametrize("source", ["Dockerfile", "compose.yaml", "k8s/deployment.yaml"])
def test_every_fishloc_variable_is_a_setting(source: str) -> None:
    text = (DEPLOY / source).read_text(encoding="utf-8")
    names = set(re.findall(r"\bFISHLOC_([A-Z0-9_]+)", text)) - {"HTTP_PUBLISH", "GRPC_PUBLISH"}
    known = _setting_variables(Settings)
    assert names, f"{source} sets no FISHLOC_* variable"
    assert names <= known, f"{source} sets unknown variables: {sorted(names - known)}"


def _setting_variables(settings: Any) -> set[str]:
    """The FISHLOC_* suffixes the settings class reads: field names and any validation aliases."""
    known = set()
    prefix = settings.model_config.get("env_prefix", "")
    for name, field in settings.model_fields.items():
        known.add(name.upper())
        alias = field.validation_alias
        choices = getattr(alias, "choices", [alias]) if alias is not None else []
        for choice in choices:
            if isinstance(choice, str) and choice.upper().startswith(prefix.upper()):
                known.add(choice.upper()[len(prefix):])
    return known
