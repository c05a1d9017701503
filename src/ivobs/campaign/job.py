"""A job: one cell of a campaign's grid, with a stable id."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, fields
from functools import cached_property
from typing import Any

from ..io.fingerprint import canonical_json as canonical  # the stable text a job id hashes

__all__ = ["Job", "canonical"]


@dataclass(frozen=True)
class Job:
    """One cell of the grid. ``burn_in=None``: a tenth of the record (as ``ivobs compare``)."""

    scenario: str
    method: str
    seed: int
    disturbance: str = "vertex"
    options: dict[str, Any] = field(default_factory=dict)
    scenario_options: dict[str, Any] = field(default_factory=dict)
    burn_in: int | None = None
    imports: tuple[str, ...] = ()

    def params(self) -> dict[str, Any]:
        """Everything that determines the result (``imports`` only make names available)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "imports"}

    @cached_property
    def id(self) -> str:
        """16 hex digits of the SHA-256 of the canonical JSON of :meth:`params`."""
        return hashlib.sha256(canonical(self.params()).encode()).hexdigest()[:16]

    def design_key(self) -> str:
        """Jobs with the same key share a design (they differ only in seed and disturbance)."""
        return canonical(
            [self.scenario, self.scenario_options, self.method, self.options, list(self.imports)]
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain values, for another process or a Dask worker."""
        return {**self.params(), "imports": list(self.imports), "job_id": self.id}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Job:
        return cls(
            scenario=d["scenario"], method=d["method"], seed=d["seed"],
            disturbance=d["disturbance"], options=dict(d["options"]),
            scenario_options=dict(d["scenario_options"]), burn_in=d["burn_in"],
            imports=tuple(d.get("imports", ())),
        )  # fmt: skip
