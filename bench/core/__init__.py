"""The ground layer: events, geometry, filter specs, seeding, run keys, tunable fields, limits and errors.

Everything else in locbench may import these modules; they import nothing of locbench above them.
"""
