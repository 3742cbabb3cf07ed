"""``bench/cosim_report.py --render-only`` with nothing finished in its work folder ends
with a one-line error and leaves the report it would overwrite as it was."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WRITTEN = [ROOT / "docs" / "cosim.md", ROOT / "docs" / "figures" / "cosim" / "report.json"]


def test_render_only_without_finished_runs_writes_nothing(tmp_path: Path) -> None:
    before = {path: path.read_bytes() for path in WRITTEN}
    done = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "cosim_report.py"), "--render-only", "--quiet",
         "--workdir", str(tmp_path / "empty")],
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )  # fmt: skip
    after = {path: path.read_bytes() for path in WRITTEN}
    for path, data in before.items():  # put the report back if it was overwritten
        if after[path] != data:
            path.write_bytes(data)
    assert done.returncode == 2, done.stderr
    assert "no experiment has finished in" in done.stderr.strip().splitlines()[-1]
    assert after == before
