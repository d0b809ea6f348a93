"""Shared fixtures of the pytest suite: the CLI (TRBC_CLI, set by scripts/run_pytest) and a scratch
SFS cache shared by the CLI and the Python calls, so that both start from the same stress-free state."""
import json
import os
import subprocess
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def cli():
    path = os.environ.get("TRBC_CLI", str(Path(__file__).resolve().parents[2] / "build" / "trbc"))
    assert Path(path).is_file(), f"the trbc CLI is needed to compare with ({path}); build it (make build)"
    return path


@pytest.fixture(scope="session")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("sfs-cache")


@pytest.fixture(scope="session")
def run_cli(cli):
    def run(*args, json_out=True):
        r = subprocess.run([cli, *map(str, args)], capture_output=True, text=True,
                           env=dict(os.environ, OMP_NUM_THREADS="1"))
        assert r.returncode == 0, f"trbc {' '.join(map(str, args))} failed ({r.returncode}): {r.stderr}"
        return json.loads(r.stdout) if json_out else r.stdout
    return run
