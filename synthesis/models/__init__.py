"""LPV models of the thesis' motor problems in LFT form (thesis 3.3, 5.6.1).

- `synthesis.models.motor`  motor data (3.57), the current model (3.41)/(5.77), the flux-observer LFT
  (5.79)/(5.80) with the observer-as-control setup of Fig. 5.4, and the Jansen-Lorenz observer (4.3.1).
- `synthesis.models.flux_observer`  the LPV flux observer design (5.6.2).
- `synthesis.models.current_controller`  the quasi-LPV stator current controller (6.2).
- `synthesis.models.speed_controller`  the LPV speed controller around the NARX MLP's LFT (6.4.3) and its
  robust version (7.2).

Nothing here imports `bench` or `mock_hw`.
"""

from synthesis.models.motor import (
    MotorData,
    a_sc,
    b_sc,
    flux_observer_plant,
    flux_observer_plant_discrete,
    jl_observer,
)

__all__ = [
    "MotorData",
    "a_sc",
    "b_sc",
    "flux_observer_plant",
    "flux_observer_plant_discrete",
    "jl_observer",
]
