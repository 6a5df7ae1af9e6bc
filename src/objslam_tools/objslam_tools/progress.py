"""Progress on stderr for long CLI work: one updating line on a terminal, a line per 10 % otherwise."""

from __future__ import annotations

import sys
import time


class StderrProgress:
    def __init__(self, label: str, unit: str = "frames") -> None:
        self.label = label
        self.unit = unit
        self.tty = sys.stderr.isatty()
        self.started = time.monotonic()
        self.last_tenth = -1

    def __call__(self, done: int, total: int) -> None:
        if total <= 0:
            return
        elapsed = time.monotonic() - self.started
        text = f"{self.label}: {done}/{total} {self.unit} ({elapsed:.0f} s)"
        if self.tty:
            print(f"\r{text}", end="\n" if done >= total else "", file=sys.stderr, flush=True)
            return
        tenth = done * 10 // total
        if tenth != self.last_tenth:
            self.last_tenth = tenth
            print(text, file=sys.stderr, flush=True)
