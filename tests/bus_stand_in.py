"""A stand-in for a process's bus, for tests that drive a server's handlers directly: it
subscribes and serves nothing, and records what the server drops as implausible."""

from __future__ import annotations

from fleet.protocol import Keys


class NoBus:
    keys = Keys()

    def __init__(self) -> None:
        self.dropped: list[tuple[str, str, str]] = []

    def subscribe(self, *_args: object) -> None:
        return None

    def serve(self, *_args: object) -> None:
        return None

    def watch_alive(self, *_args: object) -> None:
        return None

    def drop_implausible(self, key: str, sender: str, why: str, n: int = 1) -> None:
        self.dropped.append((key, sender, why))
