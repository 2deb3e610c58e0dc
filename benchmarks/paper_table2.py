"""The paper's Table II (Tolksdorf et al., IEEE IV 2023), for side-by-side comparison.

``PAPER[(method, uncertainty, epsilon)] = (e_acc, d_min)``; d_min = 3.0 in the paper means $> 3$.
"""

from __future__ import annotations

TOLERANCES = (0.0, 500.0, 1000.0, 1500.0, 2000.0, 2500.0)
_RMPC = {
    "low": [(53.5, 9.1)] * 6,
    "medium": [(72.3, 14.7), (72.2, 14.7), (72.5, 14.7), (71.7, 14.7), (70.9, 14.7), (71.2, 14.7)],
    "high": [(98.7, 20.3)] * 4 + [(98.8, 20.3), (98.7, 20.3)],
}
_SMPC = {
    "low": [(40.3, 3.3), (39.5, 3.6), (39.3, 3.5), (39.2, 3.5), (39.3, 3.5), (39.2, 3.5)],
    "medium": [(47.5, 6.9), (44.9, 5.0), (43.0, 4.6), (42.4, 3.5), (40.0, 3.5), (39.5, 3.4)],
    "high": [(64.2, 10.5), (54.7, 7.9), (48.0, 7.0), (53.0, 4.8), (39.8, 3.4), (35.7, 3.5)],
}
PAPER: dict[tuple[str, str, float], tuple[float, float]] = {
    (method, level, eps): values[i]
    for method, table in (("RMPC", _RMPC), ("SMPC", _SMPC))
    for level, values in table.items()
    for i, eps in enumerate(TOLERANCES)
}
