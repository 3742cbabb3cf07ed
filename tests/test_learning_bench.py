"""``bench/learning.py --rest`` prints one JSON document on standard output: the server it
starts for the REST curve writes its banner elsewhere."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_rest_curve_keeps_standard_output_json(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "learning.py"), "--nets", "grid", "--vehicles", "2",
         "--seeds", "0", "--rules", "consolidating", "--scenarios", "cold", "--targets", "300",
         "--jobs", "1", "--rest"],
        capture_output=True, text=True, timeout=600, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    rest = report["rest"]
    assert rest["rule"] == "consolidating"
    assert set(rest["gaps"]) == {"300"}
    assert "API docs at" in done.stderr
