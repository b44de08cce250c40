"""Dict keys and set elements whose hashing work is bounded, whatever hash values a program crafts.

A dict or set finds a key by its hash and then compares it with every stored
key that has the *same* hash. Python's hashes of numbers and tuples are public
arithmetic (``hash(i) == i % (2**61 - 1)``; a tuple's hash can be solved for),
so a program can make thousands of different keys with one hash and turn
every insertion into a walk over all of them, inside one C call. Strings and
scene objects are hashed with a per-process secret, and integers below
``2**61 - 1`` in size hash to themselves (all different but for -1 and -2),
so those are safe.

:class:`KeyGuard` sees every key that enters any dict or set of a run. It
counts the different keys per hash value and refuses the
:data:`MAX_KEYS_PER_HASH`-plus-first, so a lookup compares at most that many
keys; and it prices hashing and comparing by the key's weight
(:meth:`~robocritics.program.meter.Meter.weigh`).
"""

from __future__ import annotations

from typing import Any

from .meter import MAKE_OPS, Meter
from .skills import ObjectView

__all__ = ["KeyGuard", "MAX_KEYS_PER_HASH", "UNHASHABLE"]

MAX_KEYS_PER_HASH = 4
"""Different keys of one run that may share a hash value. Honest programs never have two (the only natural
case is ``hash(-1) == hash(-2)``); every lookup compares with at most this many stored keys."""
_TRACKED_KEY_BYTES = 100
"""Memory of remembering one key's hash (a dict entry), charged to the program that made the key."""

_SECRET_HASH = frozenset({str, ObjectView, bool, type(None)})
"""Key types whose hash a program cannot choose: strings and object ids (keyed per process), two-valued ones."""
_HASH_MODULUS = 2**61 - 1
"""Python hashes an integer to itself modulo this prime: integers smaller in size never share a hash
(except -1 and -2)."""
_KEY_OPS = 32
"""Element operations the bookkeeping of one key costs (hashing it again and looking its hash up, in Python)."""
_DICT_VIEWS = (type({}.keys()), type({}.values()), type({}.items()))
UNHASHABLE = frozenset({list, dict, set, *_DICT_VIEWS})
"""Types that can never be a key: refused before anything walks them."""
_NOTHING = object()


class KeyGuard:
    """Admits and prices the keys of one program run (see the module docstring)."""

    __slots__ = ("meter", "by_hash")

    def __init__(self, meter: Meter):
        self.meter = meter
        self.by_hash: dict[int, Any] = {}
        """Hash value -> the key with it, or a list of the different keys with it."""

    def admit(self, key: Any) -> None:
        """Check and pay for ``key`` entering a dict or set. ``TypeError`` if it is unhashable,
        ``ValueError`` if too many different keys share its hash."""
        weight = self._weight(key)
        if _unforgeable(key):
            self.meter.spend_ops(weight)
            return
        h = hash(key)
        known = self.by_hash.get(h, _NOTHING)
        if known is _NOTHING:
            self.meter.allocate(_TRACKED_KEY_BYTES)
            self.meter.spend_ops(_KEY_OPS + weight)
            self.by_hash[h] = key
            return
        group = known if type(known) is list else [known]
        self.meter.spend_ops(_KEY_OPS + (1 + len(group)) * weight)
        for other in group:
            if other is key or other == key:
                return
        if len(group) >= MAX_KEYS_PER_HASH:
            raise ValueError(
                f"more than {MAX_KEYS_PER_HASH} different dict keys or set elements have the same hash value "
                "(crafted to collide, each lookup would compare them all); use strings or small numbers as keys"
            )
        self.meter.allocate(_TRACKED_KEY_BYTES)
        group.append(key)
        self.by_hash[h] = group

    def lookup(self, key: Any) -> None:
        """Pay for looking ``key`` up in a dict or set (``TypeError`` if it is unhashable)."""
        weight = self._weight(key)
        if _unforgeable(key):
            self.meter.spend_ops(weight)
            return
        known = self.by_hash.get(hash(key), _NOTHING)
        same_hash = 0 if known is _NOTHING else len(known) if type(known) is list else 1
        self.meter.spend_ops(_KEY_OPS + (1 + same_hash) * weight)

    def admit_all(self, items: Any) -> None:
        """:meth:`admit` every element of a sized sequence; in one pass when they are all strings or all
        small integers (the usual case), whose hashes cannot be forged."""
        kinds = set(map(type, items))
        if kinds == {str}:
            self.meter.spend_ops(MAKE_OPS * len(items) + sum(map(len, items)) // 64)
        elif kinds <= {int, bool} and (not items or -_HASH_MODULUS < min(items) and max(items) < _HASH_MODULUS):
            self.meter.spend_ops(MAKE_OPS * len(items))
        else:
            for x in items:
                self.admit(x)

    def _weight(self, key: Any) -> int:
        """The key's weight (paid for by walking it); ``TypeError`` before any walk if it can never be a key."""
        if type(key) in UNHASHABLE:
            raise TypeError(f"unhashable type: '{type(key).__name__}'")
        return self.meter.weigh_bounded(key)


def _unforgeable(key: Any) -> bool:
    """Whether no program can make other keys with the hash of ``key``."""
    t = type(key)
    return t in _SECRET_HASH or (t is int and -_HASH_MODULUS < key < _HASH_MODULUS)
