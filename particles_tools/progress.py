"""One progress display for every long command (run, chart, bench, gallery, wedge): items done of
the total, the rate, the time left, and a short note; drawn by ``rich.progress`` on stderr.

Off when stderr is not a terminal (a pipe, a log file, a test) or with ``quiet``: then nothing is
drawn and stdout and stderr carry only the command's own lines. Use::

    with progress(total=120, unit="frames", label="sparks", quiet=args.quiet) as bar:
        for k in range(120):
            ...
            bar.advance(note=f"live {alive:,}")
"""
from __future__ import annotations

import contextlib
import sys


class _Off:
    """The display when it is off: same calls, nothing drawn."""

    def advance(self, n: int = 1, note: str = "") -> None:
        pass

    def update(self, completed: int, note: str = "") -> None:
        pass


class _Bar:
    def __init__(self, prog, task):
        self._prog, self._task = prog, task

    def advance(self, n: int = 1, note: str = "") -> None:
        self._prog.update(self._task, advance=n, note=note)

    def update(self, completed: int, note: str = "") -> None:
        self._prog.update(self._task, completed=completed, note=note)


def enabled(quiet: bool = False, stream=None) -> bool:
    stream = stream if stream is not None else sys.stderr
    return not quiet and bool(getattr(stream, "isatty", lambda: False)())


@contextlib.contextmanager
def progress(total: int, unit: str = "items", label: str = "", quiet: bool = False, stream=None):
    """A progress display over ``total`` ``unit`` (frames, cases, sections) on ``stream``
    (default stderr), or a silent stand-in when that is not a terminal or ``quiet`` is set.
    The display is removed when the block ends, so error lines after it stand alone."""
    stream = stream if stream is not None else sys.stderr
    if not enabled(quiet, stream):
        yield _Off()
        return
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                               TimeRemainingColumn)

    class Rate(TextColumn):
        def __init__(self):
            super().__init__("")

        def render(self, task):
            from rich.text import Text

            speed = task.finished_speed or task.speed
            return Text(f"{speed:6.1f} {unit}/s" if speed else f"   ... {unit}/s")

    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), Rate(),
               TimeRemainingColumn(), TextColumn("{task.fields[note]}"))
    with Progress(*columns, console=Console(file=stream), transient=True,
                  refresh_per_second=4) as prog:
        yield _Bar(prog, prog.add_task(label, total=max(1, int(total)), note=""))
