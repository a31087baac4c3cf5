"""A named registry of stage variants: a new variant is one module and one `register` line."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Generic, TypeVar

Variant = TypeVar("Variant")


class UnknownVariant(ValueError):
    """A stage variant was asked for by a name nobody registered."""


class Registry(Generic[Variant]):
    """Variants of one planner stage, by name (the name is stored with every plan)."""

    def __init__(self, stage: str) -> None:
        self.stage = stage
        self._variants: dict[str, Variant] = {}

    def register(self, name: str, variant: Variant) -> Variant:
        """Add a variant under `name`; names are unique within a stage."""
        if name in self._variants:
            raise ValueError(f"{self.stage} variant {name!r} is already registered")
        self._variants[name] = variant
        return variant

    def get(self, name: str) -> Variant:
        """The variant registered as `name`, or an error listing the known ones."""
        try:
            return self._variants[name]
        except KeyError:
            known = ", ".join(sorted(self._variants)) or "none"
            raise UnknownVariant(f"unknown {self.stage} {name!r} (known: {known})") from None

    def names(self) -> list[str]:
        """The registered names, sorted."""
        return sorted(self._variants)

    def __contains__(self, name: object) -> bool:
        return name in self._variants

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())
