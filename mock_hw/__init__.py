"""The mock plant: a simulated rebuild of the thesis' lab rig (App. A) behind `bench.hal`.

`make_mock_rig(MockConfig())` gives a `bench.hal.Rig` whose ports are a simulated VLT inverter,
LEM current channels, filtered voltage channels, an encoder and a DC load drive, all driven by the
induction-motor model (3.41). Controllers never import this package; only tests and logs read the
plant's ground truth (``rig.truth``).
"""

from mock_hw.motor import InductionMotor, steady_state
from mock_hw.plant import MockConfig, MockPlant, TRUTH_FIELDS, make_mock_rig

__all__ = ["InductionMotor", "MockConfig", "MockPlant", "TRUTH_FIELDS", "make_mock_rig", "steady_state"]
