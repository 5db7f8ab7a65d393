"""Shared fixtures: the command-line tool, the backend under test, images and readers of the tool's
files.

- ``CLATCH_CLI``: the ``clatch`` binary to compare with (cli/tests/python_package.rs sets it); without
  it the tests build one with ``cargo build --release -p clatch-cli`` (skipped if cargo is missing).
- ``CLATCH_TEST_BACKEND``: the backend the package is tested on (default ``cpu``; ``cuda`` on a GPU
  machine with a CUDA build). The tool always runs on the CPU: both backends give the same bits.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from helpers import REPO


@pytest.fixture(scope="session")
def backend() -> str:
    return os.environ.get("CLATCH_TEST_BACKEND", "cpu")


@pytest.fixture(scope="session")
def cli() -> Path:
    """The ``clatch`` command-line tool."""
    given = os.environ.get("CLATCH_CLI")
    if given:
        path = Path(given)
        assert path.is_file(), f"CLATCH_CLI={given} is not a file"
        return path
    if shutil.which("cargo") is None:
        pytest.skip("no CLATCH_CLI and no cargo to build the command-line tool")
    out = subprocess.run(
        ["cargo", "build", "--release", "-p", "clatch-cli", "--message-format=json-render-diagnostics"],
        cwd=REPO,
        check=True,
        stdout=subprocess.PIPE,
        text=True,
    ).stdout
    for line in out.splitlines():
        msg = json.loads(line)
        if msg.get("reason") == "compiler-artifact" and msg["target"]["name"] == "clatch":
            if msg.get("executable"):
                return Path(msg["executable"])
    raise AssertionError("cargo built no clatch binary")
