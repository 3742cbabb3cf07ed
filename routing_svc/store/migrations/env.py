"""Alembic environment of the event-log store.

Migrations run only programmatically, from :func:`routing_svc.store.engine.upgrade`,
which passes an open connection (already inside a transaction) in
``config.attributes["connection"]``. There is no ``alembic.ini`` and no logging
setup here, so running migrations never reconfigures the application's logging.
"""

from __future__ import annotations

from alembic import context
from sqlalchemy.engine import Connection

from routing_svc.store.schema import metadata


def run_migrations_online() -> None:
    """Run the pending migrations on the connection handed in by the caller."""
    connection = context.config.attributes.get("connection")
    if not isinstance(connection, Connection):
        raise RuntimeError(
            "routing_svc migrations run programmatically: pass a Connection in "
            "config.attributes['connection'] (see routing_svc.store.engine.upgrade)"
        )
    context.configure(connection=connection, target_metadata=metadata)
    with context.begin_transaction():
        context.run_migrations()


run_migrations_online()
