"""Remove the lighting of co-moving artificial lights from deep-sea survey photographs (Köser et al., "Robustly
Removing Deep Sea Lighting Effects for Visual Mapping of Abyssal Plains").

numpy arrays in, numpy arrays out::

    import abysslight
    scatter = abysslight.Scatter.from_frames(water_column_frames)
    engine = abysslight.Engine(scatter=scatter, transfer="srgb")
    for i, photo in enumerate(photos):
        for c in engine.push(photo, i):
            corrected[c.tag] = c.image
    for c in engine.finish():
        corrected[c.tag] = c.image

a list of arrays in one call::

    corrected = abysslight.correct_arrays(photos, water_column=water_column_frames, transfer="srgb")

or a whole mission from folders to folders, as ``abysslight correct`` runs it::

    report = abysslight.correct(water_column="descent", survey="survey", out="corrected")

Options are the command's options by the config file's names with ``_`` (``window=9``, ``method="paper"``); none
given are the command's defaults. See docs/python.md.
"""

import typing as _t

from . import _abysslight
from ._abysslight import (
    Corrected,
    Engine,
    Mask,
    Scatter,
    __version__,
    correct_arrays,
    evaluate,
    read,
    simulate,
)

__all__ = [
    "Corrected",
    "Engine",
    "FlaggedPhotosError",
    "Mask",
    "Scatter",
    "correct",
    "correct_arrays",
    "evaluate",
    "read",
    "simulate",
    "__version__",
]

_ProgressCallback = _t.Callable[[int, int, str, bool], _t.Any]


class FlaggedPhotosError(RuntimeError):
    """Raised by ``correct(..., strict=True)`` (the command's ``--strict``, exit status 3) when the run flagged
    photos as likely wrong. The run has written everything; ``report`` is the report ``correct()`` would have
    returned (for a cruise: ``{"dives": ..., "failed": ...}``)."""

    def __init__(self, message: str, report: _t.Dict[str, _t.Any]) -> None:
        super().__init__(message)
        self.report = report


def _flagged(report: _t.Dict[str, _t.Any]) -> int:
    return sum(1 for f in report.get("frames", []) if f.get("health", {}).get("flags"))


def _strict_check(report: _t.Dict[str, _t.Any]) -> None:
    """``FlaggedPhotosError`` when a strict run flagged photos (each dive of a cruise its own run)."""
    runs = report["dives"].items() if "dives" in report else [("", report)]
    said = []
    for name, r in runs:
        n = _flagged(r)
        if n and r.get("options", {}).get("strict"):
            where = f"{name}: " if name else ""
            said.append(f"{where}{n} of {len(r['frames'])} photos flagged as likely wrong")
    if said:
        raise FlaggedPhotosError(
            "strict: " + "; ".join(said) + " (every file was written; the flags are in the report)", report
        )


def _tqdm_progress() -> "tuple[_t.Optional[_ProgressCallback], _t.Callable[[], None]]":
    """A tqdm bar fed by the run's callback, if tqdm is installed."""
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None, lambda: None
    bar = None

    def update(done: int, total: int, path: str, ok: bool) -> None:
        nonlocal bar
        if bar is None:
            bar = tqdm(total=total or None, unit="photo", desc="abysslight")
        bar.update(1)

    def close() -> None:
        if bar is not None:
            bar.close()

    return update, close


def correct(
    survey: _t.Optional[_t.Any] = None,
    out: _t.Optional[_t.Any] = None,
    water_column: _t.Optional[_t.Any] = None,
    *,
    progress: "_t.Optional[_ProgressCallback | bool]" = None,
    **options: _t.Any,
) -> _t.Dict[str, _t.Any]:
    """Run ``abysslight correct``: correct the photos of the folder ``survey`` into ``out``, with ``S`` from the
    water-column frames in ``water_column`` (or ``scatter="scatter.png"``), and return the run report (what
    ``out/_abysslight/report.json`` holds) as a dict. With ``cruise="CRUISE"`` (instead of ``survey`` and
    ``water_column``) every dive of the cruise into ``out/<dive>``, and ``{"dives": {name: report}, "failed":
    {name: message}}``.

    ``options`` are the command's options by the config file's names with ``_`` (``window=9``, ``method="paper"``,
    ``transfer="srgb"``, ``resume=True``); ``config="dive.toml"`` is read first and the keywords override it. None
    given are the command's defaults. Switches are ``denoise=False`` or ``no_denoise=True``.

    ``progress``: a callable ``progress(done, total, path, ok)`` called after each photo; ``None`` (default) shows a
    tqdm bar when tqdm is installed; ``False``: nothing. Stages and warnings go to the ``abysslight`` logger, and
    the end-of-run summary as the command prints it (at WARNING when photos were flagged or files failed).

    ``strict=True`` (``--strict``): raise ``FlaggedPhotosError`` (with the report) when photos were flagged as
    likely wrong, after the run has written everything.

    The GIL is released while it runs. Ctrl-C (KeyboardInterrupt) stops it before the next photo; the photos
    written so far are complete and ``resume=True`` finishes the run. An exception raised by ``progress`` stops it
    the same way and is raised here.

    Raises TypeError for an unknown option (naming the accepted ones) or a value of the wrong type, ValueError for a
    bad value (with the command's message), OSError when a folder cannot be read.
    """
    close: _t.Callable[[], None] = lambda: None
    if progress is None:
        callback, close = _tqdm_progress()
    elif progress is False:
        callback = None
    elif progress is True:
        callback, close = _tqdm_progress()
    else:
        callback = progress
    try:
        report = _abysslight.correct(
            progress=callback, survey=survey, out=out, water_column=water_column, **options
        )
    finally:
        close()
    _strict_check(report)
    return report
