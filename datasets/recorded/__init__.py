"""Loaders for recorded datasets, one module per format (folder ``datasets/recorded/``).

Recorded data is read from ``$LOCBENCH_DATA/<dataset folder>``; see ../shared/datasets/SOURCES.md.

A loader (a module that defines a dataset builder: intel, radish, plaza, librsf, mrclam, lost_in_the_woods, rosbag,
textlog) imports no other loader; what two of them share sits in a shared module: ``common`` (the recorded builders'
base), ``files`` (finding, verifying and parsing files), ``plausibility`` (the flagging policy), ``carmen`` and
``tum`` (file formats), ``ros_map`` (map_server maps), ``scan_map`` (maps built from laser scans), ``reference``
(what is derived from a reference trajectory), ``jsonl_events`` and ``text_tables`` (the textlog format's events and
tables, also a bag's sidecars). tests/datasets/recorded/test_recorded_modules.py holds the rule.
"""
