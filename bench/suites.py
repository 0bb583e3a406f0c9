"""Named suites: blocks of filters x datasets x seeds.

``default`` is the main comparison (every registered filter on ``room`` and ``office``, a few
minutes on 2 cores); each source report's experiment, the kidnap protocol and global localization are
suites of their own; ``all`` is their union, what ``nox -s bench`` runs and ``results/summary`` holds.

A suite is also readable from a TOML file (``locbench run --suite my_suite.toml``), one block::

    filters = ["odometry", "ekf_landmarks[association=nearest]"]
    datasets = ["room", "office[kidnap_m=1]"]
    seeds = 10

"Every filter" is read from the registry: the package's filters that declare themselves compared
(``Filter.compared``), in their declared ``order``, each with the configurations its class declares for the
main comparison and the kidnap protocol (:func:`all_filters`, :func:`comparison_filters`, :func:`kidnap_filters`).
The suites are made on first use (:data:`SUITES`), so importing this module imports no filter.
"""

from __future__ import annotations

import os
import stat
import tomllib
from collections.abc import Iterator, MutableMapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from locbench.core.errors import ConfigError, UnknownIdError, one_line, shown
from locbench.core.limits import check_input_file
from locbench.core.spec import MAX_CONFIGS, Spec, expand_grid, format_spec, grid_size
from locbench.datasets.splits import RADISH_SITES
from locbench.registry import FILTERS

#: Most seeds a block may run (``--max-seeds`` raises it; a suite file's ``seeds`` too).
MAX_SEEDS = 10_000
#: Largest suite file read, bytes (a suite of a few hundred specs is a few kB).
MAX_SUITE_BYTES = 1 << 20


@dataclass(frozen=True)
class Block:
    """Every filter on every dataset for seeds 0 .. seeds-1.

    Grid specs (``pf[particles=100|300]``, :func:`locbench.core.spec.expand_grid`) are expanded when the block is
    made, so ``filters`` and ``datasets`` hold one spec per run configuration. The block's size (filter
    configurations x dataset configurations) is counted before anything is expanded and refused above
    ``max_configs``, and ``seeds`` above ``max_seeds``.
    """

    filters: tuple[str, ...]
    datasets: tuple[str, ...]
    seeds: int
    max_configs: int = field(default=MAX_CONFIGS, compare=False, repr=False)
    max_seeds: int = field(default=MAX_SEEDS, compare=False, repr=False)

    def __post_init__(self) -> None:
        check_seeds(self.seeds, self.max_seeds, "seeds")
        nf = sum(grid_size(f) for f in self.filters)
        nd = sum(grid_size(d) for d in self.datasets)
        if nf * nd > self.max_configs:
            raise ConfigError(
                f"{nf} filter x {nd} dataset configurations = {nf * nd}, more than the limit of "
                f"{self.max_configs} (--max-configs raises it)"
            )
        object.__setattr__(self, "filters", tuple(x for f in self.filters for x in expand_grid(f, None)))
        object.__setattr__(self, "datasets", tuple(x for d in self.datasets for x in expand_grid(d, None)))

    @property
    def runs(self) -> int:
        return len(self.filters) * len(self.datasets) * self.seeds


def check_seeds(seeds: object, limit: int, where: str) -> int:
    """``seeds`` when it is an integer 1 .. ``limit``; a one-line :class:`ConfigError` naming ``where`` otherwise."""
    if not isinstance(seeds, int) or isinstance(seeds, bool) or seeds < 1:
        raise ConfigError(f"{where} must be a positive integer, got {shown(seeds)}")
    if seeds > limit:
        raise ConfigError(f"{where}: {seeds} seeds, more than the limit of {limit} (--max-seeds raises it)")
    return seeds


@dataclass(frozen=True)
class Suite:
    """A named list of blocks."""

    name: str
    blocks: tuple[Block, ...]
    description: str = ""

    @property
    def runs(self) -> int:
        return sum(b.runs for b in self.blocks)

    def with_seeds(self, seeds: int, max_seeds: int = MAX_SEEDS) -> Suite:
        """The same suite with every block's seed count replaced (``--seeds``)."""
        blocks = tuple(Block(b.filters, b.datasets, seeds, b.max_configs, max_seeds) for b in self.blocks)
        return Suite(self.name, blocks, self.description)


# --- every filter, from the registry ---------------------------------------------------------------------------


def _compared() -> list[tuple[str, Any]]:
    """The package's filters that the comparing suites run (``Filter.compared``), in declared order, each with its
    class; None for one whose module does not import here (an optional dependency missing), which is run with its
    default configuration only."""
    out: list[tuple[str, Any]] = []
    for fid in FILTERS.package_ids():
        cls = FILTERS.class_of(fid)
        if cls is None or cls.compared:
            out.append((fid, cls))
    return out


def all_filters() -> tuple[str, ...]:
    """Every compared filter with its default config, in declared order: the rows of every comparison."""
    return tuple(fid for fid, _ in _compared())


def comparison_filters() -> tuple[str, ...]:
    """The main comparison's configurations: :func:`all_filters`, then the configurations each filter declares for
    it (``Filter.comparison_configurations``), in the same order."""
    compared = _compared()
    extra = [
        format_spec(fid, dict(p)) for fid, cls in compared if cls is not None for p in cls.comparison_configurations
    ]
    return (*(fid for fid, _ in compared), *extra)


def kidnap_filters() -> tuple[str, ...]:
    """Each compared filter with its own source's kidnap policy (``Filter.kidnap_configurations``, else its kidnap
    configuration ``Filter.kidnap_params``): 000's inflation rule is built into ekf_icp, pf switches augmented MCL
    on (003's PF, the default, only resamples), the others have none."""
    out: list[str] = []
    for fid, cls in _compared():
        configs = ({},) if cls is None else cls.kidnap_configurations
        if configs is None:
            configs = (cls.kidnap_params,)
        out += [format_spec(fid, dict(p)) for p in configs]
    return tuple(out)


if TYPE_CHECKING:
    #: :func:`all_filters` and :func:`kidnap_filters`, read when first asked for (module ``__getattr__``).
    ALL_FILTERS: tuple[str, ...]
    KIDNAP_FILTERS: tuple[str, ...]


def __getattr__(name: str) -> tuple[str, ...]:
    """``ALL_FILTERS`` (:func:`all_filters`) and ``KIDNAP_FILTERS`` (:func:`kidnap_filters`), read from the
    registry when asked for, not when this module is imported."""
    if name == "ALL_FILTERS":
        return all_filters()
    if name == "KIDNAP_FILTERS":
        return kidnap_filters()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: The kidnap distances of suite ``kidnap``, m.
KIDNAP_DISTANCES_M = (0.5, 1, 2, 4)
#: The seeds of suite ``kidnap`` at each distance: 40 kidnaps per filter and world over the four distances. The
#: recovery policies mostly differ by whole runs (0 of 20 against 20 of 20 at 20 seeds); 20 seeds cost a third of
#: the bench's run time (``pf``'s three policies on ``office`` nearly half of it), so a rate in between carries a
#: 95 % Wilson interval of about +-0.3 at 10 (docs/protocols.md, Kidnap recovery; ``--seeds 20`` runs more).
KIDNAP_SEEDS = 10

#: The recorded datasets of the recorded-data table (MRCLAM Dataset 6, all five robots; Dataset 6 is the default).
RECORDED_LANDMARK_DATASETS = (
    *(f"mrclam[robot={r}]" for r in range(1, 6)),
    "lost_in_the_woods",
    "plaza[run=1]",
    "plaza[run=2]",
    # libRSF: the real Labyrinth UWB set and the two simulated worlds under each range-noise type, with the
    # generated Gaussian reference of the robustness table
    "librsf[set=indoor_uwb]",
    *(
        f"librsf[set={w},noise={n}]"
        for w in ("m3500", "w3500")
        for n in ("heavy-tailed", "multimodal", "skewed", "gaussian")
    ),
)
RECORDED_LASER_DATASETS = ("intel", *(f"radish[site={s}]" for s in RADISH_SITES))

#: The model-matched worlds of the consistency suite (the simulator's noise is the nominal noise).
MATCHED_DATASETS = ("room[matched=true]", "office[matched=true]")

_LG_PATHS = ("circle", "star", "pentagon", "random")
_LG_LAYOUTS = ("1", "2", "3", "4", "8")


#: The initial heading errors of suite ``heading`` (deg), UKF-M's question on our worlds; each with the matching
#: initial heading standard deviation (``initial_heading_error_deg``; 0 is the world as shipped).
HEADING_ERRORS_DEG = (0, 15, 45, 90)
#: The error the claims judge (UKF-M's).
HEADING_CLAIM_DEG = 45
#: The seeds of suite ``heading`` at :data:`HEADING_CLAIM_DEG`, the runs its claims' paired tests read: every
#: filter on the same 50 (docs/protocols.md).
HEADING_SEEDS = 50
#: The seeds at the other wrong headings (15 and 90 deg), the shape of the curve around the claim's point: the main
#: comparison's 20, every filter on the same ones (50 there cost a sixth of the bench and no claim reads them).
HEADING_CURVE_SEEDS = 20
#: The seeds at 0 deg: the plain worlds are the main comparison's, whose seeds every filter shares (more seeds there
#: for four filters would leave the main table's rows on unequal seeds).
HEADING_PLAIN_SEEDS = 20
#: The filters of suite ``heading``: the EKF, the UKF and the invariant EKF on the same models, and pf as in the main
#: comparison (its default 1000 particles; shown, not judged).
HEADING_FILTERS = ("ekf_landmarks", "ukf_landmarks", "iekf_landmarks")
HEADING_PF = ("pf",)


def heading_datasets(base: str, errors: tuple[int, ...] = HEADING_ERRORS_DEG) -> tuple[str, ...]:
    """``base`` with each initial heading error of ``errors`` (the plain name at 0)."""
    return tuple(base if e == 0 else f"{base}[initial_heading_error_deg={e}]" for e in errors)


def _heading_blocks() -> tuple[Block, ...]:
    """Suite ``heading``: the four filters on room and office at the claims' error on :data:`HEADING_SEEDS` seeds,
    at the other wrong headings on :data:`HEADING_CURVE_SEEDS`, and at 0 deg (the plain worlds, the main
    comparison's) on its :data:`HEADING_PLAIN_SEEDS`."""
    claim = (HEADING_CLAIM_DEG,)
    curve = tuple(e for e in HEADING_ERRORS_DEG if e not in (0, HEADING_CLAIM_DEG))
    filters = (*HEADING_FILTERS, *HEADING_PF)
    return (
        Block(filters, heading_datasets("room", claim) + heading_datasets("office", claim), HEADING_SEEDS),
        Block(filters, heading_datasets("room", curve) + heading_datasets("office", curve), HEADING_CURVE_SEEDS),
        Block(filters, ("room", "office"), HEADING_PLAIN_SEEDS),
    )


def _kidnap_datasets(base: str) -> tuple[str, ...]:
    return tuple(f"{base}[kidnap_m={d:g}]" for d in KIDNAP_DISTANCES_M)


_SUITES_IN_ALL = (
    "default",
    "lap",
    "line_room",
    "scan_grid",
    "landmark_geometry",
    "kidnap",
    "global",
    "recorded",
    "pareto",
    "heading",
)


def _make_suites() -> dict[str, Suite]:
    """Every named suite, ``all`` (the union of :data:`_SUITES_IN_ALL`) last; what :data:`SUITES` holds."""
    # long: the suites as one table, a literal per suite
    every = all_filters()
    suites = (
        Suite(
            "default",
            (Block(comparison_filters(), ("room", "office"), 20),),
            "the main comparison: every registered filter on report 003's room and the common office",
        ),
        Suite(
            "room",
            (
                Block(
                    ("odometry", "ekf_landmarks", "ekf_landmarks[association=nearest]", "pf", "gtsam_fls"),
                    ("room",),
                    20,
                ),
            ),
            "report 003's experiment: 20 runs through 5 waypoints",
        ),
        Suite(
            "lap",
            (
                Block(("odometry", "ekf_icp"), ("lap", "lap[people=0]"), 20),
                Block(("ekf_icp",), ("lap[kidnap_m=0.3]", "lap[kidnap_m=1]", "lap[kidnap_m=2]"), 10),
            ),
            "report 000's lap with people walking, and its small-kidnap claim",
        ),
        Suite(
            "line_room",
            (
                Block(
                    (
                        "odometry",
                        "ekf_lines[chi2_threshold=1.39]",
                        "ekf_lines[chi2_threshold=4.61]",
                        "ekf_lines",
                        "ekf_lines[chi2_threshold=13.82]",
                        "ekf_lines[reject_longer=false]",
                        # the gate sweep with the length check off too (report 002's claims hold for both settings)
                        "ekf_lines[chi2_threshold=1.39|4.61|13.82,reject_longer=false]",
                    ),
                    ("line_room", "line_room[laser_sigma_m=0.05]"),
                    5,
                ),
            ),
            "report 002's chi-square gate sweep, with the line-length check on and off",
        ),
        Suite(
            "scan_grid",
            (Block(("odometry", "kf_linear"), ("scan_grid", "scan_grid[mixed_commands=true]"), 10),),
            "report 004's translate-or-rotate commands against mixed commands",
        ),
        Suite(
            "landmark_geometry",
            (
                Block(
                    ("odometry", "ekf_landmarks", "pf", "gtsam_fls"),
                    tuple(f"landmark_geometry[landmarks={n},path={p}]" for p in _LG_PATHS for n in _LG_LAYOUTS),
                    5,
                ),
                Block(
                    ("odometry", "ekf_landmarks", "ekf_landmarks[use_pose_fixes=true]"),
                    (
                        "landmark_geometry[gps=true,initial_offset_m=2]",
                        "landmark_geometry[gps=true,initial_offset_m=2,landmarks=1]",
                    ),
                    5,
                ),
                Block(
                    ("odometry", "ekf_landmarks", "ekf_landmarks[association=nearest]"),
                    ("landmark_geometry[kidnap_m=1]", "landmark_geometry[kidnap_m=2]"),
                    5,
                ),
            ),
            "report 001's paths x landmark layouts, the GPS variant from a wrong start, and kidnaps",
        ),
        Suite(
            "kidnap",
            (Block(kidnap_filters(), _kidnap_datasets("room") + _kidnap_datasets("office"), KIDNAP_SEEDS),),
            "the kidnap protocol: every filter with its own recovery policy, D = 0.5, 1, 2, 4 m",
        ),
        Suite(
            "global",
            (
                Block(
                    ("pf[augmented=true,init=uniform,use_laser=true]", "pf[augmented=true,init=uniform]"),
                    ("office",),
                    10,
                ),
            ),
            "global localization: the particle filter from a uniform prior over free space",
        ),
        Suite(
            "recorded",
            (
                Block((*every, "pf[adaptive=kld]"), RECORDED_LANDMARK_DATASETS, 1),
                # pf's laser model is off by default (003's PF uses landmarks); Intel has only the laser.
                Block((*every, "pf[use_laser=true]"), RECORDED_LASER_DATASETS, 1),
            ),
            "every filter on the recorded datasets (skips where data or a map kind is missing): MRCLAM 6 robots 1-5, "
            "Lost in the Woods, Intel, CMU Plaza 1 and 2, the 11 Radish buildings, the 9 libRSF ranging sets",
        ),
        Suite(
            "consistency",
            (Block(every, MATCHED_DATASETS, 50),),
            "consistency on the model-matched worlds (simulator noise = the filters' nominal noise): every filter, "
            "50 seeds (run beside 'all' by nox -s bench)",
        ),
        Suite(
            "pareto",
            (
                Block(
                    (
                        "odometry",
                        "pf[particles=100|300|1000|3000]",
                        "ekf_icp[max_iterations=5|10|30|700]",
                        "gtsam_fls[lag_s=0.5|1|2|4]",
                        "ekf_landmarks[association=nearest,gate_probability=0.9|0.99|0.999|0.9999]",
                    ),
                    ("office",),
                    5,
                ),
            ),
            "accuracy against runtime: the main cost knob of each filter on office (pf particles, ekf_icp ICP "
            "iterations, gtsam_fls lag, ekf_landmarks' association gate)",
        ),
        Suite(
            "heading",
            _heading_blocks(),
            "a wrong initial heading (0, 15, 45, 90 deg, the belief's heading deviation matching it) on room and "
            "office: the EKF, the UKF, the invariant EKF and pf on 50 seeds (UKF-M's 2-D question)",
        ),
        # Run by locbench.run.tuning (locbench run --suite tuned), not as blocks: the tuned configurations that
        # locbench tune --suite committed to RESULTS/tuning, and their defaults, on the test data (docs/protocols.md,
        # Tuning).
        Suite(
            "tuned",
            (),
            "every tunable filter's tuned configuration (optuna TPE, the same budget each, tuned apart by 'locbench "
            "tune --suite' on train seeds of room and office and leave-one-robot-out on MRCLAM 6) beside its default "
            "on the test seeds 0-19 and on each held-out robot",
        ),
        Suite(
            "smoke",
            (
                Block(
                    ("odometry", "ekf_landmarks", "ekf_landmarks[association=nearest]"), ("tiny_line", "tiny_circle"), 2
                ),
            ),
            "seconds-long sanity run",
        ),
    )
    out = {s.name: s for s in suites}
    out["all"] = Suite(
        "all",
        tuple(b for name in _SUITES_IN_ALL for b in out[name].blocks),
        "every experiment: " + ", ".join(_SUITES_IN_ALL) + " (what nox -s bench runs and results/summary holds)",
    )
    return out


class _Suites(MutableMapping[str, Suite]):
    """The named suites, made on first use (:func:`_make_suites`): making them reads every filter class."""

    def __init__(self) -> None:
        self._made: dict[str, Suite] | None = None

    def _suites(self) -> dict[str, Suite]:
        if self._made is None:
            self._made = _make_suites()
        return self._made

    def __getitem__(self, name: str) -> Suite:
        return self._suites()[name]

    def __setitem__(self, name: str, suite: Suite) -> None:
        self._suites()[name] = suite

    def __delitem__(self, name: str) -> None:
        del self._suites()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._suites())

    def __len__(self) -> int:
        return len(self._suites())


#: Every named suite by name (made on first use).
SUITES: MutableMapping[str, Suite] = _Suites()


def get_suite(name: str, max_configs: int = MAX_CONFIGS, max_seeds: int = MAX_SEEDS) -> Suite:
    """A named suite, or a suite read from a ``.toml`` file path (or any path that exists)."""
    if name.endswith(".toml") or (name not in SUITES and os.path.lexists(name)):
        return load_suite_file(Path(name), max_configs, max_seeds)
    try:
        return SUITES[name]
    except KeyError:
        raise UnknownIdError(
            f"unknown suite {shown(name)}; valid: {', '.join(sorted(SUITES))} or a path to a .toml file"
        ) from None


def _read_suite_text(path: Path) -> str:
    """The text of a suite file: a regular file of at most :data:`MAX_SUITE_BYTES`, UTF-8 (one line otherwise).

    The file is looked at before it is opened (a FIFO would block the open, a device never end) and read with
    a bound (a file that grows meanwhile is still refused)."""
    check_input_file(path, "suite file", MAX_SUITE_BYTES)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise ConfigError(f"{path}: not a regular file; a suite file is a .toml file")
            data = f.read(MAX_SUITE_BYTES + 1)
    except PermissionError:
        raise ConfigError(f"{path}: permission denied reading the suite file") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the suite file ({exc.strerror})") from None
    if len(data) > MAX_SUITE_BYTES:
        raise ConfigError(f"{path}: more than {MAX_SUITE_BYTES} bytes; a suite file is at most that")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start}); a suite file is UTF-8 TOML") from None


def load_suite_file(path: Path, max_configs: int = MAX_CONFIGS, max_seeds: int = MAX_SEEDS) -> Suite:
    """Read a one-block suite from TOML; errors name the file and the field."""
    text = _read_suite_text(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None
    except RecursionError:
        raise ConfigError(f"{path}: not valid TOML (nested too deeply)") from None
    unknown = sorted(set(data) - {"filters", "datasets", "seeds", "description"})
    if unknown:
        names = one_line(", ".join(unknown), 200)
        raise ConfigError(f"{path}: unknown field(s) {names}; valid: filters, datasets, seeds, description")
    for key in ("filters", "datasets"):
        val = data.get(key)
        if not isinstance(val, list) or not val or not all(isinstance(v, str) for v in val):
            raise ConfigError(
                f"{path}: field '{key}' must be a non-empty list of spec strings like \"room[kidnap_m=2]\""
            )
    seeds = check_seeds(data.get("seeds", 1), max_seeds, f"{path}: field 'seeds'")
    block = Block(tuple(data["filters"]), tuple(data["datasets"]), seeds, max_configs, max_seeds)
    return Suite(path.stem, (block,), str(data.get("description", "")))


def suite_pairs(name: str) -> list[tuple[Spec, Spec]]:
    """The (filter, dataset) pairs a suite runs, grids expanded and names canonical, in suite order.

    Canonical means as stored: parameters at their default are dropped (``room[kidnap_m=0]`` is ``room``),
    so the pairs match the ``filter`` and ``dataset`` of stored runs (the report restricts itself to them).
    """
    from locbench.registry import resolve_dataset, resolve_filter

    pairs: dict[tuple[Spec, Spec], None] = {}
    for b in get_suite(name).blocks:
        fspecs = [resolve_filter(f).spec for f in b.filters]
        for d in b.datasets:
            dspec = resolve_dataset(d).spec
            for f in fspecs:
                pairs[(f, dspec)] = None
    return list(pairs)
