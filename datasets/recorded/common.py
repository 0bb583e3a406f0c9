"""What every recorded-dataset builder shares: its files, where they are, and the skip when they are absent.

A recorded builder lists the files a parameter set needs (:meth:`RecordedDataset.files`); ``build`` asks
:meth:`RecordedDataset.paths` for their verified local paths (the local data folder ``$LOCBENCH_DATA``
first, then the download cache that ``locbench fetch`` fills) and parses them. The data does not depend on
the seed: every seed is the same recording (only a randomised filter's draws change with it).
"""

from __future__ import annotations

import abc
from pathlib import Path
from typing import Any, ClassVar

from locbench.core.spec import format_spec
from locbench.datasets.dataset import DatasetBuilder
from locbench.datasets.recorded.files import MissingDataFile, RemoteFile, locate


class RecordedDataset(DatasetBuilder):
    """Base of the recorded-dataset builders."""

    #: The sub-folder of the data root that holds this dataset (for messages and ``locbench list``).
    folder: ClassVar[str] = ""
    #: Parameters that say which recording a name means; the report always spells them out
    #: (``mrclam[dataset=6,robot=1]``, never a bare default).
    identity_keys: ClassVar[tuple[str, ...]] = ()
    #: What the reference trajectory is (the report groups recorded data by it): "motion capture", "GPS", "survey",
    #: "SLAM", "simulation" or "not stated"; a dataset whose sets differ says it in ``metadata["reference_kind"]``.
    reference_kind: ClassVar[str] = "not stated"
    nominal_duration_s: ClassVar[float] = 1000.0

    @classmethod
    @abc.abstractmethod
    def files(cls, params: Any) -> list[RemoteFile]:
        """Every file ``params`` needs, with checksums and official downloads where known."""

    @classmethod
    def recording(cls, params: Any) -> str | None:
        """This loader's id with the :attr:`identity_keys` of ``params`` (``plaza[run=1]``): the parameters that
        choose a recording, not those that window or grid it (:meth:`DatasetBuilder.recording`)."""
        return format_spec(cls.id, {k: getattr(params, k) for k in cls.identity_keys})

    @classmethod
    def data_unavailable(cls) -> str | None:
        """The first missing file of the default parameters, as a skip reason; None when all are present."""
        params = cls.Params()
        for spec in cls.files(params):
            try:
                locate(spec, verify=False)
            except MissingDataFile as exc:
                return f"unavailable: recorded data not found: {exc}"
        return None

    def paths(self, params: Any) -> dict[str, Path]:
        """Verified local path of each file of :meth:`files`, keyed by its ``relpath``."""
        return {spec.relpath: locate(spec) for spec in self.files(params)}

    def fetch(self, params: Any) -> list[str]:
        """Download what is missing (official downloads only) into the cache and verify it; every local path."""
        return [str(locate(spec, download=True)) for spec in self.files(params)]
