"""The client against a real coordinator and worker: submit, wait, download, control, events,
frames, errors; and its bundling against `tessera submit --list-files`."""

from __future__ import annotations

import struct
import threading
from pathlib import Path
from typing import Any, Dict, List

import pytest

from conftest import REPO, Farm, scene, tessera, wait_until
from tessera_client import Client, JobFailed, TesseraError, pack


def png_size(path: Path) -> tuple:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    return struct.unpack(">II", data[16:24])


def test_submit_wait_and_download(farm: Farm, tmp_path: Path) -> None:
    with Client(farm.url, token=farm.token) as c:
        job = c.submit(scene("cornell-box"), integrator="pt", spp=4, seed=5, name="client test")
        assert job.state in ("queued", "final"), job.info
        seen: List[Dict[str, Any]] = []
        done = job.wait(timeout=300, progress=seen.append)
        assert done["state"] == "done" and done["progress"] == 1.0
        assert seen and seen[-1]["state"] == "done", seen
        tiles = [s["tiles_done"] for s in seen]
        assert tiles == sorted(tiles), "progress only goes forward"
        files = job.download(tmp_path / "out.exr")
        assert [f.name for f in files] == ["out.exr", "out.png"]
        assert (tmp_path / "out.exr").read_bytes()[:4] == b"\x76\x2f\x31\x01"  # OpenEXR magic
        assert png_size(tmp_path / "out.png") == (done["width"], done["height"])
        # the same bytes as the command-line client downloads
        tessera("download", job.id, "--server", farm.url, "--token", farm.token, "-o", str(tmp_path / "cli.exr"))
        assert (tmp_path / "cli.exr").read_bytes() == (tmp_path / "out.exr").read_bytes()
        assert [j.id for j in c.jobs(state="done", name="client")] == [job.id]


def test_control_pause_resume_priority_cancel_requeue_delete(farm: Farm) -> None:
    with Client(farm.url, token=farm.token) as c:
        job = c.submit(scene("cornell-box"), integrator="pt", spp=100000, seed=1)
        assert job.pause()["state"] == "paused"
        assert job.resume()["state"] != "paused"
        assert job.set_priority(7)["priority"] == 7
        assert job.cancel()["state"] == "cancelled"
        with pytest.raises(JobFailed) as failed:
            job.wait(timeout=30)
        assert failed.value.job["state"] == "cancelled"
        assert job.requeue()["state"] not in ("cancelled", "failed")
        job.cancel()
        job.delete()
        with pytest.raises(TesseraError) as gone:
            c.job(job.id)
        assert (gone.value.status, gone.value.code) == (404, "not_found")


def test_events_show_a_new_job(farm: Farm) -> None:
    with Client(farm.url, token=farm.token) as c:
        got: List[str] = []
        def watch() -> None:
            for event in c.events():
                if event.kind == "job.state" and event.data["state"] == "done":
                    got.append(event.data["job_id"])
                    return
        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        wait_until("the stream to open", lambda: watcher.is_alive())
        job = c.submit(scene("cornell-box"), integrator="pt", spp=2, seed=1)
        watcher.join(timeout=300)
        assert got == [job.id]


def test_frames_are_downloaded_into_a_folder(farm: Farm, tmp_path: Path) -> None:
    xml = scene("cornell-box").read_text()
    lookat = '<lookat origin="0, 0, 3.9" target="0, 0, 0" up="0, 1, 0"/>'
    assert lookat in xml
    xml = xml.replace(lookat, lookat + '<rotate y="1" angle="$frame"/>', 1)
    xml = xml.replace('<scene version="3.0.0">', '<scene version="3.0.0"><default name="frame" value="0"/>', 1)
    moving = tmp_path / "move.xml"
    moving.write_text(xml)
    with Client(farm.url, token=farm.token) as c:
        job = c.submit(moving, integrator="pt", spp=2, seed=3, frames="1-2")
        job.wait(timeout=300)
        files = job.download(tmp_path / "frames")
        assert sorted(f.name for f in files) == ["move.0001.exr", "move.0001.png", "move.0002.exr", "move.0002.png"]


def test_refusals_are_errors_with_the_problem(farm: Farm) -> None:
    with Client(farm.url, token="wrong") as c, pytest.raises(TesseraError) as e:
        c.jobs()
    assert (e.value.status, e.value.code) == (401, "unauthenticated")
    with Client(farm.url, token=farm.token) as c, pytest.raises(TesseraError) as e:
        c.submit(scene("cornell-box"), integrator="nonsense")
    assert e.value.status == 400 and "integrator" in e.value.detail


@pytest.mark.parametrize("name", sorted(p.parent.name for p in (REPO / "scenes").glob("*/scene.xml")))
def test_bundles_hold_what_the_cli_ships(name: str) -> None:
    scene_path, files = pack(scene(name))
    listed = tessera("submit", str(scene(name)), "--list-files").split()
    assert [path for path, _ in files] == listed
    assert scene_path == listed[0]
