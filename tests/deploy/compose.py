"""Read docker-compose.yml the way `docker compose` does, for the deployment tests.

No Docker engine runs on our machines, so the tests take each service's command and environment
from the compose file (with ${VAR}, ${VAR:-default} and ${VAR:?message} resolved as compose
resolves them) and run the same `smoothfleet` commands as processes.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

COMPOSE_FILE = Path(__file__).resolve().parents[2] / "docker-compose.yml"
_VARIABLE = re.compile(r"\$\{(?P<name>[A-Z0-9_]+)(?:(?P<op>:-|:\?)(?P<arg>[^}]*))?\}")


class ComposeError(ValueError):
    """A required variable is unset (compose refuses to start, with this message)."""


def resolve(value: str, environment: dict[str, str]) -> str:
    """Interpolate compose variables in one string."""

    def substitute(match: re.Match[str]) -> str:
        name, op, arg = match["name"], match["op"], match["arg"]
        given = environment.get(name, "")
        if op == ":?" and not given:
            raise ComposeError(f"required variable {name} is missing a value: {arg}")
        if op == ":-" and not given:
            return arg
        return given

    return _VARIABLE.sub(substitute, value)


def _interpolate(node: Any, environment: dict[str, str]) -> Any:
    if isinstance(node, str):
        return resolve(node, environment)
    if isinstance(node, list):
        return [_interpolate(item, environment) for item in node]
    if isinstance(node, dict):
        return {key: _interpolate(item, environment) for key, item in node.items()}
    return node


def load(environment: dict[str, str]) -> dict[str, Any]:
    """The compose document with anchors merged and variables resolved."""
    document = yaml.safe_load(COMPOSE_FILE.read_text())
    resolved: dict[str, Any] = _interpolate(document, environment)
    return resolved


def service_environment(service: dict[str, Any]) -> dict[str, str]:
    """A service's environment as strings (compose accepts a mapping or KEY=VALUE list)."""
    environment = service.get("environment", {})
    if isinstance(environment, list):
        return dict(item.split("=", 1) for item in environment)
    return {key: "" if value is None else str(value) for key, value in environment.items()}
