"""deploy/raycluster.yaml against the image it runs (no live cluster): the commands are the image's entry
points, every RCP_* variable is a setting with a value it takes, the Ray address reaches the head's GCS port,
the probe and port are the server's, and the image gets Ray through its build argument."""

from __future__ import annotations

import inspect
import re
import tomllib
from pathlib import Path

import pytest
import yaml

from rcp_server.cli import main
from rcp_server.service.app import create_app
from rcp_server.service.settings import Settings

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = ROOT / "deploy" / "raycluster.yaml"


@pytest.fixture(scope="module")
def documents() -> list[dict]:
    return list(yaml.safe_load_all(MANIFEST.read_text()))


def cluster(documents) -> dict:
    (found,) = [d for d in documents if d["kind"] == "RayCluster"]
    assert found["apiVersion"] == "ray.io/v1"
    return found


def pods(documents) -> list[dict]:
    spec = cluster(documents)["spec"]
    return [spec["headGroupSpec"]["template"]["spec"]] + [g["template"]["spec"] for g in spec["workerGroupSpecs"]]


def test_every_container_runs_the_image_built_with_ray(documents):
    images = {c["image"] for pod in pods(documents) for c in pod["containers"]}
    assert images == {"rcp:ray"}
    dockerfile = (ROOT / "Dockerfile").read_text()
    assert "docker build --build-arg EXTRAS=cluster-node -t rcp:ray ." in MANIFEST.read_text()
    assert 'pip install ".${EXTRAS:+[$EXTRAS]}"' in dockerfile  # the build argument reaches pip
    assert dockerfile.count('ARG EXTRAS=""') == 2  # both stages: the default image stays lean
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert "rcp-server[cluster]" in extras["cluster-node"]
    (ray,) = [r for r in extras["cluster"] if r.startswith("ray")]
    lowest = tuple(int(n) for n in re.search(r">=([\d.]+)", ray).group(1).split("."))
    version = tuple(int(n) for n in cluster(documents)["spec"]["rayVersion"].split("."))
    assert version >= lowest


def test_the_service_shares_the_head_containers_ray_session_folder(documents):
    """A driver reaches its node's raylet through a socket under /tmp/ray: the head container's."""
    head = pods(documents)[0]
    mounts = {c["name"]: {m["mountPath"]: m["name"] for m in c.get("volumeMounts", [])} for c in head["containers"]}
    shared = {mounts[name].get("/tmp/ray") for name in mounts}
    assert len(shared) == 1 and None not in shared
    (volume,) = [v for v in head["volumes"] if v["name"] in shared]
    assert "emptyDir" in volume


def test_the_service_container_runs_rcp_serve_with_settings_it_takes(documents, capsys):
    head = pods(documents)[0]
    (service,) = [c for c in head["containers"] if c.get("command")]
    command = service["command"]
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert command[0] in scripts and scripts[command[0]] == "rcp_server.cli:main"
    with pytest.raises(SystemExit) as done:
        main([*command[1:], "--help"])
    assert done.value.code == 0 and "serve" in capsys.readouterr().out
    env = {e["name"]: e["value"] for e in service["env"]}
    assert all(name.startswith("RCP_") for name in env)
    given = {name.removeprefix("RCP_").lower(): value for name, value in env.items()}
    assert set(given) <= set(Settings.model_fields), set(given) - set(Settings.model_fields)
    settings = Settings(**given)  # every value is one the setting takes
    assert settings.ray_address == "127.0.0.1:6379"
    assert service["ports"][0]["containerPort"] == settings.port
    assert service["readinessProbe"]["httpGet"] == {"path": "/api/health", "port": settings.port}
    paths = set(create_app(settings).openapi()["paths"])
    assert "/api/health" in paths and "/api/videos" in paths
    mounts = {m["mountPath"] for m in service["volumeMounts"]}
    assert str(settings.data) in mounts


def test_the_service_keeps_its_data_on_a_claim_its_user_may_write(documents):
    """RCP_DATA on a PersistentVolumeClaim (uploads and videos outlive the pod), the pod's fsGroup the image's
    group, and the image's own RCP_DATA a declared volume."""
    head = pods(documents)[0]
    (service,) = [c for c in head["containers"] if c.get("command")]
    data = {e["name"]: e["value"] for e in service["env"]}["RCP_DATA"]
    (mount,) = [m for m in service["volumeMounts"] if m["mountPath"] == data]
    (volume,) = [v for v in head["volumes"] if v["name"] == mount["name"]]
    (claim,) = [d for d in documents if d["kind"] == "PersistentVolumeClaim"]
    assert volume["persistentVolumeClaim"]["claimName"] == claim["metadata"]["name"]
    assert claim["spec"]["accessModes"] == ["ReadWriteOnce"]  # one server per data folder: it holds a lock
    dockerfile = (ROOT / "Dockerfile").read_text()
    gid = re.search(r"groupadd --gid (\d+) rcp", dockerfile).group(1)
    assert head["securityContext"]["fsGroup"] == int(gid)
    assert re.search(rf"^\s*RCP_DATA={re.escape(data)} ", dockerfile, re.M)  # the image's default is the same folder
    assert f'VOLUME ["{data}"]' in dockerfile
    assert re.search(rf"mkdir -p [^\n]*{re.escape(data)} && chown -R rcp:rcp [^\n]*{re.escape(data)}", dockerfile)


def test_the_ray_address_is_the_heads_gcs_and_the_head_paints_no_frames(documents):
    spec = cluster(documents)["spec"]
    head = spec["headGroupSpec"]
    gcs = int(head["rayStartParams"].get("port", 6379))
    ports = {p["containerPort"] for c in head["template"]["spec"]["containers"] for p in c.get("ports", [])}
    assert gcs in ports
    (service,) = [c for c in head["template"]["spec"]["containers"] if c.get("command")]
    env = {e["name"]: e["value"] for e in service["env"]}
    assert env["RCP_RAY_ADDRESS"] == f"127.0.0.1:{gcs}"  # the same pod: the head's network namespace
    assert head["rayStartParams"]["num-cpus"] == "0"
    (http,) = [d for d in documents if d["kind"] == "Service"]
    assert http["spec"]["selector"] == {"ray.io/cluster": "rcp", "ray.io/node-type": "head"}
    assert http["spec"]["ports"][0]["targetPort"] == int(env["RCP_PORT"])


def test_the_workers_scale_with_the_admitted_walkers(documents):
    """The autoscaler is on, the painters' group may grow from one two-core node to the 64 the model counts, and
    the service paints walk-throughs there, admitting walkers for a target the settings declare."""
    spec = cluster(documents)["spec"]
    assert spec["enableInTreeAutoscaling"] is True
    assert spec["autoscalerOptions"]["idleTimeoutSeconds"] > 0
    (painters,) = spec["workerGroupSpecs"]
    assert painters["minReplicas"] == 1 <= painters["replicas"] <= painters["maxReplicas"] == 64
    (worker,) = painters["template"]["spec"]["containers"]
    assert worker["resources"]["requests"]["cpu"] == worker["resources"]["limits"]["cpu"] == "2"
    assert "num-cpus" not in painters["rayStartParams"]  # Ray counts the pod's two cores, as the walkers' shares do
    (service,) = [c for c in pods(documents)[0]["containers"] if c.get("command")]
    env = {e["name"].removeprefix("RCP_").lower(): e["value"] for e in service["env"]}
    settings = Settings(**env)
    assert settings.ray_walks and (settings.walk_width, settings.walk_height) == (640, 360)
    assert settings.max_sessions >= 64


def test_a_walkers_crew_is_placed_by_a_spreading_placement_group_the_workers_hold(documents):
    """The manifest says how crews are placed, as rcp_server/cluster/spread.py places them; each worker pod's memory
    holds a bundle for every walker its two cores take part in, and the manifest's Ray holds bundles to nodes."""
    from rcp_server.cluster import spread

    text = " ".join(MANIFEST.read_text().replace("#", " ").split())  # the comments as one text
    assert "placement group" in text and "STRICT_SPREAD" in text and spread.NODE_LABEL in text
    assert f"{spread.BUNDLE_MEMORY >> 20} MiB" in text
    (painters,) = cluster(documents)["spec"]["workerGroupSpecs"]
    (worker,) = painters["template"]["spec"]["containers"]
    memory = int(worker["resources"]["requests"]["memory"].removesuffix("Gi")) << 30
    assert memory >= 16 * spread.BUNDLE_MEMORY
    ray = pytest.importorskip("ray")
    from ray.util import placement_group

    assert "bundle_label_selector" in inspect.signature(placement_group).parameters
    installed = tuple(int(n) for n in ray.__version__.split(".")[:2])
    assert tuple(int(n) for n in cluster(documents)["spec"]["rayVersion"].split(".")[:2]) >= installed
