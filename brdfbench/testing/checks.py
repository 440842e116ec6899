"""A named set of conformance checks, each gated by the spec tags it needs."""

from __future__ import annotations

from typing import Callable, Generic, TypeVar

C = TypeVar("C")


class CheckSet(Generic[C]):
    """`@checks.register("fittable")` adds `check_foo(ctx)` as "foo", run when a spec has every tag."""

    def __init__(self) -> None:
        self.checks: dict[str, tuple[frozenset[str], Callable[[C], None]]] = {}

    def register(self, *requires: str):
        def deco(fn: Callable[[C], None]) -> Callable[[C], None]:
            self.checks[fn.__name__.removeprefix("check_")] = (frozenset(requires), fn)
            return fn

        return deco

    def items(self):
        return self.checks.items()
