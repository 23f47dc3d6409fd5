"""What a benchmark prints, also written as a Markdown page for the documentation.

``python benchmarks/bench_mesh.py --markdown docs/benchmarks/generated/bench_mesh.md``
prints its tables as usual and writes them, under a header that says which command made
them, on which machine and when, to the page the docs include (the committed file is what
the site shows). The page is written through the package's atomic writer, whole or not
at all, and the target folder is checked before the benchmark runs.
"""

from __future__ import annotations

import contextlib
import datetime
import io
import os
import platform
import sys
from collections.abc import Iterator
from pathlib import Path

__all__ = ["markdown_page", "machine"]


def machine() -> str:
    """One line: CPU model, core count, memory and Python, as the page states them."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            names = [ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")]
        cpu = names[0] if names else cpu
    except OSError:
        pass
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
        memory_text = f", {memory:.0f} GB memory"
    except (ValueError, OSError, AttributeError):
        memory_text = ""
    return (f"{cpu}, {os.cpu_count()} cores{memory_text}, {platform.system()}, "
            f"Python {platform.python_version()}")


class _Tee(io.TextIOBase):
    def __init__(self, *streams):
        self._streams = streams

    def write(self, text: str) -> int:
        for s in self._streams:
            s.write(text)
        return len(text)

    def flush(self) -> None:
        for s in self._streams:
            s.flush()


@contextlib.contextmanager
def markdown_page(path: str | os.PathLike | None, title: str, *, code: bool = False,
                  force: bool = True) -> Iterator[None]:
    """Tee standard output into a Markdown page at `path` (nothing when `path` is None).

    Parameters
    ----------
    path : str or PathLike or None
        The page to write; its folder must exist (checked before the block runs).
    title : str
        The page's heading.
    code : bool
        The script prints aligned text, not Markdown tables: the page shows it as a
        text block, as printed.
    force : bool
        Replace an existing page (the default: a benchmark re-run updates its page).
    """
    if path is None:
        yield
        return
    from napari_swa_imesh.io import atomic_write, check_writable

    path = Path(path)
    check_writable(path, force=force)
    captured = io.StringIO()
    started = datetime.datetime.now(datetime.UTC)
    command = " ".join(["python", Path(sys.argv[0]).as_posix(), *sys.argv[1:]])
    stdout = sys.stdout
    sys.stdout = _Tee(stdout, captured)
    try:
        yield
    finally:
        sys.stdout = stdout
    header = (f"## {title}\n\n"
              f"Written by `{command}` on {started:%Y-%m-%d %H:%M} UTC, on {machine()}.\n\n")
    body = captured.getvalue().rstrip()
    if code:
        body = f"```text\n{body}\n```"
    with atomic_write([path], force=force) as (tmp,):
        tmp.write_text(header + body + "\n", encoding="utf-8")
