# Shared fixtures of the Python tests (run from ctest as python_tests, tests/CMakeLists.txt):
# ARBOR_CLI is the `arbor` executable, ARBOR_DATA the repository's data/ directory; the module
# itself comes from PYTHONPATH (the build tree's python/ or an installed prefix).
import json
import os
import subprocess

import pytest


@pytest.fixture(scope="session")
def data_dir():
    return os.environ.get(
        "ARBOR_DATA", os.path.join(os.path.dirname(__file__), "..", "..", "data"))


@pytest.fixture(scope="session")
def arbor_cli():
    """Runs `arbor ARGS... --json` and returns the parsed JSON object."""
    cli = os.environ.get("ARBOR_CLI")
    if not cli:
        pytest.skip("ARBOR_CLI is not set")

    def run(*args):
        out = subprocess.run([cli, *args, "--json"], check=True, capture_output=True, text=True)
        return json.loads(out.stdout)

    run.path = cli
    return run
