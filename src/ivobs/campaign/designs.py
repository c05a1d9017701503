"""Every design of a campaign, constructed once before its jobs run (``--dry-run`` and the
start of a campaign): an invalid option value is a bad spec, not a column of failed jobs."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from ..errors import IvobsError
from .worker import cached_scenario

if TYPE_CHECKING:
    from .spec import CampaignSpec

__all__ = ["check_designs"]


def check_designs(spec: CampaignSpec) -> list[str]:
    """Construct every estimator of the spec once (per scenario, method and option set): an
    invalid option value (every job of it would fail) raises :class:`~ivobs.IvobsError` naming
    the spec and the method's options. Returns one line per design that the method declines
    (``DesignError``, or a system class it does not support: those jobs are recorded as
    ``failed``, which is expected)."""
    from ..errors import DesignError
    from ..estimators import make_estimator

    for mod in spec.imports:
        importlib.import_module(mod)
    declined: list[str] = []
    seen: set[str] = set()
    for job in spec.jobs():
        key = job.design_key()
        if key in seen:
            continue
        seen.add(key)
        sc = cached_scenario(job.scenario, job.scenario_options)
        try:
            make_estimator(job.method, sc.system, x0=sc.x0, **job.options)
        except DesignError as exc:
            declined.append(f"{job.method} {job.options or ''} on {job.scenario}: {exc}")
        except IvobsError as exc:
            if not job.options or "support" in str(exc):
                declined.append(f"{job.method} on {job.scenario}: {exc}")
                continue
            raise IvobsError(
                f"{spec.source}: options.{job.method} = {job.options} (scenario "
                f"{job.scenario}): {exc}"
            ) from None
    return declined
