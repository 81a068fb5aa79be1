#!/usr/bin/env python3
"""Writes fnv1a64.txt: 64-bit FNV-1a of shard keys, computed here independently of the C++
code (common/shard.h), for tests/common/shard_test.cc. Run: python3 make_fnv1a64.py"""

OFFSET_BASIS = 0xCBF29CE484222325
PRIME = 0x100000001B3


def fnv1a64(data: bytes) -> int:
    h = OFFSET_BASIS
    for byte in data:
        h ^= byte
        h = (h * PRIME) & 0xFFFFFFFFFFFFFFFF
    return h


KEYS = ["", "a", "foobar", "room-a", "room-b", "lab.floor_2", "Z" * 64, "0", "1234",
        "-5", "9223372036854775807", "-9223372036854775808"]

with open("fnv1a64.txt", "w") as out:
    out.write("# key (quoted) and its 64-bit FNV-1a in decimal; made by make_fnv1a64.py\n")
    for key in KEYS:
        out.write('"%s" %d\n' % (key, fnv1a64(key.encode())))
