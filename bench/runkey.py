"""What of a filter's or dataset's config enters the run key: the runner's policy, declared by the configs.

A config field added after runs were stored may carry :data:`RUN_KEY_OMIT_IF_DEFAULT` as its dataclass field
metadata: while it holds its default (which must reproduce the earlier behaviour exactly), the run key leaves
it out, so adding the field does not invalidate the stored runs.
"""

from __future__ import annotations

import dataclasses
from types import MappingProxyType
from typing import Any

from locbench.spec import params_to_dict

#: Field metadata of config fields added after runs were stored (module docstring).
RUN_KEY_OMIT_IF_DEFAULT: MappingProxyType[str, Any] = MappingProxyType({"run_key_omit_if_default": True})


def key_params(params: Any) -> dict[str, Any]:
    """A config as hashed into the run key: every field, less those marked omit-if-default at their default."""
    out = params_to_dict(params)
    for f in dataclasses.fields(params):
        if f.metadata.get("run_key_omit_if_default") and getattr(params, f.name) == f.default:
            out.pop(f.name, None)
    return out
