"""The batched PCG64 draws exactly what each numpy Generator draws, whichever way it is asked."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.utils import seeding

from risk_env.envs.pcg64 import MAX_DRAWS, GeneratorBatch, PCG64Batch


def _generators(seeds: list[int | None]) -> list[np.random.Generator]:
    return [seeding.np_random(seed)[0] for seed in seeds]


def test_batch_draws_equal_each_generators_draws_under_masks() -> None:
    seeds = [*range(40), 2**63 - 1, None, None]
    batch, refs = PCG64Batch(len(seeds)), _generators(seeds)
    for i, g in enumerate(refs):
        batch.load(i, g)
        refs[i] = np.random.Generator(np.random.PCG64())
        refs[i].bit_generator.state = g.bit_generator.state  # an independent copy
    rng = np.random.default_rng(0)
    for count, share in [(3, 1.0), (8, 0.1), (1, 0.6), (MAX_DRAWS, 0.9), (2, 0.0), (3, None)]:
        mask = None if share is None else rng.random(len(seeds)) < share
        draws = batch.random(count, mask)
        assert draws.shape == (len(seeds), count)
        for i in range(len(seeds)) if mask is None else np.flatnonzero(mask):
            np.testing.assert_array_equal(draws[i], refs[i].random(count))  # bit for bit
        index = np.flatnonzero(rng.random(len(seeds)) < 0.2)  # a few generators alone
        np.testing.assert_array_equal(batch.random_at(count, index), [refs[i].random(count) for i in index])
    last = batch.random(1)  # the generators off the masks did not advance either
    assert all(last[i, 0] == g.random() for i, g in enumerate(refs))


def test_store_and_load_hand_the_stream_over() -> None:
    (g,), (ref,) = _generators([5]), _generators([5])
    batch = PCG64Batch(1)
    batch.load(0, g)
    np.testing.assert_array_equal(batch.random(4)[0], ref.random(4))
    batch.store(0, g)
    assert g.random() == ref.random()  # the generator continues where the batch stopped
    g.normal(size=7), ref.normal(size=7)
    batch.load(0, g)
    np.testing.assert_array_equal(batch.random(2)[0], ref.random(2))


def test_bad_use_raises() -> None:
    batch = PCG64Batch(2)
    with pytest.raises(ValueError, match="count"):
        batch.random(MAX_DRAWS + 1)
    with pytest.raises(TypeError, match="PCG64"):
        batch.load(0, np.random.Generator(np.random.MT19937(0)))


@pytest.mark.parametrize("vectorized", [False, True])
def test_generator_batch_loop_and_vectorised_agree(vectorized: bool) -> None:
    gens = GeneratorBatch(6, vectorized=vectorized)
    refs = _generators(list(range(6)))
    for i in range(6):
        gens.seed(i, i)
    mask = np.array([True, False, True, True, False, True])
    draws = gens.random(3, mask)
    for i in np.flatnonzero(mask):
        np.testing.assert_array_equal(draws[i], refs[i].random(3))
    np.testing.assert_array_equal(gens.random_at(8, np.array([4, 0])), [refs[4].random(8), refs[0].random(8)])
    g = gens.borrow(1)  # a direct use in between (Monte Carlo draws)
    np.testing.assert_array_equal(g.random(5), refs[1].random(5))
    gens.give_back(1)
    np.testing.assert_array_equal(gens.random(8)[1], refs[1].random(8))
