r"""numpy's PCG64 generators stepped many at once: the batched env's draws without a Python loop.

Each copy of :class:`~risk_env.envs.vector_env.RiskCrossingVectorEnv` owns a ``np.random.Generator``
(PCG64, as Gymnasium seeds them), so that copy $i$ draws exactly what a single env seeded alike
would. Asking 1,024 generators for 3 numbers each costs ~0.6 us per generator in a Python loop.
:class:`PCG64Batch` holds their 128-bit states as ``uint64`` arrays and computes what
``Generator.random(k)`` returns for every generator at once, bit for bit
(``tests/test_pcg64.py``), in some 40 numpy calls whatever the batch.

PCG64 (O'Neill's PCG XSL RR 128/64, numpy's ``pcg64.h``): the state advances as
$s \leftarrow s M + \mathrm{inc} \pmod{2^{128}}$; a draw outputs
``rotr64(hi(s) ^ lo(s), hi(s) >> 58)`` of the new state; ``random()`` is its top 53 bits times
$2^{-53}$. $j$ draws ahead the state is $M^j s + \mathrm{inc}\, (M^{j-1} + \dots + 1)$, so every
draw of a call is one 128-bit multiply-add from the state before it.
"""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding

MULTIPLIER = (2549297995355413924 << 64) + 4865540595714422341
"""PCG64's 128-bit LCG multiplier M."""
MAX_DRAWS = 8
"""Most draws per generator in one :meth:`PCG64Batch.random` call."""
_MASK64 = (1 << 64) - 1
_MASK128 = (1 << 128) - 1
_LOW32 = np.uint64(0xFFFFFFFF)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2^-53


def _split(values: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """128-bit Python ints -> (high, low) ``uint64`` arrays."""
    return (
        np.array([v >> 64 for v in values], dtype=np.uint64),
        np.array([v & _MASK64 for v in values], dtype=np.uint64),
    )


# M^j and the sums 1 + M + ... + M^(j-1) for j = 1..MAX_DRAWS, as (MAX_DRAWS, 1) columns.
_POWERS = [pow(MULTIPLIER, j, 1 << 128) for j in range(1, MAX_DRAWS + 1)]
_SUMS = [sum(pow(MULTIPLIER, i, 1 << 128) for i in range(j)) & _MASK128 for j in range(1, MAX_DRAWS + 1)]
_POWER_HI, _POWER_LO = (a[:, None] for a in _split(_POWERS))


def _mul_high(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The high 64 bits of the 128-bit products ``a b`` (``uint64``, broadcast)."""
    a0, a1 = a & _LOW32, a >> np.uint64(32)
    b0, b1 = b & _LOW32, b >> np.uint64(32)
    p01, p10 = a0 * b1, a1 * b0
    mid = (a0 * b0) >> np.uint64(32)
    mid += p01 & _LOW32
    mid += p10 & _LOW32
    high = a1 * b1
    high += p01 >> np.uint64(32)
    high += p10 >> np.uint64(32)
    high += mid >> np.uint64(32)
    return high


def _check_count(count: int) -> None:
    if not 1 <= count <= MAX_DRAWS:
        raise ValueError(f"count must be in [1, {MAX_DRAWS}], got {count}")


class PCG64Batch:
    """The states of ``size`` PCG64 generators, advanced together.

    :meth:`load` copies a generator's state in, :meth:`store` writes it back (before the
    generator itself is used again); in between, :meth:`random` draws for the generators of a
    mask as each would.
    """

    def __init__(self, size: int) -> None:
        self.high = np.zeros(size, dtype=np.uint64)
        self.low = np.zeros(size, dtype=np.uint64)
        # inc (1 + M + ... + M^(j-1)) for j = 1..MAX_DRAWS, per generator: (MAX_DRAWS, size)
        self._add_high = np.zeros((MAX_DRAWS, size), dtype=np.uint64)
        self._add_low = np.zeros((MAX_DRAWS, size), dtype=np.uint64)
        self._inc = [0] * size

    def load(self, index: int, generator: np.random.Generator) -> None:
        """Take generator ``index``'s state from ``generator`` (a PCG64 ``Generator``)."""
        state = generator.bit_generator.state
        if state["bit_generator"] != "PCG64":
            raise TypeError(f"PCG64Batch steps PCG64 generators, got {state['bit_generator']}")
        s, inc = state["state"]["state"], state["state"]["inc"]
        self.high[index], self.low[index] = s >> 64, s & _MASK64
        if inc != self._inc[index]:
            self._inc[index] = inc
            high, low = _split([(inc * c) & _MASK128 for c in _SUMS])
            self._add_high[:, index], self._add_low[:, index] = high, low

    def store(self, index: int, generator: np.random.Generator) -> None:
        """Give ``generator`` the state of generator ``index`` (as :meth:`load` took it, advanced)."""
        state = generator.bit_generator.state
        state["state"]["state"] = (int(self.high[index]) << 64) | int(self.low[index])
        generator.bit_generator.state = state

    def random(self, count: int, mask: np.ndarray | None = None) -> np.ndarray:
        """``(size, count)`` doubles on [0, 1): row i is what ``Generator.random(count)`` of
        generator i returns. Generators off ``mask`` (a ``(size,)`` bool array) do not advance,
        and their rows are to be ignored (every generator is computed: for masks of most)."""
        _check_count(count)
        high, low, out = self._advance(count, self.high, self.low, slice(None))
        if mask is None:
            self.high, self.low = high, low
        else:
            np.copyto(self.high, high, where=mask)
            np.copyto(self.low, low, where=mask)
        return out.T

    def random_at(self, count: int, index: np.ndarray) -> np.ndarray:
        """``(len(index), count)``: the draws of the generators ``index`` alone (for a few)."""
        _check_count(count)
        high, low, out = self._advance(count, self.high[index], self.low[index], index)
        self.high[index], self.low[index] = high, low
        return out.T

    def _advance(
        self, count: int, s_hi: np.ndarray, s_lo: np.ndarray, columns: slice | np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """States ``count`` draws on from ``(s_hi, s_lo)`` (of the generators ``columns``) and the
        draws ``(count, len)``."""
        a_hi, a_lo = _POWER_HI[:count], _POWER_LO[:count]
        add_hi, add_lo = self._add_high[:count, columns], self._add_low[:count, columns]
        # s_j = M^j s + c_j, for j = 1..count at once: rows j, columns generators
        low = s_lo * a_lo
        high = _mul_high(s_lo, a_lo)
        high += s_hi * a_lo
        high += s_lo * a_hi
        low += add_lo
        high += add_hi
        high += low < add_lo  # the carry of the low words' sum
        # XSL RR output of each new state, then its top 53 bits as a double
        rot = high >> np.uint64(58)
        x = high ^ low
        out = x >> rot
        out |= x << ((np.uint64(64) - rot) & np.uint64(63))
        out >>= np.uint64(11)
        return high[-1].copy(), low[-1].copy(), out * _TO_UNIT


VECTORIZED_MIN = 128
"""From this many generators on, :class:`GeneratorBatch` draws through :class:`PCG64Batch`
(~50 us whatever the batch) rather than a loop over the generators (~0.7 us each)."""


class GeneratorBatch:
    """One numpy ``Generator`` per copy of a batched env, seeded as Gymnasium seeds a single env,
    and their draws: a loop for a few, :class:`PCG64Batch` for many (the same numbers)."""

    def __init__(self, size: int, vectorized: bool | None = None) -> None:
        self.size = size
        self.generators: list[np.random.Generator | None] = [None] * size
        vectorized = size >= VECTORIZED_MIN if vectorized is None else vectorized
        self._batch = PCG64Batch(size) if vectorized else None
        self._buffers: dict[int, tuple[np.ndarray, list[np.ndarray]]] = {}

    def seed(self, index: int, seed: int | None) -> None:
        """A new generator for copy ``index`` (``seed=None``: fresh entropy)."""
        self.generators[index], _ = seeding.np_random(seed)
        if self._batch is not None:
            self._batch.load(index, self.generators[index])

    def random(self, count: int, mask: np.ndarray | None = None) -> np.ndarray:
        """``(size, count)`` doubles on [0, 1): row i is ``generators[i].random(count)`` for the
        copies of ``mask`` (all by default); the other rows are to be ignored."""
        if self._batch is not None:
            return self._batch.random(count, mask)
        if count not in self._buffers:
            buffer = np.zeros((self.size, count))
            self._buffers[count] = buffer, list(buffer)
        buffer, rows = self._buffers[count]
        if mask is None:
            for generator, row in zip(self.generators, rows, strict=True):
                generator.random(out=row)
        else:
            for i in np.flatnonzero(mask).tolist():
                self.generators[i].random(out=rows[i])
        return buffer

    def random_at(self, count: int, index: np.ndarray) -> np.ndarray:
        """``(len(index), count)``: :meth:`random` of the generators ``index`` alone."""
        if self._batch is not None:
            return self._batch.random_at(count, index)
        out = np.empty((len(index), count))
        for row, i in zip(out, index.tolist(), strict=True):
            self.generators[i].random(out=row)
        return out

    def borrow(self, index: int) -> np.random.Generator:
        """Copy ``index``'s generator, up to date, for a direct use; hand it back with
        :meth:`give_back` before the next :meth:`random`."""
        if self._batch is not None:
            self._batch.store(index, self.generators[index])
        return self.generators[index]

    def give_back(self, index: int) -> None:
        """The end of a :meth:`borrow`: later draws continue from the generator's state."""
        if self._batch is not None:
            self._batch.load(index, self.generators[index])
