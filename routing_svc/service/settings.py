"""Service settings (pydantic-settings): environment ``ROUTING_SVC_*`` or arguments."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

from routing_svc.store.engine import StoreTimeouts


class Settings(BaseSettings):
    """Everything the service needs to start; nothing is read at import time.

    Attributes
    ----------
    database_url : str
        ``sqlite:///PATH`` (the embedded default) or ``postgresql+psycopg://...``.
        ``DATABASE_URL`` is honoured too.
    networks : dict[str, str]
        Networks to load at start-up, ``name -> path`` (``--net NAME=PATH``).
    data_dir : Path
        Where uploaded networks are kept.
    api_key : str or None
        When set, every write route needs the header ``X-API-Key``.
    cors_origins : list[str]
        Origins allowed to call the API from a browser (none by default).
    max_body_bytes : int
        Largest JSON body accepted.
    max_network_bytes : int
        Largest network upload, compressed or not, and its decompressed size.
    demo_fleet : bool
        Create the demo fleet ``demo`` on the first network when it does not exist.
    demo_rate : float
        Targets per second that the demo feeder posts to the demo fleet (0: off).
    recent_window : int
        How many recent targets the "recent" mean cost covers.
    consolidation_workers : int
        Processes that solve the due consolidations of ``consolidating`` fleets off the
        write path (:mod:`routing_svc.service.background_solver`); 0 solves each inside
        the target that made it due.
    target_fast_path : bool
        Serve ``POST /v1/fleets/{id}/targets`` from the ASGI layer for valid
        bodies (:mod:`routing_svc.service.fastpath`); off, FastAPI's route serves
        every request. The answers are the same bytes either way.
    request_timeout_s : float
        Deadline of a request (all but network uploads and the event stream): past
        it the answer is a 503 problem with ``Retry-After``.
    health_timeout_s : float
        Deadline of ``/healthz``, which then reports the store unreachable.
    health_min_free_bytes : int
        ``/healthz`` answers 503 when the file system of a SQLite database has less free.
    retry_after_s : int
        The ``Retry-After`` of a 503 caused by the store.
    db_busy_timeout_ms : int
        How long a SQLite writer waits for another process's write lock.
    db_connect_timeout_s, db_pool_timeout_s, db_statement_timeout_ms, db_lock_timeout_ms,
    db_idle_in_transaction_timeout_ms, db_lent_timeout_s, db_keepalives_idle_s,
    db_keepalives_interval_s, db_keepalives_count, db_tcp_user_timeout_ms
        Bounds on the waits on the database, see
        :class:`~routing_svc.store.engine.StoreTimeouts` (PostgreSQL; the pool's
        timeout applies to SQLite too). ``db_lent_timeout_s`` <= 0 turns the
        client-side bound off.
    """

    model_config = SettingsConfigDict(
        env_prefix="ROUTING_SVC_", extra="ignore", populate_by_name=True
    )

    database_url: str = Field(
        default="sqlite:///var/routing_svc.db",
        validation_alias="DATABASE_URL",
    )
    networks: dict[str, str] = Field(default_factory=dict)
    data_dir: Path = Path("var/networks")
    api_key: str | None = None
    cors_origins: list[str] = Field(default_factory=list)
    max_body_bytes: int = 4 * 1024 * 1024
    max_network_bytes: int = 64 * 1024 * 1024
    demo_fleet: bool = False
    demo_rate: float = 0.0
    recent_window: int = 200
    consolidation_workers: int = Field(default=1, ge=0)
    target_fast_path: bool = True
    request_timeout_s: float = Field(default=30.0, gt=0)
    health_timeout_s: float = Field(default=2.0, gt=0)
    health_min_free_bytes: int = Field(default=64 * 1024 * 1024, ge=0)
    retry_after_s: int = Field(default=2, ge=0)
    db_busy_timeout_ms: int = Field(default=30_000, ge=0)
    db_connect_timeout_s: int = Field(default=5, ge=2)
    db_pool_timeout_s: float = Field(default=5.0, gt=0)
    db_statement_timeout_ms: int = Field(default=5_000, ge=0)
    db_lock_timeout_ms: int = Field(default=5_000, ge=0)
    db_idle_in_transaction_timeout_ms: int = Field(default=10_000, ge=0)
    db_lent_timeout_s: float = 10.0
    db_keepalives_idle_s: int = Field(default=10, ge=1)
    db_keepalives_interval_s: int = Field(default=3, ge=1)
    db_keepalives_count: int = Field(default=3, ge=1)
    db_tcp_user_timeout_ms: int = Field(default=10_000, ge=0)

    def store_timeouts(self) -> StoreTimeouts:
        """The ``db_*`` bounds as the store takes them."""
        return StoreTimeouts(
            connect_s=self.db_connect_timeout_s,
            pool_checkout_s=self.db_pool_timeout_s,
            statement_ms=self.db_statement_timeout_ms,
            lock_ms=self.db_lock_timeout_ms,
            idle_in_transaction_ms=self.db_idle_in_transaction_timeout_ms,
            lent_s=self.db_lent_timeout_s if self.db_lent_timeout_s > 0 else None,
            keepalives_idle_s=self.db_keepalives_idle_s,
            keepalives_interval_s=self.db_keepalives_interval_s,
            keepalives_count=self.db_keepalives_count,
            tcp_user_timeout_ms=self.db_tcp_user_timeout_ms,
        )
