"""lago_cvx.io.floatfmt: Python's repr of whole arrays, byte for byte, compared with repr itself on
values of every kind (random bit patterns, decimals of every length, integers, powers of two and ten,
extremes), and the writer's guard that falls back to Python's formatting."""

from __future__ import annotations

import numpy as np
import pytest

import lago_cvx.io.writer as writer
from lago_cvx.io.floatfmt import int_fields, join_fields, repr_fields
from lago_cvx.io.writer import format_records, format_records_py


def _lines(fields_list, k):
    return join_fields(k, fields_list).split(b"\n")[:-1]


def _check_repr(x):
    x = np.asarray(x, dtype=float)
    got = _lines([repr_fields(x)], x.size)
    want = [repr(float(v)).encode() for v in x]
    bad = [(w, g) for w, g in zip(want, got) if w != g]
    assert not bad and len(got) == x.size, bad[:5]


def _decimals(rng, k, digits):
    """Doubles read from decimals of ``digits`` significant digits, every magnitude."""
    values = rng.normal(size=k) * 10.0 ** rng.integers(-30, 30, k)
    return np.array([float(f"{v:.{d}g}") for v, d in zip(values.tolist(), digits.tolist())])


def test_random_bit_patterns():
    rng = np.random.default_rng(0)
    bits = rng.integers(-2 ** 63, 2 ** 63 - 1, 400_000, dtype=np.int64).view(np.float64)
    _check_repr(bits[np.isfinite(bits)])


@pytest.mark.parametrize("kind", ["normal", "scaled", "rounded", "decimals", "integers", "powers"])
def test_values_of_every_kind(kind):
    rng = np.random.default_rng(["normal", "scaled", "rounded", "decimals", "integers", "powers"].index(kind) + 1)
    if kind == "normal":
        x = rng.normal(size=200_000)
    elif kind == "scaled":
        x = rng.normal(size=200_000) * 10.0 ** rng.integers(-300, 300, 200_000)
    elif kind == "rounded":
        x = np.concatenate([np.round(rng.normal(size=20_000) * 1000, d) for d in range(10)])
    elif kind == "decimals":
        x = _decimals(rng, 100_000, rng.integers(1, 18, 100_000))
    elif kind == "integers":
        x = np.concatenate([rng.integers(-10 ** 17, 10 ** 17, 100_000).astype(float),
                            rng.integers(-1000, 1000, 10_000).astype(float)])
    else:
        x = np.concatenate([2.0 ** rng.integers(-1074, 1024, 50_000) * rng.choice([1, -1], 50_000),
                            10.0 ** rng.integers(-320, 309, 50_000)])
    _check_repr(x)


def test_edge_values():
    _check_repr([0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 2.225073858507201e-308,
                 1.7976931348623157e308, -1.7976931348623157e308, 0.1, 0.2, 0.3, 1 / 3, 2 / 3, 1e-5, 1e-4,
                 9.999999999999999e-5, 0.0001, 0.00012, 1e15, 1e16, 1e16 - 2, 9999999999999998.0,
                 123456789012345680.0, 0.30000000000000004, 1e22, 1e23, 5e-5, 4.35, 0.5, 2.5, 1e-270, 1e270,
                 1.0000000000000002, 0.9999999999999999, 1234567890123456.7, 9007199254740993.0,
                 4503599627370495.5, -1.5e-7, 2.0 ** 52, 2.0 ** 53 + 2, 1e100, 1.5e300, 6.02214076e23])


def test_integers():
    rng = np.random.default_rng(9)
    v = np.concatenate([[0, -1, 1, 2 ** 63 - 1, -2 ** 63, 10 ** 18, -10 ** 18, 99, -100],
                        rng.integers(-2 ** 63, 2 ** 63 - 1, 50_000), rng.integers(-1000, 1000, 5000)])
    got = _lines([int_fields(v)], v.size)
    assert got == [b"%d" % i for i in v.tolist()]


def test_lines_are_laid_out_like_percent_formatting():
    rng = np.random.default_rng(4)
    k = 5000
    ids = np.column_stack([rng.integers(-2 ** 40, 2 ** 40, k), np.arange(k)])
    values = np.column_stack([rng.normal(size=k), np.full(k, 44.72), np.round(rng.normal(size=k), 2),
                              rng.normal(size=k) * 1e-9, np.zeros(k), rng.integers(0, 5, k).astype(float)])
    assert format_records("EDGE_SE2", ids, values) == format_records_py("EDGE_SE2", ids, values)
    assert format_records("V", ids[:1, :1], values[:1, :3]) == format_records_py("V", ids[:1, :1], values[:1, :3])


def test_guard_falls_back_to_python(monkeypatch):
    rng = np.random.default_rng(5)
    ids = np.arange(100)[:, None]
    values = rng.normal(size=(100, 3))

    def wrong(x):
        fields = repr_fields(x)
        chars, length = fields[-1]
        chars = chars.copy()
        chars[:, -1] = ord("7")  # every number's last digit changed
        return fields[:-1] + [(chars, length)]

    monkeypatch.setattr(writer, "repr_fields", wrong)
    assert format_records("V", ids, values) == format_records_py("V", ids, values)
