"""Mesh data to NumPy: ``foreach_get`` into arrays, and the face attributes the opal tools share.

Blender's collections copy out in one call with ``foreach_get`` (no Python loop per vertex or
face); the exporter (``export.meshes``) and the opal tools (``opal.attributes``) both read meshes
this way. The two per-face attributes below are the contract between them: the opal tools write
them, the exporter reads them when a material's grating direction is 'Face Attribute'.
"""

from __future__ import annotations

import numpy as np

__all__ = ["GRATING_ATTRIBUTE", "PERIOD_ATTRIBUTE", "foreach", "attribute_ok"]

#: Per-face grating direction (FLOAT_VECTOR, object space) the opal tools write.
GRATING_ATTRIBUTE = "opal_grating_direction"
#: Per-face grating period (FLOAT, nm) the opal tools write: overrides the material's period on
#: grating faces (0 or less: the material's).
PERIOD_ATTRIBUTE = "opal_grating_period"


def foreach(coll, attr: str, n: int, dtype, width: int = 1) -> np.ndarray:
    """``attr`` of the ``n`` items of ``coll`` as an (n,) array, or (n, width) when width > 1."""
    a = np.empty(n * width, dtype)
    if n:
        coll.foreach_get(attr, a)
    return a.reshape(n, width) if width > 1 else a


def attribute_ok(attr, data_type: str, domain: str = "FACE") -> bool:
    """Whether the mesh attribute ``attr`` exists with this data type and domain."""
    return attr is not None and attr.data_type == data_type and attr.domain == domain
