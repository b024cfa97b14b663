"""Server-sent events of a coordinator (`/api/v1/events`, `/api/v1/jobs/{id}/events`)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Dict, Iterable, Iterator, List


@dataclass(frozen=True)
class Event:
    """One event: `kind` is `job.state`, `job.progress`, `job.deleted`, `frame.state`,
    `worker`, `worker.gone` or `lagged`; `data` the whole new state of what changed."""

    kind: str
    data: Dict[str, Any]
    id: str = ""


def parse(lines: Iterable[str]) -> Iterator[Event]:
    """Events from the lines of a `text/event-stream` body (comments and keep-alives skipped)."""
    kind, event_id = "message", ""
    data: List[str] = []
    for line in lines:
        line = line.rstrip("\r\n")
        if not line:
            if data:
                yield Event(kind, json.loads("\n".join(data)), event_id)
            kind, data, event_id = "message", [], ""
            continue
        if line.startswith(":"):
            continue
        name, _, value = line.partition(":")
        value = value[1:] if value.startswith(" ") else value
        if name == "event":
            kind = value
        elif name == "data":
            data.append(value)
        elif name == "id":
            event_id = value
