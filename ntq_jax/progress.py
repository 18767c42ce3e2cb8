"""Progress bars are passed in: the contract, a silent bar and the tqdm factory.

Long stages take ``progress=``: ``None``/``False`` (silent), ``True`` (tqdm
bars on stderr) or any :class:`ProgressFn`, a factory called as
``progress(desc=..., total=..., unit=..., initial=...)`` that returns a
:class:`Bar`. Compute code only calls :func:`open_bar`; it never imports tqdm.
"""

from __future__ import annotations

from typing import Any, Protocol, Union

__all__ = ["Bar", "ProgressFn", "Progress", "NullBar", "tqdm_progress", "open_bar"]


class Bar(Protocol):
    """What a stage does with a bar (a subset of tqdm's interface)."""

    def update(self, n: int = 1) -> Any: ...

    def set_postfix_str(self, s: str) -> Any: ...

    def close(self) -> Any: ...

    def __enter__(self) -> "Bar": ...

    def __exit__(self, *exc) -> Any: ...


class ProgressFn(Protocol):
    """A bar factory."""

    def __call__(self, *, desc: str, total: int | None, unit: str, initial: int = 0) -> Bar: ...


Progress = Union[bool, None, ProgressFn]


class NullBar:
    """A bar that shows nothing."""

    def update(self, n: int = 1) -> None:
        pass

    def set_postfix_str(self, s: str) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self) -> "NullBar":
        return self

    def __exit__(self, *exc) -> None:
        pass


def tqdm_progress(*, desc: str, total: int | None, unit: str, initial: int = 0) -> Bar:
    """A tqdm bar (the scripts' default)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit=unit, leave=True, dynamic_ncols=True)


def open_bar(
    progress: Progress, *, desc: str, total: int | None, unit: str, initial: int = 0
) -> Bar:
    """The bar ``progress`` asks for: silent for None/False, tqdm for True, else the factory's."""
    if progress is None or progress is False:
        return NullBar()
    fn = tqdm_progress if progress is True else progress
    return fn(desc=desc, total=total, unit=unit, initial=initial)
