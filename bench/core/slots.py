"""Named slots of a state array of floats, declared once: the indices a kernel reads and the attributes a class shows.

A part whose kernel is written once for both engines keeps its state and tunables in one array of floats: the Python
engine runs the kernel on the part's own list (`new_array`), the compiled FOC tick on a float64 region of its buffer
that the part then views (`bench.controllers.foc_compiled`); the kernel indexes either the same way. `slots`
declares the array by name and kind, and gives a namedtuple of each field's first slot: numba reads a global
namedtuple's fields as compile-time constants, so ``s[S.b]`` costs what a literal index does, and CPython's attribute
access on it is fast. `with_views` gives the class the same fields as attributes (Python floats, ints, complex
numbers, None for an optional value without its flag), so code outside the kernel reads and sets them as before.
Adding a field adds one line; no other index moves by hand.
"""

from __future__ import annotations

from collections import namedtuple
from typing import Any, Callable


#: kinds of field and the slots each takes: a float, an int (exact in a float64 up to 2**53), a complex (re, im), and
#: an optional complex (a flag, then re, im: None while the flag is 0); besides, "fN", "iN" and "cN" are blocks of N
#: floats, ints or complex numbers (a tuple, a row-major matrix or another part's region that a kernel indexes from
#: the field's first slot; N or 2N slots, no attribute view)
WIDTH = {"f": 1, "i": 1, "c": 2, "?c": 3}


def width(kind: str) -> int:
    """The slots a field of ``kind`` takes (`WIDTH`, or a block's: N for "fN" and "iN", 2N for "cN"); ValueError for
    another kind."""
    if kind in WIDTH:
        return WIDTH[kind]
    if kind[:1] in ("f", "i", "c") and kind[1:].isdigit() and int(kind[1:]) > 0:
        return int(kind[1:]) * WIDTH[kind[0]]
    raise ValueError(f"kind {kind!r}, not one of {sorted(WIDTH)} or a block fN, iN, cN (N > 0)")


def slots(typename: str, **fields: str) -> Any:
    """A namedtuple instance: the first slot of each field, in the order given. The field names are the attribute
    names without a leading underscore (namedtuple's rule); the type keeps ``size`` (slots in all) and ``kinds``
    (attribute -> kind, `WIDTH`)."""
    names, first, n = [], [], 0
    for attr, kind in fields.items():
        try:
            w = width(kind)
        except ValueError as e:
            raise ValueError(f"{typename}.{attr}: {e}") from None
        names.append(attr.lstrip("_"))
        first.append(n)
        n += w
    cls = namedtuple(typename, names)  # type: ignore[misc]  # (a layout made at run time, by name)
    cls.size, cls.kinds = n, dict(fields)
    return cls(*first)


def with_views(spec: Any, logged: tuple[str, ...] = ()) -> Callable[[type], type]:
    """A class decorator: a property per field of ``spec`` on the instance's array ``self.s``. Reading gives a Python
    value of the field's kind, setting stores it. Setting a field named in ``logged`` calls ``self._logged()`` after
    (the compiled FOC refreshes the row it logs from its buffer; the class's own is a no-op)."""
    def decorate(cls: type) -> type:
        for (attr, kind), i in zip(type(spec).kinds.items(), spec):
            if kind not in WIDTH:
                raise ValueError(f"{type(spec).__name__}.{attr}: a block ({kind}) has no attribute view")
            setattr(cls, attr, _view(kind, i, attr in logged))
        return cls

    return decorate


def _view(kind: str, i: int, logged: bool) -> property:
    get: Callable[[Any], Any]
    if kind == "f":
        def get(o: Any) -> float:
            return float(o.s[i])

        def put(o: Any, v: Any) -> None:
            o.s[i] = float(v)
    elif kind == "i":
        def get(o: Any) -> int:
            return int(o.s[i])

        def put(o: Any, v: Any) -> None:
            o.s[i] = int(v)
    elif kind == "c":
        def get(o: Any) -> complex:
            return complex(o.s[i], o.s[i + 1])

        def put(o: Any, v: Any) -> None:
            v = complex(v)
            o.s[i], o.s[i + 1] = v.real, v.imag
    else:  # "?c"
        def get(o: Any) -> complex | None:
            s = o.s
            return complex(s[i + 1], s[i + 2]) if s[i] else None

        def put(o: Any, v: Any) -> None:
            z = 0j if v is None else complex(v)
            o.s[i], o.s[i + 1], o.s[i + 2] = 0.0 if v is None else 1.0, z.real, z.imag

    if logged:
        def put_logged(o: Any, v: Any) -> None:
            put(o, v)
            o._logged()

        return property(get, put_logged)
    return property(get, put)


def new_array(spec: Any) -> list[float]:
    """A zeroed state array for ``spec``, for the Python engine: a list of Python floats (indexing one is three times
    as fast as a numpy array's element, and gives a Python float, so the kernel's arithmetic is CPython's). The
    compiled engine hands the part a float64 array instead (a region of its buffer)."""
    return [0.0] * type(spec).size
