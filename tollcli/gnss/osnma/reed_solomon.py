"""Erasure decoding of the Galileo I/NAV Reed–Solomon outer code over GF(2⁸) with arrays (the fast path).

The code (Galileo OS SIS ICD, I/NAV outer FEC): RS(118, 58) shortened from (255, 197), field polynomial
x⁸+x⁴+x³+x²+1 (0x11D), generator α = 2, first consecutive root α¹, 60 parity symbols. A symbol list
``msg`` is read as r(x) = Σ msg[k]·x^(n−1−k) (the first symbol the highest power), as ``reedsolo`` does.

:func:`erasure_decode` fills the symbols at known positions (erasures) by Forney's algorithm —
syndromes Sᵢ = r(αⁱ⁺¹), erasure locator Λ(x) = Π(1 + Xₚx), evaluator Ω = S·Λ mod x⁶⁰,
Yₚ = Ω(Xₚ⁻¹)/Λ′(Xₚ⁻¹) — and returns the word only when every syndrome of the result is zero. Such a word agrees
with every symbol received, and with at most 60 erasures (fewer than the minimum distance, 61) it is the only
one: the word any decoder returns. Otherwise (a symbol received in error) it returns None and the caller
decodes errors and erasures with ``reedsolo``.
"""

from __future__ import annotations

import numpy as np

#: parity symbols
NSYM = 60


def _tables() -> tuple[np.ndarray, np.ndarray]:
    exp, log = np.zeros(512, np.int64), np.zeros(256, np.int64)
    x = 1
    for i in range(255):
        exp[i], log[x] = x, i
        x <<= 1
        if x & 0x100:
            x ^= 0x11D
    exp[255:510] = exp[:255]
    return exp, log


EXP, LOG = _tables()


def gf_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Element-wise product in GF(2⁸) (0x11D)."""
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    return np.where((a == 0) | (b == 0), 0, EXP[(LOG[a] + LOG[b]) % 255])


def syndromes(symbols: np.ndarray, nsym: int = NSYM) -> np.ndarray:
    """Sᵢ = r(αⁱ⁺¹), i = 0 … nsym−1, of the symbol array (int64, first symbol the highest power)."""
    n = len(symbols)
    k = np.flatnonzero(symbols)
    if not len(k):
        return np.zeros(nsym, np.int64)
    power = (np.arange(1, nsym + 1)[:, None] * (n - 1 - k)[None, :] + LOG[symbols[k]][None, :]) % 255
    return np.bitwise_xor.reduce(EXP[power], axis=1)


def _evaluate(coeffs: np.ndarray, powers: np.ndarray, log_x: np.ndarray) -> np.ndarray:
    """Σⱼ coeffs[j]·x^powers[j] at each x = α^log_x."""
    terms = np.where(coeffs[None, :] == 0, 0, EXP[(LOG[coeffs][None, :] + log_x[:, None] * powers[None, :]) % 255])
    return np.bitwise_xor.reduce(terms, axis=1)


def erasure_decode(msg: bytes | bytearray, erase_pos: list[int], nsym: int = NSYM) -> bytes | None:
    """The code word agreeing with ``msg`` everywhere but at ``erase_pos`` (module docstring), or None."""
    c = np.frombuffer(bytes(msg), np.uint8).astype(np.int64)
    n = len(c)
    pos = np.unique(np.asarray(erase_pos, np.int64))
    if len(pos) > nsym:
        return None
    c[pos] = 0
    s = syndromes(c, nsym)
    if s.any():
        log_x = (n - 1 - pos) % 255
        lam = np.zeros(len(pos) + 1, np.int64)
        lam[0] = 1
        for k, lx in enumerate(log_x):  # Λ ← Λ·(1 + Xₚx)
            lam[1 : k + 2] ^= np.where(lam[: k + 1] == 0, 0, EXP[(LOG[lam[: k + 1]] + lx) % 255])
        omega = np.zeros(nsym, np.int64)
        for b in np.flatnonzero(lam[:nsym]):
            omega[b:] ^= gf_mul(s[: nsym - b], lam[b])
        log_inv = (-log_x) % 255
        odd = np.arange(1, len(lam), 2)  # Λ′ in characteristic 2: the odd terms, one power down
        num = _evaluate(omega, np.arange(nsym), log_inv)
        den = _evaluate(lam[odd], odd - 1, log_inv)
        if (den == 0).any():
            return None
        c[pos] ^= np.where(num == 0, 0, EXP[(LOG[num] - LOG[den]) % 255])
        if syndromes(c, nsym).any():
            return None
    return bytes(c.astype(np.uint8))
