"""Silence native libraries that print to stdout/stderr (OpenEXR) while a file is read.

Bad input gets exactly one ``error:`` line: a library's own "Warning: ..." lines must
not precede it. What they printed is kept so the caller can fold it into its message.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
from collections.abc import Iterator


class Captured:
    text: str = ""

    @property
    def first_line(self) -> str:
        lines = [ln.strip() for ln in self.text.splitlines() if ln.strip()]
        return lines[0] if lines else ""


@contextlib.contextmanager
def quiet_output() -> Iterator[Captured]:
    """Capture Python-level and file-descriptor-level stdout/stderr for the block."""
    cap = Captured()
    buf = io.StringIO()
    saved: list[tuple[int, int]] = []
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        try:
            for fd in (1, 2):
                try:
                    saved.append((fd, os.dup(fd)))
                    os.dup2(tmp.fileno(), fd)
                except OSError:  # no such descriptor (embedded interpreters)
                    continue
            with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
                yield cap
        finally:
            for stream in (sys.__stdout__, sys.__stderr__):
                with contextlib.suppress(Exception):
                    stream.flush()  # type: ignore[union-attr]
            for fd, copy in saved:
                os.dup2(copy, fd)
                os.close(copy)
            tmp.seek(0)
            native = tmp.read().decode("utf-8", "replace")
            cap.text = buf.getvalue() + native
