"""docker-compose.yml, .env.example and the Dockerfile describe the scaled-out topology.

The compose file is validated by the compose CLI itself (`docker compose config`, or the standalone
`docker-compose config`; no engine is needed) with `.env.example` as `.env`; the normalised result is
then checked: services, healthchecks, the shared volume, the env file, scalable workers.
"""
from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
APP_SERVICES = ("api", "worker", "viewer")


def _compose_cli() -> list[str] | None:
    if shutil.which("docker"):
        probe = subprocess.run(["docker", "compose", "version"], capture_output=True, text=True)
        if probe.returncode == 0:
            return ["docker", "compose"]
    if shutil.which("docker-compose"):
        return ["docker-compose"]
    return None


@pytest.fixture(scope="module")
def config(tmp_path_factory: pytest.TempPathFactory) -> dict:
    cli = _compose_cli()
    if cli is None:
        pytest.skip("no compose CLI (`docker compose` plugin or `docker-compose`) to validate with")
    folder = tmp_path_factory.mktemp("compose")
    shutil.copy(ROOT / "docker-compose.yml", folder / "docker-compose.yml")
    shutil.copy(ROOT / ".env.example", folder / ".env")
    if cli == ["docker", "compose"]:
        out = subprocess.run([*cli, "config", "--format", "json"], cwd=folder, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout)
    out = subprocess.run([*cli, "config"], cwd=folder, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    # docker-compose v1 prints YAML only; it is a Python program, so its interpreter has PyYAML.
    script = shutil.which("docker-compose")
    assert script is not None  # _compose_cli chose it
    interpreter = Path(script).read_text().splitlines()[0].removeprefix("#!").strip()
    conv = subprocess.run([interpreter, "-c", "import json, sys, yaml; print(json.dumps(yaml.safe_load(sys.stdin)))"],
                          input=out.stdout, capture_output=True, text=True)
    assert conv.returncode == 0, conv.stderr
    return json.loads(conv.stdout)


def test_services_and_healthchecks(config: dict) -> None:
    services = config["services"]
    assert set(services) == {"api", "worker", "viewer", "postgres", "redis"}
    for name, svc in services.items():
        test = svc["healthcheck"]["test"]
        assert test[0] in ("CMD", "CMD-SHELL"), (name, test)
    assert "/api/v1/health" in " ".join(services["api"]["healthcheck"]["test"])
    assert "pg_isready" in " ".join(services["postgres"]["healthcheck"]["test"])
    assert services["redis"]["healthcheck"]["test"][1:] == ["redis-cli", "ping"]
    assert services["worker"]["healthcheck"]["test"][1:] == ["python", "-m", "worker.health"]


def test_app_services_share_the_data_volume_and_the_env_file(config: dict) -> None:
    assert "data" in config["volumes"]
    env_example = (ROOT / ".env.example").read_text()
    for name in APP_SERVICES:
        svc = config["services"][name]
        assert svc["environment"]["VTD_DATA_DIR"] == "/data"
        assert any(v["source"] == "data" and v["target"] == "/data" if isinstance(v, dict)
                   else v.startswith("data:/data") for v in svc["volumes"]), svc["volumes"]
        # env_file was read: its settings reached the service
        assert svc["environment"]["VTD_DATABASE_URL"].startswith("postgresql://")
        assert svc["environment"]["VTD_QUEUE_URL"].startswith("redis://redis:")
        assert {"postgres", "redis"} <= set(svc["depends_on"]) or name == "viewer"
    assert "VTD_REQUEUE_ORPHANS=" in env_example and "POSTGRES_PASSWORD=" in env_example
    assert int(config["services"]["worker"]["deploy"]["replicas"]) >= 2
    assert "ports" not in config["services"]["worker"]  # scalable: no fixed host port


def test_source_compose_file_uses_the_env_file() -> None:
    text = (ROOT / "docker-compose.yml").read_text()
    assert re.search(r"^\s+env_file: \.env$", text, re.M)
    assert (ROOT / ".env.example").is_file()
    assert ".env" in (ROOT / ".dockerignore").read_text().split()


def test_dockerfile_installs_the_cpu_torch_wheel_before_the_project() -> None:
    lines = [ln.strip() for ln in (ROOT / "Dockerfile").read_text().splitlines()]
    torch = next(i for i, ln in enumerate(lines) if "torch==2.13.0" in ln and "pip install" in ln)
    project = next(i for i, ln in enumerate(lines) if re.match(r"RUN pip install \.(\s|$)", ln))
    assert torch < project
    assert "--index-url https://download.pytorch.org/whl/cpu" in lines[torch]
    assert not re.search(r"whl/cu\d|cuda", lines[torch], re.I)
