"""bench.core.slots: an array declared by name gives the indices a numba kernel reads and the attributes a class
shows."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from bench.core.slots import new_array, slots, with_views

S = slots("Demo", x="f", _n="i", z="c", _prev="?c", y="f")


@with_views(S, logged=("y",))
class Demo:
    def __init__(self) -> None:
        self.s = new_array(S)
        self.calls = 0

    def _logged(self) -> None:
        self.calls += 1


def kernel(s, v):  # noqa: ANN001, ANN201 - the same function compiled and plain
    s[S.x] = s[S.x] + v
    s[S.n] = int(s[S.n]) + 1
    s[S.prev], s[S.prev + 1], s[S.prev + 2] = 1.0, s[S.z], s[S.z + 1]
    return complex(s[S.z], s[S.z + 1]) * v


def test_the_layout_follows_the_declaration():
    assert S == (0, 1, 2, 4, 7) and type(S).size == 8 and type(S)._fields == ("x", "n", "z", "prev", "y")
    with pytest.raises(ValueError, match="Bad.q: kind 'd', not one of"):
        slots("Bad", q="d")
    for bad in ("c0", "cx", "c-1"):
        with pytest.raises(ValueError, match=f"Bad.q: kind '{bad}'"):
            slots("Bad", q=bad)


def test_a_block_of_complex_numbers_takes_two_slots_an_entry_and_has_no_view():
    B = slots("Blocks", a="f", m="c4", t="c3", b="c")
    assert B == (0, 1, 9, 15) and type(B).size == 17
    with pytest.raises(ValueError, match="Blocks.m: a block \\(c4\\) has no attribute view"):
        with_views(B)(type("Holder", (), {}))


def test_attributes_read_and_set_the_array_with_their_kinds():
    d = Demo()
    d.x, d._n, d.z = 1.5, 3.7, 2 - 1j
    assert d.s[:4] == [1.5, 3, 2.0, -1.0] and type(d.x) is float and d._n == 3 and type(d._n) is int
    assert d.z == 2 - 1j and d._prev is None
    d._prev = 0j  # an optional complex holds 0j apart from None
    assert d._prev == 0j and d.s[S.prev] == 1.0
    d._prev = None
    assert d._prev is None and d.calls == 0
    d.y = 4.0  # a logged value calls the hook
    assert d.calls == 1 and d.s[S.y] == 4.0


@pytest.mark.parametrize("compiled", [False, True])
def test_a_kernel_reads_the_slots_by_name_compiled_or_not(compiled):
    """The Python engine's list and the compiled engine's float64 array (a region of a buffer, as the FOC's)."""
    d = Demo()
    d.z, d.x = 1 + 2j, 0.25
    if compiled:
        buf = np.zeros(20)
        buf[5:13] = d.s
        d.s = buf[5:13]
    f = njit(kernel) if compiled else kernel
    assert f(d.s, 2.0) == 2 + 4j
    assert d.x == 2.25 and d._n == 1 and d._prev == 1 + 2j
    assert np.array_equal(d.s, np.array([2.25, 1.0, 1.0, 2.0, 1.0, 1.0, 2.0, 0.0]))
    assert type(d.x) is float and type(d._n) is int and type(d._prev) is complex
