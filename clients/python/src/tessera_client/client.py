"""The REST client: `Client` for a coordinator, `Job` for one of its jobs."""

from __future__ import annotations

import io
import json
import tarfile
import time
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, List, Mapping, Optional, Sequence, Union

import httpx

from . import bundle, events

JobInfo = Dict[str, Any]
Progress = Callable[[JobInfo], None]
ENDED = ("done", "failed", "cancelled")


class TesseraError(Exception):
    """The coordinator refused a request: `status`, the problem's `code` and `detail`."""

    def __init__(self, status: int, code: str, detail: str) -> None:
        super().__init__(f"{status} {code}: {detail}")
        self.status, self.code, self.detail = status, code, detail


class JobFailed(TesseraError):
    """A job that was waited for ended failed or cancelled."""

    def __init__(self, job: JobInfo) -> None:
        reason = job.get("error") or job["state"]
        super().__init__(409, job["state"], f"job {job['id']} ended {job['state']}: {reason}")
        self.job = job


def _check(r: httpx.Response) -> httpx.Response:
    if r.is_success:
        return r
    try:
        problem = r.json()
        code, detail = str(problem.get("code", "")), str(problem.get("detail", r.text))
    except ValueError:
        code, detail = "", r.text
    raise TesseraError(r.status_code, code, detail)


class Client:
    """A coordinator at `url` (`https://` with TLS), with the client `token` if it needs one and
    `ca_cert`, the PEM file its certificate chains to (a farm's own CA or a self-signed one)."""

    def __init__(self, url: str, token: Optional[str] = None, ca_cert: Optional[Union[str, Path]] = None,
                 timeout: float = 60.0) -> None:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        verify: Union[bool, str] = str(ca_cert) if ca_cert else True
        self.url = url.rstrip("/")
        self.http = httpx.Client(base_url=self.url, headers=headers, verify=verify, timeout=timeout)

    def close(self) -> None:
        self.http.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def submit(self, scene: Union[str, Path], *, integrator: Optional[str] = None, spp: Optional[int] = None,
               seed: Optional[int] = None, name: Optional[str] = None, priority: int = 0,
               after: Sequence[str] = (), require_tags: Sequence[str] = (), frames: Optional[str] = None,
               frame_param: str = "frame", seed_per_frame: bool = False, warm_start: bool = False,
               defines: Optional[Mapping[str, str]] = None, **settings: Any) -> "Job":
        """Submits a scene file (or a folder holding `scene.xml`) with every file it references.
        `settings` are further render settings as `tessera render` takes them (`max_depth`,
        `time_limit_s`, ...); `frames` (`"1-240"`) makes a job of frames, each with `$frame_param`
        set to its number."""
        path = bundle.find_scene(Path(scene))
        numbers = _frame_numbers(frames) if frames else None
        per_frame = [dict(defines or {}, **{frame_param: str(n)}) for n in numbers] if numbers else [dict(defines or {})]
        scene_path, files = bundle.pack(path, per_frame)
        body: Dict[str, Any] = {k: v for k, v in settings.items() if v is not None}
        given = {"integrator": integrator, "spp": spp, "seed": seed, "name": name or path.stem}
        body.update({k: v for k, v in given.items() if v is not None})
        if defines:
            body["defines"] = dict(defines)
        body.update(priority=priority, after=list(after), require_tags=list(require_tags))
        if frames:
            body.update(frames=frames, frame_param=frame_param, seed_per_frame=seed_per_frame, warm_start=warm_start)
        parts: List[Any] = [("settings", (None, json.dumps(body), "application/json"))]
        handles = [local.open("rb") for _, local in files]
        try:
            for (bundle_path, _), handle in zip(files, handles):
                part = "scene" if bundle_path == scene_path else "asset"
                parts.append((part, (bundle_path, handle, "application/octet-stream")))
            info = _check(self.http.post("/api/v1/jobs", files=parts)).json()
        finally:
            for handle in handles:
                handle.close()
        return Job(self, info)

    def job(self, job_id: str) -> "Job":
        """A job by id (or a unique prefix of it)."""
        return Job(self, _check(self.http.get(f"/api/v1/jobs/{job_id}")).json())

    def jobs(self, state: Optional[Union[str, Sequence[str]]] = None, name: Optional[str] = None) -> List["Job"]:
        """Every job, newest first, optionally in these states or with `name` in its name."""
        params: Dict[str, str] = {"limit": "1000"}
        if state:
            params["state"] = state if isinstance(state, str) else ",".join(state)
        if name:
            params["name"] = name
        out: List[Job] = []
        while True:
            page = _check(self.http.get("/api/v1/jobs", params=dict(params, offset=str(len(out))))).json()
            out += [Job(self, info) for info in page]
            if len(page) < 1000:
                return out

    def workers(self) -> List[Dict[str, Any]]:
        """The registered workers: id, name, state, threads, leases, tags."""
        result: List[Dict[str, Any]] = _check(self.http.get("/api/v1/workers")).json()
        return result

    def events(self, job_id: Optional[str] = None) -> Iterator[events.Event]:
        """Events as they happen: every job's and worker's, or one job's until it ends."""
        url = f"/api/v1/jobs/{job_id}/events" if job_id else "/api/v1/events"
        with self.http.stream("GET", url, timeout=httpx.Timeout(self.http.timeout.connect, read=None)) as r:
            if not r.is_success:
                r.read()
                _check(r)
            yield from events.parse(r.iter_lines())


class Job:
    """One job of a coordinator. `info` is its JSON as last read (`refresh` reads it again)."""

    def __init__(self, client: Client, info: JobInfo) -> None:
        self.client, self.info = client, info
        self.id: str = info["id"]

    def __repr__(self) -> str:
        return f"Job({self.id!r}, {self.info.get('name')!r}, {self.state!r})"

    @property
    def state(self) -> str:
        return str(self.info["state"])

    @property
    def progress(self) -> float:
        return float(self.info["progress"])

    def refresh(self) -> JobInfo:
        self.info = _check(self.client.http.get(f"/api/v1/jobs/{self.id}")).json()
        return self.info

    def wait(self, timeout: Optional[float] = None, progress: Optional[Progress] = None) -> JobInfo:
        """Follows the job's events until it ends; returns its JSON when done and raises
        `JobFailed` when it fails or is cancelled, `TimeoutError` after `timeout` seconds.
        `progress` is called with each new state of the job."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.refresh()["state"] not in ENDED:
            if deadline is not None and time.monotonic() >= deadline:
                raise TimeoutError(f"job {self.id} is still {self.state} after {timeout} s")
            try:
                self._follow(deadline, progress)
            except httpx.TransportError:
                time.sleep(1.0)  # the stream broke: read the state, then follow again
        if self.state != "done":
            raise JobFailed(self.info)
        return self.info

    def _follow(self, deadline: Optional[float], progress: Optional[Progress]) -> None:
        left = None if deadline is None else max(deadline - time.monotonic(), 0.1)
        timeout = httpx.Timeout(self.client.http.timeout.connect, read=left)
        with self.client.http.stream("GET", f"/api/v1/jobs/{self.id}/events", timeout=timeout) as r:
            if not r.is_success:
                r.read()
                _check(r)
            try:
                for event in events.parse(r.iter_lines()):
                    if event.kind.startswith("job.") and event.data.get("job_id") == self.id and progress:
                        progress(event.data)
                    if deadline is not None and time.monotonic() >= deadline:
                        return
            except httpx.ReadTimeout:
                return

    def download(self, path: Union[str, Path]) -> List[Path]:
        """Writes a done job's outputs: the EXR to `path`, the PNG beside it, and for EMIS the
        strategy PNG and report; a job of frames' frames go into the folder `path`. Returns the
        files written."""
        path = Path(path)
        if self.info.get("frames_total"):
            path.mkdir(parents=True, exist_ok=True)
            data = _check(self.client.http.get(f"/api/v1/jobs/{self.id}/frames.tar")).content
            with tarfile.open(fileobj=io.BytesIO(data)) as tar:
                members = [m for m in tar.getmembers() if m.isfile() and "/" not in m.name and ".." not in m.name]
                tar.extractall(path, members=members)
            return [path / m.name for m in members]
        outputs = [("result.exr", path), ("preview.png", path.with_suffix(".png"))]
        if str(self.info.get("settings", {}).get("integrator", "")).startswith("emis-"):
            outputs += [("strategy.png", path.with_suffix(".strategy.png")), ("emis.json", path.with_suffix(".emis.json"))]
        for name, target in outputs:
            target.write_bytes(_check(self.client.http.get(f"/api/v1/jobs/{self.id}/{name}")).content)
        return [target for _, target in outputs]

    def _act(self, action: str) -> JobInfo:
        self.info = _check(self.client.http.post(f"/api/v1/jobs/{self.id}/{action}")).json()
        return self.info

    def cancel(self) -> JobInfo:
        return self._act("cancel")

    def pause(self) -> JobInfo:
        return self._act("pause")

    def resume(self) -> JobInfo:
        return self._act("resume")

    def requeue(self) -> JobInfo:
        return self._act("requeue")

    def set_priority(self, priority: int) -> JobInfo:
        self.info = _check(self.client.http.patch(f"/api/v1/jobs/{self.id}", json={"priority": priority})).json()
        return self.info

    def delete(self) -> None:
        _check(self.client.http.delete(f"/api/v1/jobs/{self.id}"))


def _frame_numbers(frames: str) -> List[int]:
    """`1-10,12,20-30:5` as numbers, each once (the coordinator checks the rule again)."""
    numbers: List[int] = []
    for part in frames.split(","):
        span, _, step = part.strip().partition(":")
        first, _, last = span.partition("-")
        try:
            lo, hi, by = int(first), int(last or first), int(step or 1)
        except ValueError:
            raise ValueError(f"frames \"{frames}\": \"{part}\" is not N, A-B or A-B:S") from None
        numbers += [n for n in range(lo, hi + 1, max(by, 1)) if n not in numbers]
    return numbers
