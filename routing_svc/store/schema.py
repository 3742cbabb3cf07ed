"""The store's tables (SQLAlchemy Core).

The tables are created and changed only by the Alembic migrations in
``routing_svc/store/migrations``; this module describes the head revision so
queries can be built from it (a test checks that the two agree).

``events.batch_size`` is the number of events written by the same append call;
the idempotency key and request hash are kept on the first event of that batch,
so a retried call can return every event the first call wrote.
"""

from __future__ import annotations

import sqlalchemy as sa

__all__ = [
    "ID_LENGTH",
    "KEY_LENGTH",
    "KIND_LENGTH",
    "events",
    "fleets",
    "metadata",
    "networks",
    "store_probe",
]

ID_LENGTH = 128
"""Longest network or fleet id."""
KEY_LENGTH = 255
"""Longest idempotency key or request hash."""
KIND_LENGTH = 64
"""Longest event kind."""

metadata = sa.MetaData()

networks = sa.Table(
    "networks",
    metadata,
    sa.Column("id", sa.String(ID_LENGTH), primary_key=True),
    sa.Column("sha256", sa.String(64), nullable=False),
    sa.Column("path", sa.Text(), nullable=False),
    sa.Column("name", sa.Text(), nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("meta", sa.Text(), nullable=False),
)

fleets = sa.Table(
    "fleets",
    metadata,
    sa.Column("id", sa.String(ID_LENGTH), primary_key=True),
    sa.Column(
        "network_id",
        sa.String(ID_LENGTH),
        sa.ForeignKey("networks.id", name="fk_fleets_network_id"),
        nullable=False,
    ),
    sa.Column("config", sa.Text(), nullable=False),
    sa.Column("version", sa.Integer(), nullable=False),
    sa.Column("state", sa.Text(), nullable=True),
    sa.Column("snapshot_version", sa.Integer(), nullable=True),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("deleted", sa.Boolean(), nullable=False),
)

events = sa.Table(
    "events",
    metadata,
    sa.Column(
        "fleet_id",
        sa.String(ID_LENGTH),
        sa.ForeignKey("fleets.id", name="fk_events_fleet_id"),
        primary_key=True,
    ),
    sa.Column("seq", sa.Integer(), primary_key=True, autoincrement=False),
    sa.Column("kind", sa.String(KIND_LENGTH), nullable=False),
    sa.Column("payload", sa.Text(), nullable=False),
    sa.Column("result", sa.Text(), nullable=True),
    sa.Column("idempotency_key", sa.String(KEY_LENGTH), nullable=True),
    sa.Column("request_hash", sa.String(KEY_LENGTH), nullable=True),
    sa.Column("batch_size", sa.Integer(), nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.UniqueConstraint("fleet_id", "idempotency_key", name="uq_events_fleet_idempotency_key"),
)

store_probe = sa.Table(
    "store_probe",
    metadata,
    sa.Column("id", sa.Integer(), primary_key=True, autoincrement=False),
    sa.Column("written_at", sa.DateTime(timezone=True), nullable=True),
)
"""One row that ``/healthz`` rewrites to learn whether the store takes writes again
after a write failed (:meth:`EventLog.probe_write`)."""
