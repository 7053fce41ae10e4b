"""Commissioning: identifying the motor at the rig (thesis 3.6).

* `signals` - the test signals (DC staircase, multisine) as one plan;
* `circuit` - the standstill impedance of the inverse-Γ circuit, its sampled-data form, parameter sets;
* `fits` - least squares with 95 % confidence intervals (DC line, lock-in, impedance);
* `standstill` - the test as a controller plugin (``standstill_id``);
* `identify` - `bench identify`: run the test as a session, fit the log, report and plot;
* `calibrate` - `bench calibrate`: the ADC offsets at standstill, written into the rig file.
"""
