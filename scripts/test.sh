#!/usr/bin/env bash
# Installs everything the tests need and runs them: lint, types, then pytest.
# Used as-is by the README quick start and by .ci/run.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}

# Debian packages: Chromium for the dashboard's browser tests.
if ! command -v chromium >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ]; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null
  else
    echo "scripts/test.sh: chromium is missing; run as root or: sudo apt-get install chromium" >&2
    exit 1
  fi
fi

# PostgreSQL: the store and service tests run against both SQLite and PostgreSQL.
if command -v pg_ctlcluster >/dev/null 2>&1 && ! pg_isready -h 127.0.0.1 -p 5432 -q 2>/dev/null; then
  for version in $(ls /etc/postgresql 2>/dev/null); do
    pg_ctlcluster --skip-systemctl-redirect "$version" main start || true
  done
  for _ in $(seq 1 30); do pg_isready -h 127.0.0.1 -p 5432 -q && break; sleep 1; done
fi
export ROUTING_SVC_TEST_PG_URL=${ROUTING_SVC_TEST_PG_URL:-postgresql+psycopg://postgres@127.0.0.1:5432/test}

"$PYTHON" -m pip install -q -e '.[test]'

"$PYTHON" -m ruff check routing_svc tests bench sumo_nets
"$PYTHON" -m ruff format --check routing_svc tests bench sumo_nets
"$PYTHON" -m mypy

# one pytest worker per core (PYTEST_WORKERS, default 2); a test file stays on one worker,
# so a module's fixtures (a SUMO run, a server) are built once
"$PYTHON" -m pytest -n "${PYTEST_WORKERS:-2}" --dist loadfile "$@"
