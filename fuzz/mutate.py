"""Byte mutators seeded with real valid inputs, as hypothesis strategies.

A mutated input is a real one (a drive CSV, MAVLink packets of the simulated firmware,
CAN frames of the AlertEncoder, the example box.toml) with a few edits drawn by
hypothesis: bit flips, bytes or tokens inserted or written over, ranges deleted or
duplicated, truncation, splices of two seeds. Starting from valid inputs lets the
mutations get past the first check and reach the deep code.
"""
from __future__ import annotations

from hypothesis import strategies as st

GENERIC_TOKENS: tuple[bytes, ...] = (
    b"\x00", b"\xff", b"\xfd", b"\xfe", b"\x80", b"\xff\xfe", b"\xc3\x28", b"\n", b"\r\n", b",", b" ",
    b"nan", b"inf", b"-inf", b"NaN", b"1e400", b"-1e400", b"3.4e38", b"-3.5e38", b"1.7e308", b"1e-320",
    b"9" * 400, b"-" + b"9" * 30, b"0x7f", b"1_000", b"", b"\"", b"[", b"{", b"=", b"#",
)


def _apply(seed: bytes, ops: list[tuple[int, int, int, bytes]], other: bytes) -> bytes:
    buf = bytearray(seed)
    for op, a, b, token in ops:
        n = len(buf)
        i = a % (n + 1)
        if op == 0 and n:  # flip a bit
            buf[i % n] ^= 1 << (b % 8)
        elif op == 1 and n:  # a byte
            buf[i % n] = b & 0xFF
        elif op == 2:  # insert a token
            buf[i:i] = token
        elif op == 3:  # write a token over
            buf[i:i + len(token)] = token
        elif op == 4:  # delete a short range
            del buf[i:i + 1 + b % 16]
        elif op == 5:  # duplicate a range
            buf[i:i] = buf[i:i + 1 + b % 64]
        elif op == 6:  # truncate
            del buf[i:]
        elif op == 7:  # splice the head of another seed in
            buf[i:] = other[b % (len(other) + 1):]
    return bytes(buf)


def mutated(seeds: list[bytes], tokens: tuple[bytes, ...] = GENERIC_TOKENS, max_ops: int = 6) -> st.SearchStrategy[bytes]:
    """A seed with 0..max_ops edits; now and then plain random bytes."""
    op = st.tuples(st.integers(0, 7), st.integers(0, 2**31 - 1), st.integers(0, 2**31 - 1), st.sampled_from(tokens))
    edited = st.builds(_apply, st.sampled_from(seeds), st.lists(op, max_size=max_ops), st.sampled_from(seeds))
    return st.one_of(edited, edited, edited, st.binary(max_size=256))
