"""The exact risk's disc probability against an independent reference (nested adaptive quadrature
in the belief's frame, :mod:`benchmarks.exact_accuracy`) on random beliefs of any aspect ratio
(up to 1:1000), rotation, truncation and offset: within 1e-4, never below by more than 1e-5, on
every path (the env's numpy kernels, the generic form, the SMPC's CasADi form)."""

import numpy as np
import pytest

from benchmarks import exact_accuracy as acc

ABS = acc.ABS_TARGET
SHORT = acc.SHORT_TARGET


def check(beliefs: int, seed: int) -> None:
    cases = acc.random_beliefs(np.random.default_rng(seed), beliefs)
    ref = acc.references(cases)
    assert ref[:, 1].max() <= 1e-10  # the reference's two orders agree
    got = acc.estimates(cases)
    for name, p in got.items():
        err = p - ref[:, 0]
        assert np.abs(err).max() <= ABS, (name, np.abs(err).max())
        assert err.min() >= -SHORT, (name, err.min())
    # the SMPC's form stays at or above the env's value
    assert np.all(got["SMPC's CasADi form"] >= got["env, numpy batch"] - 1e-12)


def test_random_beliefs_cover_what_they_should():
    c = acc.random_beliefs(np.random.default_rng(0), 2000)
    ratio = np.maximum(c["sx"], c["sy"]) / np.minimum(c["sx"], c["sy"])
    assert np.mean(ratio == 1.0) > 0.1 and np.mean(ratio > 100) > 0.2 and ratio.max() > 900
    assert np.mean(c["sx"] > c["sy"]) > 0.3 and np.mean(c["sx"] < c["sy"]) > 0.3
    truncated = np.minimum(c["hx"] / c["sx"], c["hy"] / c["sy"]) < 1.0
    assert 0.2 < np.mean(truncated) < 0.8
    inside = (np.abs(c["along"]) < c["hx"]) & (np.abs(c["across"]) < c["hy"])
    assert 0.1 < np.mean(inside) < 0.9
    assert np.ptp(c["frame"]) > 6.0
    assert np.all(np.isclose(np.hypot(c["dx"], c["dy"]), np.hypot(c["along"], c["across"])))


def test_exact_risk_against_the_reference_on_random_beliefs():
    check(300, seed=1)


@pytest.mark.slow
def test_exact_risk_against_the_reference_on_ten_thousand_beliefs():
    check(10_000, seed=0)


def test_the_command_prints_the_worst_errors(capsys):
    results = acc.main(["--beliefs", "40", "--seed", "3"])
    out = capsys.readouterr().out
    assert "targets (|error| <= 0.0001, never below by more than 1e-05): met" in out
    assert set(results) == {
        "env, numpy batch",
        "env, numpy scalar",
        "generic form (numpy face)",
        "SMPC's CasADi form",
    }
