"""The README's quick start in a fresh virtualenv: install, run, install for the tests, run.

``pip install .`` then a command that compiles the numba kernels, then the editable
install that ``scripts/test.sh`` makes, then ``routing-svc --help``: the second install
must find no compiled cache left in ``site-packages`` (numba's cache is in the user's cache
folder, :mod:`routing_svc.paths`), and the command must still import the package.
"""

from __future__ import annotations

import os
import subprocess
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def run(args: list[str], env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(args, env=env, cwd=cwd, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, (args, done.stdout[-2000:], done.stderr[-4000:])
    return done


@pytest.mark.slow
def test_the_quick_start_installs_in_that_order_then_runs(tmp_path: Path) -> None:
    env_dir = tmp_path / "venv"
    # the project's dependencies come from this interpreter's site-packages: no download
    venv.EnvBuilder(system_site_packages=True, with_pip=True).create(env_dir)
    python = str(env_dir / "bin" / "python")
    env = {
        **os.environ,
        "HOME": str(tmp_path / "home"),
        "PATH": f"{env_dir / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
        "PIP_NO_BUILD_ISOLATION": "1",
        "PIP_DISABLE_PIP_VERSION_CHECK": "1",
    }
    for name in ("ROUTING_SVC_CACHE", "NUMBA_CACHE_DIR", "PYTHONPATH"):
        env.pop(name, None)
    site = Path(
        run(
            [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            env,
            tmp_path,
        ).stdout.strip()
    )
    run([python, "-m", "pip", "install", "-q", "--no-deps", str(ROOT)], env, tmp_path)
    installed = site / "routing_svc"
    assert (installed / "__init__.py").is_file()
    # compiles and caches the search kernels
    run(
        [str(env_dir / "bin" / "routing-svc"), "simulate", "--net", "grid", "--vehicles", "2",
         "--targets", "40", "--checkpoints", "1", "--start", "random", "--quiet"],
        env, tmp_path,
    )  # fmt: skip
    assert not list(installed.rglob("*.nb[ic]")), "numba cached beside the installed sources"
    assert list((tmp_path / "home" / ".cache" / "routing_svc" / "numba").rglob("*.nbi"))
    run([python, "-m", "pip", "install", "-q", "--no-deps", "-e", str(ROOT)], env, tmp_path)
    assert not installed.exists(), f"left in site-packages: {sorted(installed.rglob('*'))[:5]}"
    run([str(env_dir / "bin" / "routing-svc"), "--help"], env, tmp_path)
    found = run([python, "-c", "import routing_svc.network as n; print(n.__file__)"], env, tmp_path)
    assert Path(found.stdout.strip()).is_relative_to(ROOT)
