"""Held-out two-object scenes (benchmarks.heldout): the generator, and the RMPC and the SMPC at
epsilon = 0 never colliding on scenes they were not tuned on."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import heldout


def test_scenes_are_reproducible_prefixes_with_two_crossing_objects():
    scenes = heldout.make_scenes(6, seed=3)
    assert scenes[:4] == heldout.make_scenes(4, seed=3)
    assert scenes != heldout.make_scenes(6, seed=4)
    for scene in scenes:
        sc = scene.scenario()
        assert len(sc.objects) == 2 and sc.risk_tolerance == 0.0
        ego = sc.ego.start
        for obj in sc.objects:
            # far from the ego (the first step is feasible), 1-4 m/s
            assert np.hypot(obj.start.x - ego.x, obj.start.y - ego.y) > 5.0 and 1.0 <= obj.speed <= 4.0
    with pytest.raises(ValueError, match="count"):
        heldout.make_scenes(-1)


def _assert_safe(rows):
    for row in rows:
        assert not row["collision"], row
        assert row["d_min"] > 2.0, row  # r_e + r_o = 2 m


def test_rmpc_and_smpc_at_zero_never_collide_on_a_few_held_out_scenes(tmp_path):
    rows = heldout.main(["--scenes", "3", "--workers", "1", "--out", str(tmp_path)])
    assert len(rows) == 6
    _assert_safe(rows)
    assert (tmp_path / "heldout.md").read_text().startswith("`python -m benchmarks.heldout")


@pytest.mark.slow
def test_rmpc_and_smpc_at_zero_never_collide_on_forty_held_out_scenes(tmp_path):
    _assert_safe(heldout.main(["--scenes", "40", "--workers", "1", "--out", str(tmp_path)]))
