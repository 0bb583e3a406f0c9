"""Which recording a dataset reads (DatasetBuilder.recording): declared by the loaders, no data files needed."""

from __future__ import annotations

import os

import pytest

from locbench.registry import DATASETS, dataset_recording


def test_the_intel_loader_and_the_radish_intel_site_read_one_recording() -> None:
    assert dataset_recording("intel") == dataset_recording("radish[site=intel]") == "intel"
    assert dataset_recording("radish[site=aces]") == "radish[site=aces]"
    assert dataset_recording("radish[site=aces]") != dataset_recording("radish[site=freiburg-079]")


def test_a_recording_is_named_by_the_parameters_that_choose_it_not_those_that_window_it() -> None:
    assert dataset_recording("mrclam") == "mrclam[dataset=6,robot=1]"
    assert dataset_recording("mrclam[robot=2]") != dataset_recording("mrclam")
    assert dataset_recording("radish[site=intel,max_scans=100]") == dataset_recording("radish[site=intel]")
    assert dataset_recording("intel[map_resolution_m=0.1]") == dataset_recording("intel")
    assert dataset_recording("plaza[run=2]") == "plaza[run=2]"
    assert dataset_recording("librsf") == "librsf[set=indoor_uwb]"


def test_a_users_file_is_its_absolute_path() -> None:
    here = os.path.realpath("log")
    assert dataset_recording("textlog[path=log]") == f"file {here}"
    assert dataset_recording("rosbag[path=log,map=m.yaml]") == f"file {here}"


@pytest.mark.parametrize("ident", ["room", "office", "tiny_line", "tiny_circle", "scan_grid", "lap", "line_room"])
def test_synthetic_worlds_read_no_recording(ident: str) -> None:
    assert DATASETS.load(ident).recording(DATASETS.load(ident).Params()) is None
    assert dataset_recording(f"{ident}") is None
