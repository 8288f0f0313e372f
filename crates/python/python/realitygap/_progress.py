"""Progress of the long calls: the extension sends its events (bars, notes,
result lines) to a reporter on the calling thread; this one draws tqdm
bars (``tqdm.auto``: a widget in Jupyter with ipywidgets, text elsewhere)
and writes notes to ``sys.stderr``."""

import sys
import warnings
from typing import Any, Dict, List


def _tqdm() -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from tqdm.auto import tqdm
    return tqdm


class Reporter:
    """Receives a long call's events. ``show``: draw bars and notes (else
    silent); ``lines`` collects the lines the command prints on standard
    output."""

    def __init__(self, show: bool = True) -> None:
        self.show = show
        self.bars: Dict[int, Any] = {}
        self.lines: List[str] = []

    def bar(self, id: int, total: int, unit: str) -> None:
        if not self.show:
            return
        tqdm = _tqdm()
        self.bars[id] = tqdm(
            total=total or None,
            unit=unit[:-1] if unit.endswith("s") else unit,
            leave=False,
            dynamic_ncols=True,
            file=sys.stderr,
        )

    def inc(self, id: int, n: int) -> None:
        bar = self.bars.get(id)
        if bar is not None:
            bar.update(n)

    def position(self, id: int, n: int) -> None:
        bar = self.bars.get(id)
        if bar is not None and n >= bar.n:
            bar.update(n - bar.n)

    def message(self, id: int, text: str) -> None:
        bar = self.bars.get(id)
        if bar is not None:
            bar.set_postfix_str(text, refresh=True)

    def finish(self, id: int) -> None:
        bar = self.bars.pop(id, None)
        if bar is not None:
            bar.close()

    def note(self, line: str) -> None:
        if not self.show:
            return
        if self.bars:
            _tqdm().write(line, file=sys.stderr)
        else:
            print(line, file=sys.stderr, flush=True)

    def say(self, line: str) -> None:
        self.lines.append(line)

    def close(self) -> None:
        for id in list(self.bars):
            self.finish(id)


def reporter(progress: Any) -> Any:
    """``True``: tqdm bars; ``False``/``None``: silent; anything else is a
    reporter of its own (the methods of :class:`Reporter`)."""
    if progress is True:
        return Reporter(True)
    if progress is False or progress is None:
        return Reporter(False)
    return progress
