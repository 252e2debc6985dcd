"""Meshes of core/scene/primitives.py: closed, consistently wound outwards, with the stated proportions."""

from __future__ import annotations

import numpy as np

from opal_diffraction.core.scene.primitives import round_brilliant


def test_round_brilliant_is_closed_outward_and_has_tolkowsky_proportions():
    v, t = round_brilliant((0.1, 0.2, 0.3), 2.0)
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    # closed and consistently oriented: every directed edge once, its reverse once
    assert len(np.unique(directed, axis=0)) == len(directed)
    rev = {tuple(e) for e in directed[:, ::-1]}
    assert rev == {tuple(e) for e in directed}
    rel = v - (0.1, 0.2, 0.3)
    volume = np.sum(np.einsum("ij,ij->i", rel[t[:, 0]], np.cross(rel[t[:, 1]], rel[t[:, 2]]))) / 6
    assert volume > 0  # outward normals
    # crown height above the girdle = (R - R_table) tan 34.5 deg; pavilion depth = R tan 40.75 deg
    top, bottom = rel[:, 2].max(), rel[:, 2].min()
    hg = 0.02
    np.testing.assert_allclose(top - hg, (1.0 - 0.57) * np.tan(np.radians(34.5)), rtol=1e-12)
    np.testing.assert_allclose(-bottom - hg, np.tan(np.radians(40.75)), rtol=1e-12)
    assert len(t) == 80
