"""The registry of experiments, source reports and their claims, which the report reads through one hook.

The modules of :mod:`locbench.claims` register, at import:

- :class:`Source`: a source report, cited by title and authors;
- :class:`Experiment`: a dataset id with its title and role in the report (a summary dataset with an
  accuracy-runtime figure, a per-experiment section, variants folded into one table);
- :class:`Claim`: one checkable claim of a source report: a function from the tidy metrics rows
  (``dataset, filter, seed, metric, value``) of the experiment it concerns to a :class:`ClaimResult`;
- report sections (:func:`register_section`): extra tables and figures of an experiment, built as
  :mod:`locbench.present.docfmt` blocks.

The claims package is imported by name on the first query (:func:`_load`), so the report depends on this module,
not on the claims (an import-linter contract in ``pyproject.toml``).
"""

from __future__ import annotations

import importlib
import logging
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, NamedTuple

import pandas as pd

from locbench.core.spec import Spec
from locbench.suites import Suite

if TYPE_CHECKING:
    from locbench.present.docfmt import Block

log = logging.getLogger(__name__)

#: The package whose modules register the claims, experiments and sections.
CLAIMS_PACKAGE = "locbench.claims"

Verdict = Literal["reproduced", "not reproduced", "not evaluated"]
VERDICTS: tuple[Verdict, ...] = ("reproduced", "not reproduced", "not evaluated")


class ClaimResult(NamedTuple):
    """The verdict of one claim and the measured values behind it, as text; a claim that compares two filters
    or settings also names its test, the number of runs and the p-value (``test``, see :func:`test_text`)."""

    verdict: Verdict
    measured: str
    test: str = ""


@dataclass(frozen=True)
class Source:
    """A source report, cited by its title and authors as printed at its head."""

    key: str
    title: str
    authors: str

    @property
    def citation(self) -> str:
        return f"*{self.title}* ({self.authors})"


@dataclass(frozen=True)
class Experiment:
    """A dataset id's place in the report.

    Attributes
    ----------
    dataset : str
        The dataset id (``office``); its plain name is the experiment's base dataset.
    title : str
        Section heading.
    text : str
        One paragraph: what the experiment tests.
    source : Source or None
        The source report whose experiment it replays.
    summary : bool
        The experiment is a main comparison: a summary table and an accuracy-runtime figure.
    fold_variants : bool
        Its variants are shown folded (by its registered sections) instead of one table each.
    order : int
        Position among the experiment sections (and summary tables), ascending.
    suite : Suite
        The suite that makes the experiment's runs (keyword): it must run some variant of ``dataset``, so an
        experiment (and its claims) cannot point to runs no suite makes.
    """

    dataset: str
    title: str
    text: str = ""
    source: Source | None = None
    summary: bool = False
    fold_variants: bool = False
    order: int = 100
    suite: Suite = field(kw_only=True)

    def __post_init__(self) -> None:
        if not any(Spec.parse(d).ident == self.dataset for b in self.suite.blocks for d in b.datasets):
            raise ValueError(f"experiment {self.dataset!r}: suite {self.suite.name!r} runs no {self.dataset} dataset")


@dataclass(frozen=True)
class Claim:
    """One checkable claim of a source report.

    Attributes
    ----------
    id : str
        Stable short name (``room_odometry_grows``).
    dataset : str
        Dataset id the claim concerns (``room``): checked on the rows of its plain name, or with
        ``across_variants`` on the rows of every stored variant of that id.
    source : Source
        The source report.
    text : str
        The claim, with the concrete test we apply.
    reported : str
        The report's own numbers behind the claim.
    check : callable
        Tidy metrics rows of one dataset name -> :class:`ClaimResult`; with ``across_variants`` the rows
        of every stored variant of the dataset id (``scan_grid`` and ``scan_grid[mixed_commands=true]``).
    across_variants : bool
        Evaluated once over all variants of the dataset id (a sweep over a dataset parameter, recovery
        against kidnap distance) instead of once per dataset name.
    suite : Suite or None
        The suite that makes the runs the claim reads when it is not its experiment's (the consistency
        claims read the matched worlds of suite ``consistency``); :func:`claim_suite` resolves it.
    """

    id: str
    dataset: str
    source: Source
    text: str
    reported: str
    check: Callable[[pd.DataFrame], ClaimResult]
    across_variants: bool = False
    suite: Suite | None = None

    def evaluate(self, df: pd.DataFrame) -> ClaimResult:
        """Run the check; a check that cannot run (missing data) is "not evaluated", never an exception."""
        try:
            return self.check(df)
        except (KeyError, ValueError, IndexError) as exc:
            log.warning("claim %s could not be evaluated: %s", self.id, exc)
            return ClaimResult("not evaluated", f"could not be evaluated: {exc}")


# --- the registry: the modules of the claims package register their claims and report sections ---------

SectionFn = Callable[[pd.DataFrame, str], "list[Block]"]

_CLAIMS: list[Claim] = []
_SECTIONS: list[tuple[str, SectionFn]] = []
_EXPERIMENTS_BY_DATASET: dict[str, Experiment] = {}
_loaded = False


def register_experiment(experiment: Experiment) -> None:
    """Add an experiment (one per dataset id)."""
    if experiment.dataset in _EXPERIMENTS_BY_DATASET:
        raise ValueError(f"experiment {experiment.dataset!r} registered twice")
    _EXPERIMENTS_BY_DATASET[experiment.dataset] = experiment


def experiments() -> tuple[Experiment, ...]:
    """Every registered experiment, by ``order`` then dataset id."""
    _load()
    return tuple(sorted(_EXPERIMENTS_BY_DATASET.values(), key=lambda e: (e.order, e.dataset)))


def experiment_of(dataset_id: str) -> Experiment | None:
    """The experiment registered for a dataset id, if any."""
    _load()
    return _EXPERIMENTS_BY_DATASET.get(dataset_id)


def register(*claims: Claim) -> None:
    """Add claims (called at import time by the ``report_NNN`` modules of this package)."""
    known = {c.id for c in _CLAIMS}
    for c in claims:
        if c.id in known:
            raise ValueError(f"claim id {c.id!r} registered twice")
        _CLAIMS.append(c)
        known.add(c.id)


def register_section(dataset_id: str, fn: SectionFn) -> None:
    """Add an extra block of an experiment's report section.

    ``fn(rows, slug)`` gets the tidy metrics rows of every stored variant of the dataset id and a
    file-name slug for its figures (``<slug>_*``) and returns :mod:`locbench.present.docfmt` blocks (text,
    tables, plots); it does no I/O.
    """
    _SECTIONS.append((dataset_id, fn))


def _load() -> None:
    """Import every module of the claims package (:data:`CLAIMS_PACKAGE`) once (they register on import).

    By name, as the filter registry loads its classes: the report reads this registry and never imports the
    claims package itself.
    """
    global _loaded
    if _loaded:
        return
    _loaded = True
    pkg = importlib.import_module(CLAIMS_PACKAGE)
    for mod in sorted(m.name for m in pkgutil.iter_modules(pkg.__path__) if not m.name.startswith("_")):
        importlib.import_module(f"{CLAIMS_PACKAGE}.{mod}")


def all_claims() -> tuple[Claim, ...]:
    """Every registered claim: the protocol's own claims first, then by source report number, each in
    registration order (the claims modules are named by source, so their file order is not the report's)."""
    _load()
    return tuple(sorted(_CLAIMS, key=lambda c: (c.source.key.isdigit(), c.source.key)))


def claims_for(dataset_id: str, across_variants: bool = False) -> tuple[Claim, ...]:
    """The registered claims about a dataset id (per dataset name, or across its variants), in order."""
    return tuple(c for c in all_claims() if c.dataset == dataset_id and c.across_variants == across_variants)


def sections_for(dataset_id: str) -> tuple[SectionFn, ...]:
    """The extra report sections registered for a dataset id."""
    _load()
    return tuple(fn for ds, fn in _SECTIONS if ds == dataset_id)


def claim_suite(claim: Claim) -> Suite:
    """The suite whose runs a claim reads: its own, else its experiment's (a claim without either is an error)."""
    if claim.suite is not None:
        return claim.suite
    exp = experiment_of(claim.dataset)
    if exp is None:
        raise ValueError(f"claim {claim.id!r}: no experiment registered for dataset {claim.dataset!r} and no suite")
    return exp.suite
