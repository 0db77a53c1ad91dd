"""Serialised access to stateful objects shared across threads.

The compiled filter, tracker and least-squares objects release the GIL while they compute, so
two threads calling one object at once would meet a Rust borrow that is already taken ("Already
borrowed"). :func:`serialized` gives each instance a re-entrant lock that every public method
holds: concurrent calls then run one after another, as on a single thread.
"""

from __future__ import annotations

import functools
import threading
from typing import Any, TypeVar

T = TypeVar("T", bound=type)


def _locked(method: Any) -> Any:
    @functools.wraps(method)
    def call(self: Any, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            return method(self, *args, **kwargs)

    return call


def serialized(cls: T) -> T:
    """Class decorator: ``__init__`` creates ``self._lock`` and every public method holds it."""
    init = cls.__init__

    @functools.wraps(init)
    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:  # noqa: N807
        object.__setattr__(self, "_lock", threading.RLock())
        init(self, *args, **kwargs)

    cls.__init__ = __init__  # type: ignore[misc]
    for name, attr in list(vars(cls).items()):
        if not name.startswith("_") and callable(attr) and not isinstance(attr, (staticmethod, classmethod, type)):
            setattr(cls, name, _locked(attr))
    return cls
