"""Python's ``repr`` of many doubles at once, byte for byte, in NumPy.

``repr(x)`` writes the *shortest* decimal that reads back as x (and, of the shortest, the closest to x),
in fixed notation when the decimal point position ``decpt`` (the number of digits before the point in
``0.d₁d₂… × 10^decpt``) satisfies −4 < decpt ≤ 16 and in exponential notation otherwise
(``1e-05``, ``1.5e+16``). Python finds those digits with arbitrary-precision arithmetic, one number at a
time (``benchmarks/io.md``); this module finds them for a whole array:

1. S = |x|·10^k with k = 16 − ⌊log₁₀|x|⌋, so that 10¹⁶ ≤ S < 10¹⁷, as a double-double (Dekker's exact
   product with a double-double table of 10^k): S is known to about 10⁻¹⁴, and split exactly into an
   integer D and a fraction f.
2. In these units the rounding interval of x is S ± H with H = S/(2m), m the 53-bit significand
   (a decimal reads back as x iff it lies strictly inside, or on the boundary when m is even).
3. For p significant digits the nearest p-digit decimal is V = round(S / 10^(17−p))·10^(17−p), computed
   in exact integer arithmetic from D and f; the shortest p is the smallest whose V lies in the
   interval (17 always does, and shorter works iff longer does, so p is found by a short search).
4. The text is laid out as ``repr`` does, as fields of digits right-aligned in byte tables (four digits
   per table look-up): fixed notation is C // 10^f, '.', C % 10^f zero-padded to f digits (C the
   digits, f the digits after the point, ``0.000ddd`` included); exponential notation is the first digit,
   '.', the others, 'e±XX'. ``join_fields`` puts the fields of a line side by side and keeps the used
   bytes of the table, in order.

Every decision is made with a margin: a value whose V sits within 10⁻⁹ of the interval boundary, or
exactly half-way between two candidates, a power of two (its interval is lopsided), or |x| outside
[1e-270, 1e270], is handed to ``repr`` itself — a few per ten thousand random doubles, none among
integers. Integral values below 1e16 are their integer digits and ``.0``. ``tests/test_floatfmt.py``
compares the result with ``repr`` on millions of values of every kind.
"""

from __future__ import annotations


import numpy as np

__all__ = ["repr_fields", "int_fields", "join_fields"]

_KMIN, _KMAX = -260, 290  # k = 16 − ⌊log₁₀|x|⌋ ± 1 for 1e-270 ≤ |x| ≤ 1e270
_SPLIT = 134217729.0          # 2**27 + 1, Dekker's splitter
_TOL = 1e-9                   # margin of every decision, in units of the 17th digit (S is good to 1e-14)
_POW10 = 10 ** np.arange(19, dtype=np.int64)
_POW10_U = np.array([10 ** i for i in range(20)], dtype=np.uint64)
_QUADS = (np.arange(10_000)[:, None] // np.array([1000, 100, 10, 1]) % 10 + 48).astype(np.uint8).view("<u4")[:, 0]  # "0000" … "9999"
_DIGITS = 24                  # width of the zero-padded digit rows (groups of four)
_FALLBACK = 24                # longest repr of a double: -2.2250738585072014e-308


def _table():
    """10^k = hi + lo for every k of the range, hi the nearest double and lo the nearest double to the
    rest — exact integer arithmetic, rounded once (CPython's int → float and int / int are correctly
    rounded, as ``float(Fraction)`` is)."""
    hi = np.zeros(_KMAX - _KMIN + 1)
    lo = np.zeros_like(hi)
    for i, k in enumerate(range(_KMIN, _KMAX + 1)):
        if k >= 0:
            v = 10 ** k
            h = float(v)
            hi[i], lo[i] = h, float(v - int(h))
        else:
            d10 = 10 ** -k
            h = 1 / d10
            num, den = h.as_integer_ratio()        # h = num / den exactly, den a power of two
            hi[i], lo[i] = h, (den - num * d10) / (d10 * den)
    c = _SPLIT * hi
    hh = c - (c - hi)
    return hi, lo, hh, hi - hh


_P_HI, _P_LO, _P_HH, _P_HL = _table()  # 10^k ≈ hi + lo; hi = hh + hl (Dekker split)


def _scaled(a: np.ndarray, k: np.ndarray):
    """S = a·10^k as a double-double (s, e): Dekker's exact product with the table entry."""
    i = k - _KMIN
    h, l, hh, hl = _P_HI[i], _P_LO[i], _P_HH[i], _P_HL[i]
    c = _SPLIT * a
    ah = c - (c - a)
    al = a - ah
    p = a * h
    err = ((ah * hh - p) + ah * hl + al * hh) + al * hl + a * l
    s = p + err
    return s, err - (s - p)


def _candidate(D, f, H, even, pj):
    """The nearest decimal with ``pj`` = 10^j as its last place: (digits C, reads back, uncertain)."""
    q, r = np.divmod(D, pj)
    twice = (2 * r - pj).astype(float) + 2 * f        # 2·(fraction of S/10^j) − 1, times 10^j
    C = q + (twice > 0)
    dist = np.abs((C * pj - D).astype(float) - f)     # |V − S|
    back = (dist < H) | ((dist == H) & even)
    uncertain = (np.abs(dist - H) < _TOL) | ((np.abs(twice) < 2 * _TOL) & (dist < H + _TOL))
    return C, back, uncertain


def _shortest(a: np.ndarray):
    """For 1e-270 ≤ a ≤ 1e270 (positive): digits C (int64), their count, decpt, and ``ok`` (False: use
    ``repr``)."""
    k = (16 - np.floor(np.log10(a))).astype(np.int64)
    s, e = _scaled(a, k)
    for _ in range(2):  # log10 may be one off
        low = s < 1e16
        high = (s > 1e17) | ((s == 1e17) & (e >= 0))
        fix = np.flatnonzero(low | high)
        if fix.size == 0:
            break
        k[fix] += np.where(low[fix], 1, -1)
        s[fix], e[fix] = _scaled(a[fix], k[fix])
    ok = (s >= 1e16) & (s < 1e17) & np.isfinite(e)
    s = np.where(ok, s, 1e16)
    e = np.where(ok, e, 0.0)
    whole = np.floor(e)
    D = s.astype(np.int64) + whole.astype(np.int64)
    f = e - whole
    mant, _ = np.frexp(a)
    m = (mant * 2.0 ** 53).astype(np.int64)
    ok &= m != (1 << 52)                                # a power of two: lopsided interval
    H = 0.5 * (s / m)
    even = (m & 1) == 0

    C, b16, u16 = _candidate(D, f, H, even, 10)       # 16 digits (about half of all doubles)
    ok &= ~u16
    j = np.where(b16, 1, 0)
    b15 = np.zeros_like(b16)
    need17 = np.flatnonzero(~b16)                      # 17 digits: the nearest integer to S
    if need17.size:
        f17 = f[need17]
        C[need17] = D[need17] + (f17 > 0.5)
        ok[need17] &= np.abs(f17 - 0.5) >= _TOL
    try15 = np.flatnonzero(b16)
    if try15.size:
        c15, b, u15 = _candidate(D[try15], f[try15], H[try15], even[try15], 100)
        ok[try15] &= ~u15
        b15[try15] = b
        C[try15[b]], j[try15[b]] = c15[b], 2
    more = np.flatnonzero(b15 & ok)                     # 15 digits or fewer: bisect j in [2, 17)
    if more.size:
        Dm, fm, Hm, em = D[more], f[more], H[more], even[more]
        lo, hi = np.full(more.size, 2), np.full(more.size, 17)
        good = np.ones(more.size, bool)
        while (hi - lo > 1).any():
            active = hi - lo > 1
            mid = (lo + hi) // 2
            _, back, uncertain = _candidate(Dm, fm, Hm, em, _POW10[mid])
            good &= ~(uncertain & active)
            lo = np.where(active & back, mid, lo)
            hi = np.where(active & ~back, mid, hi)
        Cm, _, uncertain = _candidate(Dm, fm, Hm, em, _POW10[lo])
        C[more], j[more] = Cm, lo
        ok[more] &= good & ~uncertain
    n = np.searchsorted(_POW10, C, "right")            # digits of C (a carry may add one)
    decpt = 17 - k + (n - (17 - j))
    carry = C == _POW10[n - 1]                          # 10^p after a carry: the digit string is "1"
    C, n = np.where(carry, 1, C), np.where(carry, 1, n)
    return C, n, decpt, ok


def _digit_rows(u: np.ndarray) -> np.ndarray:
    """(N, 24) ASCII digits of the values (below 10^20), right-aligned and zero-padded: cut into groups
    of four digits, each looked up in a table of "0000" … "9999"."""
    out = np.empty((u.size, _DIGITS), np.uint8)
    quads = out.view("<u4")                                   # (N, 6)
    q = u.astype(np.uint64, copy=True)
    ten4 = np.uint64(10_000)
    for col in range(_DIGITS // 4 - 1, -1, -1):
        if col < _DIGITS // 4 - 1 and not q.any():
            quads[:, :col + 1] = _QUADS[0]
            break
        q, r = np.divmod(q, ten4)
        quads[:, col] = _QUADS[r]
    return out


def _exp_rows(exponent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 5) right-aligned ``e±XX`` / ``e±XXX`` and their lengths."""
    mag = np.abs(exponent)
    rows = np.zeros((exponent.size, 5), np.uint8)
    rows[:, 4] = 48 + mag % 10
    rows[:, 3] = 48 + (mag // 10) % 10
    three = mag >= 100
    rows[:, 2] = np.where(three, 48 + mag // 100, np.where(exponent < 0, 45, 43))
    rows[:, 1] = np.where(three, np.where(exponent < 0, 45, 43), 101)
    rows[:, 0] = 101
    return rows, np.where(three, 5, 4)


def int_fields(v: np.ndarray) -> list:
    """``%d`` of int64 values as right-aligned fields (chars (N, width), lengths): the sign (omitted
    when no value is negative) and the digits."""
    v = np.asarray(v, dtype=np.int64)
    neg = v < 0
    u = np.where(neg, (~v).astype(np.uint64) + np.uint64(1), v.astype(np.uint64))
    n = np.maximum(np.searchsorted(_POW10_U, u, "right"), 1)
    fields = [(_digit_rows(u)[:, -20:], n)]
    if neg.any():
        fields.insert(0, (np.full((v.size, 1), 45, np.uint8), neg.astype(np.int64)))
    return fields


def repr_fields(x: np.ndarray) -> list:
    """``repr`` of float64 values as right-aligned fields written one after the other with no separator
    (chars (N, width), lengths): sign, integer digits, point, fraction digits (zero-padded), exponent,
    and the text of ``repr`` itself for the values left to it (the other fields empty there). Fields
    that would be empty in every row are left out.

    With the shortest digits C (n of them) and the point position decpt: fixed notation is
    ``C // 10^f`` '.' ``C % 10^f`` (f = n − decpt fraction digits, ``0.000ddd`` included); exponential
    notation is the first digit '.' the others 'e±XX'; an integral value is its digits '.' '0'."""
    x = np.asarray(x, dtype=float)
    N = x.size
    a = np.abs(x)
    neg = np.signbit(x)
    integral = (a < 1e16) & (a == np.floor(a))          # zeros included
    general = ~integral & (a >= 1e-270) & (a <= 1e270)
    if general.all():
        C, n, decpt, ok = _shortest(a)
    else:
        C = np.where(integral, a, 0.0).astype(np.int64)
        n = np.maximum(np.searchsorted(_POW10, C, "right"), 1)
        decpt = n.copy()
        ok = integral.copy()
        g = np.flatnonzero(general)
        if g.size:
            C[g], n[g], decpt[g], ok[g] = _shortest(a[g])
    exp_form = ~integral & ((decpt <= -4) | (decpt > 16))
    ok &= integral | exp_form | (decpt < n)             # fixed notation needs a fraction digit here
    fraction = np.where(integral, 0, np.where(exp_form, n - 1, n - decpt))
    fraction = np.where(ok, fraction, 0)
    whole, part = np.divmod(C, _POW10[np.minimum(fraction, 18)])  # C < 10^17: a point beyond 18 leaves 0
    on = ok.astype(np.int64)
    int_len = np.where(exp_form | integral, n - fraction, np.maximum(decpt, 1)) * on
    point = ((fraction > 0) | integral) & ok
    frac_len = np.where(integral, 1, fraction) * on
    fields = [(_digit_rows(whole)[:, -17:], int_len), (np.full((N, 1), 46, np.uint8), point.astype(np.int64)),
              (_digit_rows(part)[:, -20:], frac_len)]
    if (neg & ok).any():
        fields.insert(0, (np.full((N, 1), 45, np.uint8), (neg & ok).astype(np.int64)))
    exp_at = np.flatnonzero(exp_form & ok)
    if exp_at.size:
        exp_rows, exp_len = np.zeros((N, 5), np.uint8), np.zeros(N, np.int64)
        exp_rows[exp_at], exp_len[exp_at] = _exp_rows(decpt[exp_at] - 1)
        fields.append((exp_rows, exp_len))
    bad = np.flatnonzero(~ok)
    if bad.size:
        fallback = np.zeros((N, _FALLBACK), np.uint8)
        fallback_len = np.zeros(N, np.int64)
        for i in bad.tolist():
            text = repr(float(x[i])).encode("ascii")
            fallback[i, _FALLBACK - len(text):] = np.frombuffer(text, np.uint8)
            fallback_len[i] = len(text)
        fields.append((fallback, fallback_len))
    return fields


def join_fields(k: int, items: list) -> bytes:
    """Lay out k lines: ``items`` in order, each a literal (bytes, the same in every line) or a list of
    right-aligned fields (chars (k, width), lengths (k,)) written one after the other; a newline ends
    each line. One compaction of a (k, total width) byte table by a mask of the used cells; each field
    is trimmed to its longest entry first."""
    parts = []  # (chars or literal bytes, lengths or None)
    for item in items:
        if isinstance(item, bytes):
            if parts and parts[-1][1] is None:
                parts[-1] = (parts[-1][0] + item, None)  # adjacent literals merge
            else:
                parts.append((item, None))
            continue
        for chars, length in item:
            w = int(length.max()) if length.size else 0
            if w:
                parts.append((chars[:, chars.shape[1] - w:], length))
    parts.append((b"\n", None))
    total = sum(len(c) if n is None else c.shape[1] for c, n in parts)
    table = np.empty((k, total), np.uint8)
    used = np.empty((k, total), bool)
    col = 0
    for chars, length in parts:
        if length is None:
            table[:, col:col + len(chars)] = np.frombuffer(chars, np.uint8)
            used[:, col:col + len(chars)] = True
            col += len(chars)
            continue
        w = chars.shape[1]
        table[:, col:col + w] = chars
        np.greater_equal(np.arange(w, dtype=np.int16)[None, :], (w - length).astype(np.int16)[:, None],
                         out=used[:, col:col + w])
        col += w
    return table[used].tobytes()
