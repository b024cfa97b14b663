"""A real coordinator and worker for the client's tests: the debug binaries of the repository
(or those in $TESSERA_BIN), on a loopback port, with tokens."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path
from typing import Iterator, NamedTuple

import pytest

REPO = Path(__file__).resolve().parents[3]
BIN = Path(os.environ.get("TESSERA_BIN", REPO / "target" / "debug"))
TOKEN = "client-test-token"


class Farm(NamedTuple):
    url: str
    token: str
    data: Path


def scene(name: str) -> Path:
    return REPO / "scenes" / name / "scene.xml"


def tessera(*args: str) -> str:
    """Runs the `tessera` command and returns its standard output."""
    return subprocess.run([str(BIN / "tessera"), *args], check=True, capture_output=True, text=True).stdout


@pytest.fixture()
def farm(tmp_path: Path) -> Iterator[Farm]:
    serve = subprocess.Popen(
        [str(BIN / "tessera"), "serve", "--data-dir", str(tmp_path / "data"), "--listen", "127.0.0.1:0",
         "--client-token", TOKEN, "--worker-token", "worker-token"],
        stdout=subprocess.PIPE, stderr=open(tmp_path / "serve.log", "w"), text=True)
    assert serve.stdout is not None
    line = serve.stdout.readline()
    assert line.startswith("tessera serve: listening on "), line
    url = line.rsplit(" ", 1)[1].strip()
    worker = subprocess.Popen(
        [str(BIN / "tessera-worker"), "--coordinator", url, "--token", "worker-token", "--threads", "1",
         "--cache-dir", str(tmp_path / "cache")],
        stdout=subprocess.DEVNULL, stderr=open(tmp_path / "worker.log", "w"))
    try:
        yield Farm(url, TOKEN, tmp_path)
    finally:
        for p in (worker, serve):
            p.terminate()
        for p in (worker, serve):
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()


def wait_until(what: str, check: "object", timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not check():  # type: ignore[operator]
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.1)
