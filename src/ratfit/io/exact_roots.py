"""Exact real-root counts of a 1-D denominator on its domain (the loader's pole proof).

A fit file's denominator q is a polynomial in the window variable t in [-1, 1] given
by float coefficients in a Legendre, Chebyshev or monomial basis, or in a
data-orthonormal (Arnoldi) basis given by its float recurrence. Floats are dyadic
rationals, so q is an exact rational polynomial: its monomial coefficients are
computed here in integer arithmetic (no rounding), and the number of its distinct
real roots in the closed window is counted with a Sturm sequence (a primitive
pseudo-remainder sequence over the integers, signs kept). Distinct roots are counted
whatever their multiplicity: q = (t - c)^2 with c inside has one.

A sample-based sign check cannot see a root of even multiplicity (q touches 0
without changing sign) or two roots between neighbouring samples; this can.
"""

from __future__ import annotations

from fractions import Fraction
from math import comb, gcd
from typing import Any

import numpy as np

__all__ = ["EXACT_MAX_DEGREE", "WINDOW_PAD", "denominator_has_root", "exact_monomial",
           "has_root_in", "real_roots_in"]

# Beyond this degree the exact conversion of an Arnoldi recurrence (O(m^3) big-integer
# operations: 0.8 s at degree 100, 4.7 s at 150) would make loading a hostile file a
# denial of service; ratfit's own 1-D fits stay far below it (max_total 100 by default).
EXACT_MAX_DEGREE = 150
# The closed window [-1, 1] widened by 2^-32 on each side: the float map x -> t may
# put a domain end a few ulps outside [-1, 1], and the fitter refuses poles within
# 1e-9 of the domain's width outside it, so no fit it verified has a root there.
WINDOW_PAD = Fraction(1, 1 << 32)


def _frac(v: float) -> Fraction:
    return Fraction(*float(v).as_integer_ratio())


def _to_integers(coef: list[Fraction]) -> list[int]:
    """A positive multiple of ``coef`` with integer entries (content divided out)."""
    den = 1
    for c in coef:
        den = den * c.denominator // gcd(den, c.denominator)
    ints = [int(c * den) for c in coef]
    g = 0
    for v in ints:
        g = gcd(g, v)
    return [v // g for v in ints] if g > 1 else ints


def _family_polys(name: str, k: int) -> list[list[int | Fraction]]:
    """Monomial coefficients (low to high) of the first ``k`` functions of a family."""
    out: list[list[int | Fraction]] = []
    if name == "monomial":
        for i in range(k):
            power: list[int | Fraction] = [int(e == i) for e in range(i + 1)]
            out.append(power)
    elif name == "chebyshev":
        for i in range(k):
            if i == 0:
                out.append([1])
            elif i == 1:
                out.append([0, 1])
            else:
                a, b = out[i - 1], out[i - 2]
                nxt = [0] + [2 * v for v in a]
                for j, v in enumerate(b):
                    nxt[j] -= v
                out.append(nxt)
    elif name == "legendre":
        for n in range(k):
            # P_n = 2^-n sum_j (-1)^j C(n, j) C(2n - 2j, n) t^(n - 2j)
            row: list[int | Fraction] = [0] * (n + 1)
            for j in range(n // 2 + 1):
                row[n - 2 * j] = Fraction((-1) ** j * comb(n, j) * comb(2 * n - 2 * j, n),
                                          1 << n)
            out.append(row)
    else:  # pragma: no cover (PolynomialSpace refuses unknown families)
        raise ValueError(f"unknown family {name!r}")
    return out


def _dyadic(v: float) -> tuple[int, int]:
    """(n, e) with v == n / 2^e exactly (every finite float is one)."""
    n, d = float(v).as_integer_ratio()
    return n, d.bit_length() - 1


def _lcm(a: int, b: int) -> int:
    return a // gcd(a, b) * b


def _arnoldi_monomial(H: np.ndarray, coef: np.ndarray) -> list[int]:
    """Integer monomial coefficients of a positive multiple of sum_j coef_j phi_j for a
    1-D Arnoldi recurrence ``phi_0 = 1 / H[0, 0]``,
    ``H[i, i] phi_i = t phi_(i-1) - sum_(j<i) H[j, i] phi_j``.

    Each phi_j is kept as an integer vector over its own integer denominator, reduced
    by their gcd (13x faster than Fractions: 0.8 s at 100 coefficients)."""
    k = len(coef)
    n0, e0 = _dyadic(H[0, 0])
    nums: list[list[int]] = [[1 << e0]]
    dens: list[int] = [n0]
    lcm = n0
    for i in range(1, k):
        hs = [_dyadic(H[j, i]) for j in range(i)]
        big_e = max(e for _, e in hs)
        # T / (lcm 2^E) = t phi_(i-1) - sum_j H[j, i] phi_j
        f = (lcm // dens[i - 1]) << big_e
        t = [0] + [v * f for v in nums[i - 1]]
        for j, (hn, he) in enumerate(hs):
            if hn == 0:
                continue
            g = hn * (lcm // dens[j]) << (big_e - he)
            for e, v in enumerate(nums[j]):
                t[e] -= g * v
        a, s_ = _dyadic(H[i, i])  # phi_i = T 2^s / (lcm 2^E a), a > 0
        num = [v << s_ for v in t]
        den = (lcm << big_e) * a
        g = den
        for v in num:
            g = gcd(g, v)
        nums.append([v // g for v in num])
        dens.append(den // g)
        lcm = _lcm(lcm, dens[-1])
    cs = [_dyadic(c) for c in coef]
    big_e = max(e for _, e in cs)
    total = [0] * k
    for (cn, ce), num, den in zip(cs, nums, dens, strict=True):
        if cn == 0:
            continue
        g = cn * (lcm // den) << (big_e - ce)
        for e, v in enumerate(num):
            total[e] += g * v
    return _primitive(_trim(total))


def exact_monomial(rf: Any, which: str = "q") -> list[int]:
    """Integer monomial coefficients in t (low to high) of a positive multiple of the
    1-D numerator or denominator of ``rf`` (a :class:`RationalFunction`), exactly."""
    coef = np.asarray(rf.q if which == "q" else rf.p, dtype=float)
    basis = rf.q_basis if which == "q" else rf.p_basis
    k = int(np.max(np.nonzero(coef)[0])) + 1 if np.any(coef) else 1
    if k - 1 > EXACT_MAX_DEGREE:
        raise ValueError(f"degree {k - 1} is above {EXACT_MAX_DEGREE}, the largest whose "
                         "roots are counted exactly")
    if basis is not None:
        return _arnoldi_monomial(np.asarray(basis.H, dtype=float), coef[:k])
    polys = _family_polys(rf.space.family.name, k)
    total = [Fraction(0)] * k
    for c, poly in zip(coef[:k], polys, strict=True):
        if c == 0.0:
            continue
        cf = _frac(c)
        for e, v in enumerate(poly):
            total[e] += cf * v
    while len(total) > 1 and total[-1] == 0:
        total.pop()
    return _to_integers(total)


# ---------------------------------------------------------------------------- Sturm
def _trim(p: list[int]) -> list[int]:
    while len(p) > 1 and p[-1] == 0:
        p.pop()
    return p


def _primitive(p: list[int]) -> list[int]:
    g = 0
    for v in p:
        g = gcd(g, v)
    return [v // g for v in p] if g > 1 else p


def _neg_prem(a: list[int], b: list[int]) -> list[int]:
    """A positive multiple of -(a mod b) (integers): the next term of a Sturm chain."""
    r = list(a)
    lb = b[-1]
    db = len(b) - 1
    steps = 0
    while len(r) - 1 >= db and any(r):
        lr = r[-1]
        shift = len(r) - 1 - db
        # r <- lb * r - lr * t^shift * b   (multiplies the remainder by lb)
        r = [lb * v for v in r]
        for j, v in enumerate(b):
            r[shift + j] -= lr * v
        r.pop()  # the leading term cancels
        r = _trim(r) if r else [0]
        steps += 1
    # r = lb^steps * (a mod b): fix the sign so the result is -(a mod b) times a positive
    sign = -1 if (lb < 0 and steps % 2 == 1) else 1
    return _primitive(_trim([-sign * v for v in r]))


def _sign_at(p: list[int], num: int, den: int) -> int:
    """Sign of p(num / den), den > 0 (Horner on den^deg p(num/den), exact)."""
    acc = 0
    scale = 1
    for v in reversed(p):  # high to low: acc = acc * num + v * den^i
        acc = acc * num + v * scale
        scale *= den
    # acc == den^(deg) * p(num/den) up to the factor den^0 ordering: positive multiple
    return (acc > 0) - (acc < 0)


def _variations(chain: list[list[int]], num: int, den: int) -> int:
    signs = [s for s in (_sign_at(p, num, den) for p in chain) if s != 0]
    return sum(1 for a, b in zip(signs, signs[1:], strict=False) if a != b)


def real_roots_in(poly: list[int], lo: Fraction, hi: Fraction) -> int:
    """Number of distinct real roots of the integer polynomial ``poly`` (low to high
    coefficients) in the closed interval [lo, hi], exactly."""
    p = _primitive(_trim(list(poly)))
    if len(p) == 1:
        return 0 if p[0] != 0 else -1  # -1: the zero polynomial (zero everywhere)
    at_lo = _sign_at(p, lo.numerator, lo.denominator) == 0
    dp = _primitive([i * v for i, v in enumerate(p)][1:])
    chain = [p, dp]
    while len(chain[-1]) > 1:
        nxt = _neg_prem(chain[-2], chain[-1])
        if not any(nxt):
            break
        chain.append(nxt)
    # Sturm: distinct roots in (lo, hi] = V(lo) - V(hi), zeros skipped (at a root, the
    # skipped zero leaves the count of just right of it); a root at lo is added
    inner = _variations(chain, lo.numerator, lo.denominator) - _variations(
        chain, hi.numerator, hi.denominator)
    return inner + int(at_lo)


# ---------------------------------------------------------------------------- Descartes
# Bisection on [0, 1] with Descartes' rule of signs, in integers: fast where roots are
# far from the interval (a handful of Taylor shifts), undecided only where roots
# cluster or touch (a double root, a complex pair hugging the interval); there the
# Sturm count decides.
DESCARTES_DEPTH = 40
STURM_MAX_DEGREE = 120  # Sturm's remainders grow fast: 1.2 s at degree 100, 37 s at 200


def _shift(a: list[int], k: int) -> list[int]:
    """Coefficients of A(x + k) (Taylor shift by the integer k)."""
    a = list(a)
    n = len(a)
    for i in range(n - 1):
        for j in range(n - 2, i - 1, -1):
            a[j] += k * a[j + 1] if k != 1 else a[j + 1]
    return a


def _shift1(a: list[int]) -> list[int]:
    return _shift(a, 1)


def _sign_changes(a: list[int]) -> int:
    signs = [v > 0 for v in a if v != 0]
    return sum(1 for x, y in zip(signs, signs[1:], strict=False) if x != y)


def _on_unit_interval(p: list[int], lo: Fraction, hi: Fraction) -> list[int]:
    """Integer coefficients of a positive multiple of A(x) = p(lo + (hi - lo) x)."""
    d = len(p) - 1
    w = hi - lo
    # B(y) = wd^d p(w y), then A(x) = B(x + lo / w), the shift by c = cn / cd done as
    # E(z) = cd^d B(z / cd), E(z + cn), z = cd x: every step in integers
    b = [v * w.numerator ** i * w.denominator ** (d - i) for i, v in enumerate(p)]
    c = lo / w
    e = [v * c.denominator ** (d - i) for i, v in enumerate(b)]
    e = _shift(e, c.numerator)
    return _primitive([v * c.denominator ** i for i, v in enumerate(e)])


def _descartes_root(a: list[int]) -> bool | None:
    """True if A has a root in [0, 1], False if not, None when undecided at the depth."""
    if a[0] == 0 or sum(a) == 0:
        return True
    d = len(a) - 1
    stack = [(a, 0)]
    while stack:
        a, depth = stack.pop()
        v = _sign_changes(_shift1(a[::-1]))
        if v == 0:
            continue
        if v % 2 == 1:  # the count of roots in (0, 1) has the parity of v
            return True
        if depth >= DESCARTES_DEPTH:
            return None
        left = _primitive([c << (d - i) for i, c in enumerate(a)])  # 2^d A(x / 2)
        right = _shift1(left)  # the same on the right half
        if right[0] == 0:  # A(1/2) == 0
            return True
        stack.append((left, depth + 1))
        stack.append((_primitive(right), depth + 1))
    return False


def has_root_in(poly: list[int], lo: Fraction, hi: Fraction) -> bool | None:
    """Whether the integer polynomial ``poly`` has a real root in [lo, hi], exactly;
    None only when roots cluster there and the degree is too high for Sturm."""
    p = _primitive(_trim(list(poly)))
    if len(p) == 1:
        return p[0] == 0
    found = _descartes_root(_on_unit_interval(p, lo, hi))
    if found is None and len(p) - 1 <= STURM_MAX_DEGREE:
        return real_roots_in(p, lo, hi) > 0
    return found


def _value(p: list[int], x: Fraction) -> Fraction:
    acc = Fraction(0)
    for v in reversed(p):
        acc = acc * x + v
    return acc


# A denominator whose smallest |q| on the domain is below this fraction of its largest
# is a pole in double precision: evaluating q there in floats rounds it to 0 or flips
# its sign (a double root c written with a rounded c, (t - 0.3)^2, is such a q: its
# exact roots are complex, 1e-9 off the axis, and r reaches 1e16 times its size).
NEAR_ZERO = Fraction(1, 1 << 45)


def denominator_has_root(rf: Any) -> bool | None:
    """Whether a 1-D fit's denominator has a real root in its closed window (padded by
    :data:`WINDOW_PAD`), or comes within :data:`NEAR_ZERO` of its largest value of
    one, exactly; None when that could not be decided."""
    q = exact_monomial(rf, "q")
    one = Fraction(1) + WINDOW_PAD
    found = has_root_in(q, -one, one)
    if found is not False or len(q) == 1:
        return found
    # no root: q has one sign; |q| > NEAR_ZERO * (a lower bound of max |q|) everywhere
    # iff q -+ that bound has no root either
    vals = [_value(q, Fraction(i, 32)) for i in range(-32, 33)]
    top = max(abs(v) for v in vals)
    floor = NEAR_ZERO * top * (1 if vals[32] > 0 else -1)
    shifted = [Fraction(v) for v in q]
    shifted[0] -= floor
    return has_root_in(_to_integers(shifted), -one, one)
