"""``routing-svc serve``: the service under uvicorn."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from routing_svc.errors import InvalidInput
from routing_svc.network.catalogue import named_network


def _net_option(text: str) -> tuple[str, str]:
    try:
        return named_network(text)
    except InvalidInput as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "serve",
        help="run the REST service (SQLite by default) with the dashboard",
        description="Run the fleet service. With no --net, the DRT district network that "
        "eclipse-sumo ships is loaded as 'drt' and a demo fleet is created.",
    )
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--db", type=Path, default=None, help="SQLite file (default var/routing_svc.db)")
    p.add_argument(
        "--database-url", default=None, help="SQLAlchemy URL, e.g. postgresql+psycopg://..."
    )
    p.add_argument(
        "--net",
        action="append",
        default=[],
        metavar="NAME=PATH",
        type=_net_option,
        help="a network to load (repeatable); NAME=PATH, PATH may be a known name (drt, grid, ...)",
    )
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--api-key", default=os.environ.get("ROUTING_SVC_API_KEY"))
    p.add_argument("--cors-origin", action="append", default=[])
    p.add_argument("--data-dir", type=Path, default=Path("var/networks"))
    p.add_argument("--no-demo", action="store_true", help="do not create the demo fleet")
    p.add_argument("--demo-rate", type=float, default=1.0, help="demo targets per second (0: off)")
    p.add_argument("--log-level", default="info")
    bounds = p.add_argument_group(
        "bounds on waits", "defaults from the settings (environment ROUTING_SVC_<NAME>)"
    )
    from routing_svc.service.settings import Settings

    for name in BOUNDS:
        field = Settings.model_fields[name]
        bounds.add_argument(
            "--" + name.replace("_", "-"),
            type=type(field.default),
            default=None,
            metavar="N",
            help=f"default {field.default}",
        )
    p.set_defaults(run=run)


BOUNDS = (
    "request_timeout_s",
    "health_timeout_s",
    "health_min_free_bytes",
    "retry_after_s",
    "db_busy_timeout_ms",
    "db_connect_timeout_s",
    "db_pool_timeout_s",
    "db_statement_timeout_ms",
    "db_lock_timeout_ms",
    "db_idle_in_transaction_timeout_ms",
    "db_lent_timeout_s",
    "db_keepalives_idle_s",
    "db_keepalives_interval_s",
    "db_keepalives_count",
    "db_tcp_user_timeout_ms",
)
"""Settings that ``serve`` takes as options (``--request-timeout-s`` ...); see
:class:`~routing_svc.service.settings.Settings`."""


def database_url_of(db: Path | None, database_url: str | None) -> str:
    """The store's URL from ``--db`` or ``--database-url``, else ``$DATABASE_URL``, else
    SQLite in ``var/routing_svc.db`` (its folder made)."""
    if database_url and db:
        raise InvalidInput("give --db or --database-url, not both")
    url = database_url or os.environ.get("DATABASE_URL")
    if url is None:
        path = db or Path("var/routing_svc.db")
        path.parent.mkdir(parents=True, exist_ok=True)
        url = f"sqlite:///{path.resolve()}"
    return url


def settings_env(args: argparse.Namespace) -> dict[str, str]:
    """The settings as environment variables, so that every uvicorn worker reads them."""
    import json

    from routing_svc.network.catalogue import resolve_network

    url = database_url_of(args.db, args.database_url)
    nets = dict(args.net) or {"drt": "drt"}
    resolved = {name: str(resolve_network(path)) for name, path in nets.items()}
    if args.demo_rate < 0:
        raise InvalidInput("--demo-rate must be >= 0")
    env = {
        "DATABASE_URL": url,
        "ROUTING_SVC_NETWORKS": json.dumps(resolved),
        "ROUTING_SVC_DATA_DIR": str(args.data_dir.resolve()),
        "ROUTING_SVC_DEMO_FLEET": "false" if args.no_demo else "true",
        "ROUTING_SVC_DEMO_RATE": str(0.0 if args.no_demo else args.demo_rate),
        "ROUTING_SVC_CORS_ORIGINS": json.dumps(args.cors_origin),
    }
    if args.api_key:
        env["ROUTING_SVC_API_KEY"] = args.api_key
    for name in BOUNDS:
        value = getattr(args, name, None)
        if value is not None:
            env[f"ROUTING_SVC_{name.upper()}"] = str(value)
    return env


def check_database(url: str) -> None:
    """Open the event log once before uvicorn starts (durability check, migrations).

    A database that would lose acknowledged events (PostgreSQL with ``fsync``,
    ``synchronous_commit`` or ``full_page_writes`` off), an unreachable server
    or a bad URL then ends ``serve`` with the one-line message of
    :class:`~routing_svc.errors.StorageError` and exit code 2, instead of a
    traceback from the application's lifespan.
    """
    from routing_svc.store import EventLog

    EventLog(url).open().close()


def run(args: argparse.Namespace) -> int:
    import uvicorn

    if args.workers < 1:
        raise InvalidInput("--workers must be >= 1")
    env = settings_env(args)
    check_database(env["DATABASE_URL"])
    os.environ.update(env)
    base = f"http://{args.host}:{args.port}"
    print(f"routing_svc: API docs at {base}/docs, dashboard at {base}/dashboard", flush=True)
    uvicorn.run(
        "routing_svc.service.asgi:app",
        host=args.host,
        port=args.port,
        workers=args.workers,
        log_level=args.log_level,
        log_config=log_config(),
        factory=False,
    )
    return 0


def log_config() -> dict[str, Any]:
    """uvicorn's logging configuration, with the service's loggers (``routing_svc.*``, e.g.
    the causes of 5xx answers under their error ids) on its default handler."""
    import copy

    from uvicorn.config import LOGGING_CONFIG

    config: dict[str, Any] = copy.deepcopy(LOGGING_CONFIG)
    config["loggers"]["routing_svc"] = {
        "handlers": ["default"],
        "level": "INFO",
        "propagate": False,
    }
    return config
