"""Golden logs: a few lockstep runs recorded as digests, so that a change of the code that should not change behaviour
can be checked bit for bit (`tests/test_golden.py`; record again with ``python3 -m tests.golden.record``).

`tests.golden.runs` defines and runs them, `tests.golden.digest` makes and compares the digests, the recorded
digests live in ``tests/golden/data/``. docs/golden.md says what they are and when to record them again.
"""
