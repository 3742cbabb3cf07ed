"""Service settings (pydantic-settings): environment ``ROUTING_SVC_*`` or arguments."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict


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
    target_fast_path : bool
        Serve ``POST /v1/fleets/{id}/targets`` from the ASGI layer for valid
        bodies (:mod:`routing_svc.service.fastpath`); off, FastAPI's route serves
        every request. The answers are the same bytes either way.
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
    target_fast_path: bool = True
