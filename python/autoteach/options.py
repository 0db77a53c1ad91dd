"""Option objects: the one check that every frozen options dataclass of the package shares.

Each capability with many settings takes a frozen dataclass (``AutoteachConfig``,
``WaferDetectOptions``, ``VotingOptions``, ``SolverOptions``, ``SessionOptions``, …) and keyword
overrides of its fields. An override with a name the dataclass does not have is refused, and
the message lists the names it does have, so a typo never falls back silently to a default.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import Any, TypeVar

from autoteach.errors import InvalidInputError

__all__ = ["checked_replace", "field_names", "refuse_unknown"]

T = TypeVar("T")


def refuse_unknown(known: Iterable[str], given: Iterable[str], what: str) -> None:
    """Raise :class:`InvalidInputError` when a name of ``given`` is not in ``known``.

    ``what`` names the options in the message (``"voting"`` gives "unknown voting option(s)").
    """
    known = set(known)
    unknown = sorted(set(given) - known)
    if unknown:
        raise InvalidInputError(f"unknown {what} option(s) {unknown}; the options are {sorted(known)}")


def field_names(cls: Any) -> set[str]:
    """The field names of a dataclass (type or instance)."""
    return {f.name for f in dataclasses.fields(cls)}


def checked_replace(options: T, what: str, changes: dict[str, Any]) -> T:
    """A copy of the dataclass ``options`` with ``changes``; unknown names are refused."""
    refuse_unknown(field_names(options), changes, what)
    return dataclasses.replace(options, **changes)  # type: ignore[type-var]
