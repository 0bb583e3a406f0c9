"""The ``--scheduler`` value: an address, or a dask scheduler file that is waited for and read."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest

from locbench.core.errors import ConfigError
from locbench.run.executors import scheduler_address, scheduler_from_file


def test_an_address_is_checked_as_written() -> None:
    assert scheduler_address("tcp://127.0.0.1:8786") == "tcp://127.0.0.1:8786"
    with pytest.raises(ConfigError, match="port"):
        scheduler_address("tcp://127.0.0.1:99999")


def test_a_scheduler_file_gives_its_address(tmp_path: Path) -> None:
    f = tmp_path / "scheduler.json"
    f.write_text(json.dumps({"type": "Scheduler", "address": "tcp://10.0.0.2:40123"}), encoding="utf-8")
    assert scheduler_address(str(f)) == "tcp://10.0.0.2:40123"


def test_a_file_written_while_waiting_is_read(tmp_path: Path) -> None:
    f = tmp_path / "scheduler.json"
    ready = threading.Event()

    def write() -> None:
        ready.wait()
        f.write_text(json.dumps({"address": "tcp://127.0.0.1:1234"}), encoding="utf-8")

    writer = threading.Thread(target=write)
    writer.start()
    ready.set()  # the writer may run before or during the wait: both must give the address
    try:
        assert scheduler_from_file(str(f), timeout_s=300.0) == "tcp://127.0.0.1:1234"
    finally:
        writer.join()


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (None, "no scheduler file after 0.2 s \\(it does not exist\\)"),
        ("{not json", "no scheduler file after 0.2 s \\(it is not JSON"),
        (json.dumps({"type": "Scheduler"}), "field 'address' missing or not a string"),
        (json.dumps({"address": "http://h:8787"}), "dashboard"),
    ],
)
def test_a_bad_scheduler_file_names_the_file_and_the_problem(
    tmp_path: Path, content: str | None, expected: str
) -> None:
    f = tmp_path / "scheduler.json"
    if content is not None:
        f.write_text(content, encoding="utf-8")
    with pytest.raises(ConfigError, match=expected) as info:
        scheduler_from_file(str(f), timeout_s=0.2)
    assert str(f) in str(info.value) or "dashboard" in expected
